"""Probe 13, T5: float64 depth (a ``.npy`` of metres) is judged as stored, not after the cast to float32,
which turned 1e300 m into infinite pixels ("mark invalid pixels with 0 or NaN") and 1e-300 m into no
depth at all; each is now said for what it is, and ordinary float64 / float16 metres read as before."""

from __future__ import annotations

import numpy as np
import pytest

from frontiernet.errors import InputError
from frontiernet.sequences.images import read_depth


@pytest.mark.parametrize("values, reason", [
    (np.full((4, 5), 1e300), r"median depth 1e\+300 m is implausible \(float depth is read as metres\)"),
    (np.full((4, 5), 1e-300), r"median depth 1e-300 m is implausible \(float depth is read as metres\)"),
    (np.where(np.eye(4, 5) > 0, 1e300, 2.0), r"4 pixel\(s\) beyond 100 m \(the farthest 1e\+300 m\)"),
])
def test_float64_depth_out_of_float32_range_is_named_for_what_it_is(tmp_path, values, reason):
    path = tmp_path / "depth.npy"
    np.save(path, values)
    with pytest.raises(InputError, match=reason) as refused:
        read_depth(path)
    assert str(path) in str(refused.value) and "infinite" not in str(refused.value)


@pytest.mark.parametrize("dtype", [np.float64, np.float16])
def test_float_metres_of_any_width_read_as_float32_with_invalid_pixels_zero(tmp_path, dtype):
    path = tmp_path / "depth.npy"
    np.save(path, np.array([[np.nan, 2.5], [3.0, -1.0]], dtype))
    depth = read_depth(path)
    assert depth.dtype == np.float32 and depth.tolist() == [[0.0, 2.5], [3.0, 0.0]]

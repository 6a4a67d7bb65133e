"""Checked inputs of the occupancy map: its settings and the frames it integrates.

Every check raises :class:`~frontiernet.errors.InputError` naming the bad value.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import ConfigSection
from ..errors import InputError, positive_number


@dataclass(frozen=True)
class MapSettings(ConfigSection):
    """The ``map`` section of ``configs/explore.yaml``, checked (see the file for meanings)."""

    voxel_size: float
    log_odds_hit: float
    log_odds_miss: float
    log_odds_min: float
    log_odds_max: float
    occupied_threshold: float
    ray_stride_px: int
    max_range_m: float
    invalid_depth: str
    depth_edge_rtol: float | None
    monocular_hit_range_m: float | None = None
    monocular_log_odds_miss: float | None = None
    monocular_free_fraction: float | None = None
    monocular_far_hit_max: float | None = None

    SECTION = "map"

    @classmethod
    def from_section(cls, conf) -> MapSettings:
        """From the ``map`` section (DictConfig or dict)."""
        try:
            values = {key: conf[key] for key in cls.__dataclass_fields__}
        except KeyError as error:
            raise InputError(f"map.{error.args[0]} is missing from the map config") from None
        numbers = {key: finite_number(values[key], f"map.{key}") for key in
                   ("log_odds_hit", "log_odds_miss", "log_odds_min", "log_odds_max", "occupied_threshold")}
        if not (numbers["log_odds_min"] <= 0.0 <= numbers["log_odds_max"]):
            raise InputError(f"map.log_odds_min <= 0 <= map.log_odds_max must hold (0 is the unknown prior), "
                             f"got {numbers['log_odds_min']}, {numbers['log_odds_max']}")
        if not (numbers["log_odds_hit"] > 0.0 > numbers["log_odds_miss"]):
            raise InputError(f"map.log_odds_hit must be > 0 and map.log_odds_miss < 0, got "
                             f"{numbers['log_odds_hit']}, {numbers['log_odds_miss']}")
        stride = values["ray_stride_px"]
        if isinstance(stride, bool) or not isinstance(stride, int) or stride < 1:
            raise InputError(f"map.ray_stride_px must be an integer >= 1, got {stride!r}")
        if values["invalid_depth"] not in ("free", "skip"):
            raise InputError(f"map.invalid_depth must be 'free' or 'skip', got {values['invalid_depth']!r}")
        edge_rtol = values["depth_edge_rtol"]
        if edge_rtol is not None:
            edge_rtol = positive_number(scalar(edge_rtol), "map.depth_edge_rtol (or null)")
        hit_range = values["monocular_hit_range_m"]
        if hit_range is not None:
            hit_range = positive_number(scalar(hit_range), "map.monocular_hit_range_m (or null)", "metres")
        miss = values["monocular_log_odds_miss"]
        if miss is not None:
            miss = finite_number(miss, "map.monocular_log_odds_miss (or null)")
            if miss >= 0.0:
                raise InputError(f"map.monocular_log_odds_miss must be < 0 (or null), got {miss}")
        fraction = values["monocular_free_fraction"]
        if fraction is not None:
            fraction = finite_number(fraction, "map.monocular_free_fraction (or null)")
            if not 0.0 < fraction <= 1.0:
                raise InputError(f"map.monocular_free_fraction must be in (0, 1] (or null), got {fraction}")
        far_max = values["monocular_far_hit_max"]
        if far_max is not None:
            far_max = finite_number(far_max, "map.monocular_far_hit_max (or null)")
            if not 0.0 < far_max <= numbers["log_odds_max"]:
                raise InputError(f"map.monocular_far_hit_max must be in (0, log_odds_max] (or null), got {far_max}")
        return cls(voxel_size=positive_number(values["voxel_size"], "map.voxel_size", "metres"), ray_stride_px=stride,
                   max_range_m=positive_number(values["max_range_m"], "map.max_range_m", "metres"),
                   invalid_depth=str(values["invalid_depth"]), depth_edge_rtol=edge_rtol,
                   monocular_hit_range_m=hit_range, monocular_log_odds_miss=miss,
                   monocular_free_fraction=fraction, monocular_far_hit_max=far_max, **numbers)


def scalar(value):
    """Numpy scalars as Python numbers (the checks of :mod:`frontiernet.errors` take those)."""
    return value.item() if isinstance(value, np.generic) else value


def finite_number(value, name: str) -> float:
    """`value` as a float if it is a finite number, else InputError naming `name`."""
    value = scalar(value)
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value)
    if not ok:
        raise InputError(f"{name} must be a finite number, got {value!r}")
    return float(value)


def depth_image(depth) -> np.ndarray:
    """(H, W) float32 C-contiguous depth, or InputError naming `depth`."""
    depth = np.asarray(depth)
    if depth.ndim != 2 or depth.size == 0:
        raise InputError(f"depth must be a non-empty 2D (H, W) image of metres, got shape {depth.shape}")
    if depth.dtype.kind != "f":
        raise InputError(f"depth must be a float image of metres (convert integer millimetres first), "
                         f"got dtype {depth.dtype}")
    return np.ascontiguousarray(depth, np.float32)

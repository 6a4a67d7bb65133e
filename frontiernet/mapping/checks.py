"""Checked inputs of the occupancy map: its settings and the frames it integrates.

Every check raises :class:`~frontiernet.errors.InputError` naming the bad value.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import ConfigSection, setting
from ..errors import InputError, positive_number, whole_number


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


def _or_null(check):
    """`check` for a key that may also be null (None, passed through); it names ``<key> (or null)``."""
    def checked(value, name: str, *args):
        return None if value is None else check(scalar(value), f"{name} (or null)", *args)
    return checked


def _invalid_depth(value, name: str) -> str:
    if value not in ("free", "skip"):
        raise InputError(f"{name} must be 'free' or 'skip', got {value!r}")
    return str(value)


def _monocular_miss(value, name: str) -> float | None:
    if value is None:
        return None
    miss = finite_number(value, f"{name} (or null)")
    if miss >= 0.0:
        raise InputError(f"{name} must be < 0 (or null), got {miss}")
    return miss


def _monocular_fraction(value, name: str) -> float | None:
    if value is None:
        return None
    fraction = finite_number(value, f"{name} (or null)")
    if not 0.0 < fraction <= 1.0:
        raise InputError(f"{name} must be in (0, 1] (or null), got {fraction}")
    return fraction


@dataclass(frozen=True)
class MapSettings(ConfigSection):
    """The ``map`` section of ``configs/explore.yaml``, checked (see the file for meanings)."""

    SECTION = "map"

    voxel_size: float = setting(positive_number, "metres")
    log_odds_hit: float = setting(finite_number)
    log_odds_miss: float = setting(finite_number)
    log_odds_min: float = setting(finite_number)
    log_odds_max: float = setting(finite_number)
    occupied_threshold: float = setting(finite_number)
    ray_stride_px: int = setting(whole_number, 1)
    max_range_m: float = setting(positive_number, "metres")
    invalid_depth: str = setting(_invalid_depth)
    depth_edge_rtol: float | None = setting(_or_null(positive_number))
    monocular_hit_range_m: float | None = setting(_or_null(positive_number), "metres")
    monocular_log_odds_miss: float | None = setting(_monocular_miss)
    monocular_free_fraction: float | None = setting(_monocular_fraction)
    monocular_far_hit_max: float | None = setting(_or_null(finite_number))

    def __post_init__(self) -> None:  # what ties keys together
        if not (self.log_odds_min <= 0.0 <= self.log_odds_max):
            raise InputError(f"map.log_odds_min <= 0 <= map.log_odds_max must hold (0 is the unknown prior), "
                             f"got {self.log_odds_min}, {self.log_odds_max}")
        if not (self.log_odds_hit > 0.0 > self.log_odds_miss):
            raise InputError(f"map.log_odds_hit must be > 0 and map.log_odds_miss < 0, got "
                             f"{self.log_odds_hit}, {self.log_odds_miss}")
        far_max = self.monocular_far_hit_max
        if far_max is not None and not 0.0 < far_max <= self.log_odds_max:
            raise InputError(f"map.monocular_far_hit_max must be in (0, log_odds_max] (or null), got {far_max}")


def depth_image(depth) -> np.ndarray:
    """(H, W) float32 C-contiguous depth, or InputError naming `depth`."""
    depth = np.asarray(depth)
    if depth.ndim != 2 or depth.size == 0:
        raise InputError(f"depth must be a non-empty 2D (H, W) image of metres, got shape {depth.shape}")
    if depth.dtype.kind != "f":
        raise InputError(f"depth must be a float image of metres (convert integer millimetres first), "
                         f"got dtype {depth.dtype}")
    return np.ascontiguousarray(depth, np.float32)

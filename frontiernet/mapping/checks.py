"""Checked inputs of the occupancy map: its settings, the sensor model a depth source's rays
get, the frames it integrates and the pixels of a frame it leaves out.

Every check raises :class:`~frontiernet.errors.InputError` naming the bad value.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..config import ConfigSection, setting
from ..errors import InputError, fraction_or_null, positive_number, whole_number


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


def _incidence(value, name: str) -> float:
    value = finite_number(value, name)
    if not 0.0 < value < 90.0:
        raise InputError(f"{name}: an angle from the surface normal in (0, 90) degrees, got {value}")
    return value


def _odd_window(value, name: str) -> int:
    value = whole_number(value, name, 3)
    if value % 2 == 0:
        raise InputError(f"{name}: an odd window side in pixels, got {value}")
    return value


def _monocular_fraction(value, name: str) -> float | None:
    return fraction_or_null(None if value is None else scalar(value), name)


@dataclass(frozen=True)
class RayModel:
    """How the rays of one depth source's frames update the map (:meth:`MapSettings.ray_model`).

    ``hit_range_m``: a ray's end within this z-depth (metres) is a hit; ``free_fraction``: a
    ray is free up to this fraction of its depth; ``log_odds_miss``: a passed voxel's update;
    ``far_hit_max``: ends beyond ``hit_range_m`` are weak hits raised to at most this log-odds
    (None: no hit); ``depth_edge_rtol``: pixels at depth edges are left out (:func:`depth_edges`;
    None: none); ``max_incidence_deg``: pixels seeing their surface more obliquely are left out
    (:func:`grazing_pixels` over ``normal_window_px``; None: none)."""

    hit_range_m: float
    free_fraction: float
    log_odds_miss: float
    far_hit_max: float | None
    depth_edge_rtol: float | None
    max_incidence_deg: float | None = None
    normal_window_px: int = 9


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
    monocular_max_incidence_deg: float | None = setting(_or_null(_incidence))
    monocular_normal_window_px: int = setting(_odd_window)

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

    def ray_model(self, monocular: bool) -> RayModel:
        """The sensor model of a depth source: OctoMap's rule up to ``max_range_m``, and for a
        monocular network's depth (``monocular``) the ``depth_edge_rtol`` filter and each
        ``monocular_*`` key that is set (all null: the same rule)."""
        if not monocular:
            return RayModel(self.max_range_m, 1.0, self.log_odds_miss, None, None)
        hit_range = min(self.max_range_m, _unless_null(self.monocular_hit_range_m, self.max_range_m))
        weak = self.monocular_far_hit_max is not None and hit_range < self.max_range_m
        return RayModel(hit_range, _unless_null(self.monocular_free_fraction, 1.0),
                        _unless_null(self.monocular_log_odds_miss, self.log_odds_miss),
                        self.monocular_far_hit_max if weak else None, self.depth_edge_rtol,
                        self.monocular_max_incidence_deg, self.monocular_normal_window_px)


def _unless_null(value, default):
    """`value`, or `default` where the key is null (off)."""
    return default if value is None else value


def depth_image(depth) -> np.ndarray:
    """(H, W) float32 C-contiguous depth, or InputError naming `depth`."""
    depth = np.asarray(depth)
    if depth.ndim != 2 or depth.size == 0:
        raise InputError(f"depth must be a non-empty 2D (H, W) image of metres, got shape {depth.shape}")
    if depth.dtype.kind != "f":
        raise InputError(f"depth must be a float image of metres (convert integer millimetres first), "
                         f"got dtype {depth.dtype}")
    return np.ascontiguousarray(depth, np.float32)


def depth_edges(depth: np.ndarray, rtol: float, kernel_px: int = 3) -> np.ndarray:
    """Pixels at depth discontinuities: (H, W) bool, True where the depths of the pixel's
    `kernel_px` x `kernel_px` neighbourhood span more than `rtol` times its own depth.

    The edge test of utils3d's ``depth_edge`` (max - min over the window, relative to the
    pixel's depth), which MoGe applies to its own monocular output before building a point
    cloud or mesh ("remove edge", rtol 0.04 in its demo): at a discontinuity an upsampling
    decoder gives intermediate depths, points in the free space between the two surfaces.

    Args:
        depth: (H, W) float z-depth in metres, NaN (or <= 0) where invalid; invalid
            neighbours are ignored, invalid pixels are never edges.
        rtol: relative depth span, > 0.
        kernel_px: odd window side, pixels.
    """
    depth = np.asarray(depth, np.float32)
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(depth) & (depth > 0)
    window = np.ones((kernel_px, kernel_px), np.uint8)  # grey dilation / erosion = max / min filters
    highest = cv2.dilate(np.where(valid, depth, -np.inf), window, borderType=cv2.BORDER_REPLICATE)
    lowest = cv2.erode(np.where(valid, depth, np.inf), window, borderType=cv2.BORDER_REPLICATE)
    with np.errstate(invalid="ignore"):
        return valid & (highest - lowest > rtol * depth)  # NaN (invalid) pixels compare False


def grazing_pixels(depth: np.ndarray, K: np.ndarray, max_incidence_deg: float, window_px: int,
                   stride: int = 1) -> np.ndarray:
    """Pixels that see their surface at more than `max_incidence_deg` from its normal: (H, W) bool.

    A range error moves a point along its ray; seen at incidence theta, that is an error of
    ``tan(theta)`` times as much along the surface (a wall beside a doorway, seen obliquely from
    3 m with a depth 15 % long, is drawn across the doorway). The normal is that of the point
    cloud of the depth image, from central differences over `window_px` pixels of the
    `window_px`-box-filtered points (monocular noise is correlated over a few pixels).

    Args:
        depth: (H, W) float z-depth in metres, NaN (or <= 0) where invalid; invalid pixels and
            their neighbourhood are never grazing (depth edges are :func:`depth_edges`' job).
        K: (3, 3) pinhole intrinsics, pixels.
        max_incidence_deg: angle between the viewing ray and the surface normal, degrees, in (0, 90).
        window_px: odd smoothing window and difference span, pixels.
        stride: only the pixels of rows and columns 0, stride, 2 * stride, ... are judged (the others
            are False): those whose rays the map walks (``map.ray_stride_px``). The smoothing still
            reads every pixel, so a judged pixel's verdict is the same at any stride.
    """
    depth = np.asarray(depth, np.float32)
    H, W = depth.shape
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(depth) & (depth > 0)
    u = (np.arange(W, dtype=np.float32) - np.float32(K[0, 2])) / np.float32(K[0, 0])
    v = (np.arange(H, dtype=np.float32) - np.float32(K[1, 2])) / np.float32(K[1, 1])
    z = np.where(valid, depth, np.float32(0.0))
    points = np.stack([u[None, :] * z, v[:, None] * z, z], axis=-1)  # (H, W, 3) camera frame
    box = (window_px, window_px)
    points = cv2.blur(points, box, borderType=cv2.BORDER_REPLICATE)  # box filters run on sums: no NaN in
    whole = cv2.blur(valid.astype(np.float32), box, borderType=cv2.BORDER_REPLICATE) > 1.0 - 1e-4
    points[~whole] = np.nan  # a window with an invalid pixel has no normal
    h, stride = window_px // 2, int(stride)
    judged = points[::stride, ::stride]
    # central differences over the window: the smoothed points h pixels either side, NaN where one is off
    # the image; on the judged grid, the indices k0 .. k1 - 1 of the rows (columns) that have both
    along_u, along_v = np.full_like(judged, np.nan), np.full_like(judged, np.nan)
    k0, k1 = -(-h // stride), -(-(W - h) // stride)  # ceil: the first judged column >= h, the first >= W - h
    if k1 > k0:
        a, b = k0 * stride, (k1 - 1) * stride + 1
        along_u[:, k0:k1] = points[::stride, a + h:b + h:stride] - points[::stride, a - h:b - h:stride]
    k0, k1 = -(-h // stride), -(-(H - h) // stride)
    if k1 > k0:
        a, b = k0 * stride, (k1 - 1) * stride + 1
        along_v[k0:k1] = points[a + h:b + h:stride, ::stride] - points[a - h:b - h:stride, ::stride]
    normal = np.cross(along_u, along_v)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.abs(np.einsum("hwc,hwc->hw", normal, judged)) / (
            np.linalg.norm(normal, axis=-1) * np.linalg.norm(judged, axis=-1))
    out = np.zeros((H, W), bool)
    out[::stride, ::stride] = cos < np.cos(np.radians(max_incidence_deg))  # NaN (invalid near) compares False
    return out

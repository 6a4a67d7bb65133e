"""Emulated monocular depth: ground truth degraded the way monocular metric models err.

A monocular network sees the whole scene, not a range-limited sensor: its input is the
ground truth of every surface hit at any distance (the simulator's ``Frame.hit_depth``;
:attr:`EmulatedMonocularDepth.sees_past_range`), and its far depths come out far, wrong by
the error model, never clipped to the sensor's range (the occupancy map integrates only
up to its own range and carves free space along rays whose depth lies beyond it).

Applied in this order to the (H, W) float32 ground truth (metres, NaN invalid), each
effect configurable in ``configs/depth.yaml`` section ``emulated`` (which cites the
literature behind each magnitude):

1. **Dense fill** (``fill_invalid``): monocular models predict every pixel, so invalid
   ground truth (with ``hit_depth``: rays that hit nothing, e.g. through an opening to the
   sky) becomes ``fill_depth`` (``far``: as far as the model's output range) or the depth
   of the nearest valid pixel (``nearest``); ``none`` keeps it NaN.
2. **Edge bleeding** (``edge_threshold``, ``edge_band_px``, ``edge_sigma_px``): pixels
   whose relative depth jump to a 4-neighbour exceeds ``edge_threshold`` are depth edges;
   within ``edge_band_px`` of an edge, depth is replaced by its Gaussian mix
   (sigma ``edge_sigma_px``) of foreground and background, the "flying pixels" that
   upsampling decoders produce. Flat regions away from edges are untouched.
3. **Blur** (``blur_sigma_px``): a mild Gaussian blur everywhere; planar regions barely
   change.
4. **Global scale error** (``scale_sigma``, ``scale_per_frame``, ``frame_correlation``):
   depth is multiplied by ``s = exp(x)``, ``x ~ N(0, scale_sigma)``, drawn once per episode
   (:meth:`reset`) or, per frame, as a stationary AR(1) sequence
   ``x_t = rho x_(t-1) + sqrt(1 - rho^2) N(0, scale_sigma)`` with ``rho = frame_correlation``
   (0: independent frames): a per-frame network's scale wanders with the view.
5. **Noise** (``noise_sigma``, ``noise_sigma_per_m``, ``noise_smooth_px``, ``frame_correlation``):
   multiplicative Gaussian, ``d *= 1 + sigma(d) * n`` with
   ``sigma(d) = noise_sigma + noise_sigma_per_m * d`` and ``n`` a unit-variance field,
   spatially smoothed by ``noise_smooth_px`` (0 = white) and carried from frame to frame
   as the same AR(1) sequence (``n_t = rho n_(t-1) + sqrt(1 - rho^2) w_t``).
6. **Clamp** to ``[min_depth, max_depth]`` metres.

All randomness comes from one ``np.random.default_rng(seed)``: the same seed and the
same sequence of frames give the same output.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np
from scipy import ndimage

from ..errors import InputError
from ..geometry import distance_to_false
from ._conf import number
from .base import DepthSource, check_gt_depth, check_rgb

FILL_MODES = ("far", "nearest", "none")


def fill_invalid(depth: np.ndarray, mode: str, fill_depth: float) -> np.ndarray:
    """Fill NaN pixels of (H, W) float32 `depth` (metres): ``far``, ``nearest`` or ``none``."""
    invalid = np.isnan(depth)
    if mode == "none" or not invalid.any():
        return depth
    out = depth.copy()
    if mode == "nearest" and not invalid.all():
        _, (rows, cols) = ndimage.distance_transform_edt(invalid, return_indices=True)
        out[invalid] = depth[rows[invalid], cols[invalid]]
    else:  # far, or nearest with no valid pixel at all
        out[invalid] = fill_depth
    return out


def nan_gaussian(depth: np.ndarray, sigma_px: float) -> np.ndarray:
    """Gaussian blur of (H, W) float32 `depth` that ignores NaN pixels and keeps them NaN."""
    if sigma_px <= 0:
        return depth
    valid = np.isfinite(depth)
    num = ndimage.gaussian_filter(np.where(valid, depth, 0.0).astype(np.float64), sigma_px, mode="nearest")
    den = ndimage.gaussian_filter(valid.astype(np.float64), sigma_px, mode="nearest")
    with np.errstate(invalid="ignore", divide="ignore"):
        out = (num / den).astype(np.float32)
    out[~valid | (den < 1e-6)] = np.nan
    return out


def depth_edges(depth: np.ndarray, threshold: float) -> np.ndarray:
    """(H, W) bool: pixels whose relative depth jump to a 4-neighbour exceeds `threshold`.

    The jump between depths ``a`` and ``b`` is ``|a - b| / min(a, b)``; both pixels of a
    jumping pair are marked. NaN pixels are never edges.
    """
    edges = np.zeros(depth.shape, dtype=bool)
    with np.errstate(invalid="ignore", divide="ignore"):
        for axis in (0, 1):
            a = np.moveaxis(depth, axis, 0)[:-1]
            b = np.moveaxis(depth, axis, 0)[1:]
            jump = np.abs(a - b) / np.minimum(a, b) > threshold
            view = np.moveaxis(edges, axis, 0)
            view[:-1] |= jump
            view[1:] |= jump
    return edges


def bleed_edges(depth: np.ndarray, threshold: float, band_px: float, sigma_px: float) -> np.ndarray:
    """Smear (H, W) float32 `depth` within `band_px` of its depth edges (Gaussian mix)."""
    if band_px <= 0 or sigma_px <= 0:
        return depth
    edges = depth_edges(depth, threshold)
    if not edges.any():
        return depth
    band = distance_to_false(~edges) <= band_px  # scipy's transform, bit for bit, faster
    smeared = nan_gaussian(depth, sigma_px)
    return np.where(band, smeared, depth).astype(np.float32)


def correlated_noise(rng: np.random.Generator, shape: tuple[int, int], smooth_px: float) -> np.ndarray:
    """(H, W) float32 zero-mean unit-variance Gaussian field, smoothed by `smooth_px`."""
    noise = rng.standard_normal(shape)
    if smooth_px > 0:
        noise = ndimage.gaussian_filter(noise, smooth_px, mode="wrap")
        std = noise.std()
        noise = noise / std if std > 0 else noise
    return noise.astype(np.float32)


class EmulatedMonocularDepth(DepthSource):
    """Ground truth degraded like a monocular metric-depth model (see module docstring)."""

    name = "emulated"
    requires_ground_truth = True
    sees_past_range = True
    flying_pixels = True
    seeded = True

    def __init__(self, conf: Mapping[str, Any]) -> None:
        c = self.section(conf)
        self.scale_sigma = number(c, "scale_sigma", self.name)
        self.scale_per_frame = bool(c["scale_per_frame"])
        self.frame_correlation = number(c, "frame_correlation", self.name)
        if not self.frame_correlation < 1.0:
            raise InputError(f"depth.emulated.frame_correlation: must be in [0, 1), got {self.frame_correlation}")
        self.edge_threshold = number(c, "edge_threshold", self.name)
        self.edge_band_px = number(c, "edge_band_px", self.name)
        self.edge_sigma_px = number(c, "edge_sigma_px", self.name)
        self.blur_sigma_px = number(c, "blur_sigma_px", self.name)
        self.noise_sigma = number(c, "noise_sigma", self.name)
        self.noise_sigma_per_m = number(c, "noise_sigma_per_m", self.name)
        self.noise_smooth_px = number(c, "noise_smooth_px", self.name)
        self.fill_mode = str(c["fill_invalid"])
        if self.fill_mode not in FILL_MODES:
            raise InputError(f"depth.emulated.fill_invalid: expected one of {FILL_MODES}, got '{self.fill_mode}'")
        self.fill_depth = number(c, "fill_depth", self.name, minimum=1e-6)
        self.min_depth = number(c, "min_depth", self.name, minimum=1e-6)
        self.max_depth = number(c, "max_depth", self.name, minimum=self.min_depth)
        self.scale = 1.0
        self.reset(c["seed"])

    def reset(self, seed: int | None = None) -> None:
        """New episode: reseed (``None`` = fresh OS entropy), draw the episode's (or the first
        frame's) scale and forget the previous frame's noise."""
        self._rng = np.random.default_rng(seed)
        self._log_scale = float(self._rng.normal(0.0, self.scale_sigma))
        self.scale = float(np.exp(self._log_scale))
        self._noise: np.ndarray | None = None
        self._frames = 0

    def _carry(self, previous, fresh):
        """One step of the stationary AR(1) sequence: ``rho * previous + sqrt(1 - rho^2) * fresh``."""
        rho = self.frame_correlation
        return rho * previous + np.float32(np.sqrt(1.0 - rho * rho)) * fresh

    def _next_noise(self, shape: tuple[int, int]) -> np.ndarray:
        """(H, W) float32 unit-variance noise field of this frame, correlated with the last one's."""
        fresh = correlated_noise(self._rng, shape, self.noise_smooth_px)
        if self._noise is None or self._noise.shape != shape:
            self._noise = fresh
        else:
            self._noise = self._carry(self._noise, fresh).astype(np.float32)
        return self._noise

    def estimate(self, rgb: np.ndarray, K: np.ndarray, gt_depth: np.ndarray | None = None) -> np.ndarray:
        """(H, W) float32 metres from `gt_depth`; dense unless ``fill_invalid: none``.

        `gt_depth` is best the depth of every surface hit at any distance (NaN only where
        nothing is hit): a ground truth clipped at a sensor range has no far depths, and its
        beyond-range pixels get the fill of step 1. `rgb` (H, W, 3) uint8 fixes the size; `K`
        is not used (errors are image-space). Consecutive calls are consecutive frames.
        """
        rgb = check_rgb(rgb)
        depth = check_gt_depth(gt_depth, rgb.shape[:2], self.name)
        if self.scale_per_frame and self._frames > 0:  # the first frame keeps reset's draw
            self._log_scale = float(self._carry(self._log_scale, self._rng.normal(0.0, self.scale_sigma)))
            self.scale = float(np.exp(self._log_scale))
        self._frames += 1
        depth = fill_invalid(depth, self.fill_mode, self.fill_depth)
        depth = bleed_edges(depth, self.edge_threshold, self.edge_band_px, self.edge_sigma_px)
        depth = nan_gaussian(depth, self.blur_sigma_px)
        depth = depth * np.float32(self.scale)
        sigma = self.noise_sigma + self.noise_sigma_per_m * depth
        if np.any(sigma > 0):
            depth = depth * (1.0 + sigma * self._next_noise(depth.shape))
        with np.errstate(invalid="ignore"):
            depth = np.clip(depth, self.min_depth, self.max_depth)  # NaN stays NaN
        return depth.astype(np.float32)

"""Per-pixel cues of frontier pixels: occluded-side direction, depth, gain (paper III-E).

A frontier pixel sits on an occlusion edge. The depth gradient (a large Sobel kernel, so
that it is the direction across the edge rather than pixel noise) points across the edge
from the occluder (foreground) to what is seen past it (background). The frontier's depth
is the mean of the *foreground* depth (sampled ``sample_offset_px`` down the gradient, on
the occluder) and the *background* depth (as far up it): the frontier lies on the edge's
ray in the free space between the two.

The pixel's *occluded-side direction* is the unit image direction towards the occluded
side, i.e. down the depth gradient (towards smaller depth). The space the occluder hides
lies behind it, so it projects onto the occluder's side of the edge: in a top view, the
edge's ray beyond the occluder separates the seen free space (background side) from the
shadow (occluder side), and a camera at the frontier must turn towards the occluder's side
to look into the shadow. This is the direction the ground truth's gain views use
(``datagen.ground_truth``: from observed towards unobserved free voxels). At the end of
the sensor's range (invalid background) the forward part of the view direction dominates.

Invalid depth (NaN, inf or <= 0: nothing in range) is the far end of the sensor's range:

* for the gradient it is filled with twice the farthest valid depth, so an edge between
  a surface and "nothing within range" always has a clear step towards the invalid side;
* as a background sample it counts as the farthest valid depth of the image (about the
  sensor's range): the space behind the edge reaches at least that far, and a larger
  stand-in would put the frontier beyond anything observed;
* a foreground sample must be valid (no occluder: no frontier), else the pixel is dropped.

Images are (H, W), rows v and columns u (OpenCV pixel centres at integers).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .settings import AnchoringSettings

_FAR_FILL_FACTOR = 2.0  # invalid depth in the gradient image = this x the farthest valid depth
_MIN_GRADIENT_M_PER_PX = 1e-5  # flatter is "no gradient": float32 rounding on flat depth gives
                               # ~1e-7 m/px, the gentlest occlusion edge well over 1e-2 m/px


@dataclass
class FrontierPixels:
    """N frontier pixels with their cues (all arrays (N,) or (N, 2), float64).

    Attributes:
        u, v: (N,) pixel column and row.
        occluded_side: (N, 2) unit image direction (du, dv) towards the occluded side (down
            the depth gradient, onto the occluder).
        depth: (N,) metres, z-depth of the frontier: mean of foreground and background.
        gain: (N,) cubic metres.
    """

    u: np.ndarray
    v: np.ndarray
    occluded_side: np.ndarray
    depth: np.ndarray
    gain: np.ndarray

    def __len__(self) -> int:
        return len(self.u)

    def subset(self, index: np.ndarray) -> FrontierPixels:
        """The pixels at `index` (an int or bool index array)."""
        return FrontierPixels(self.u[index], self.v[index], self.occluded_side[index], self.depth[index],
                              self.gain[index])

    @classmethod
    def empty(cls) -> FrontierPixels:
        none = np.zeros(0, np.float64)
        return cls(none, none, np.zeros((0, 2), np.float64), none, none)


def valid_depth_mask(depth: np.ndarray) -> np.ndarray:
    """(H, W) bool: finite and positive depth (NaN, inf and 0 mean invalid)."""
    with np.errstate(invalid="ignore"):
        return np.isfinite(depth) & (depth > 0)


def depth_gradient(depth: np.ndarray, valid: np.ndarray, far_m: float, kernel_px: int) -> tuple[np.ndarray, np.ndarray]:
    """Sobel derivatives of depth along u and v, invalid depth filled as far.

    Args:
        depth: (H, W) float32 metres; valid: (H, W) bool; far_m: farthest valid depth.
        kernel_px: odd Sobel aperture (public code: 9).
    Returns:
        (H, W) float32 d(depth)/du and d(depth)/dv in metres per pixel (the Sobel response
        divided by its response to a unit ramp), smoothed over the kernel.
    """
    filled = np.where(valid, depth, np.float32(_FAR_FILL_FACTOR * far_m)).astype(np.float32)
    derivative, smoothing = cv2.getDerivKernels(1, 0, kernel_px)
    ramp_response = float((derivative.ravel() * np.arange(kernel_px)).sum() * smoothing.sum())
    grad_u = cv2.Sobel(filled, cv2.CV_32F, 1, 0, ksize=kernel_px, scale=1.0 / ramp_response,
                       borderType=cv2.BORDER_REPLICATE)
    grad_v = cv2.Sobel(filled, cv2.CV_32F, 0, 1, ksize=kernel_px, scale=1.0 / ramp_response,
                       borderType=cv2.BORDER_REPLICATE)
    return grad_u, grad_v


def _sample_depth(depth: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(N,) float64 depth at the nearest pixel of (u, v), clamped into the image (NaN stays NaN)."""
    H, W = depth.shape
    cols = np.clip(np.rint(u), 0, W - 1).astype(np.intp)
    rows = np.clip(np.rint(v), 0, H - 1).astype(np.intp)
    return depth[rows, cols].astype(np.float64)


def frontier_pixel_cues(frontier_mask: np.ndarray, gain_m3: np.ndarray, depth: np.ndarray,
                        settings: AnchoringSettings) -> FrontierPixels:
    """Occluded-side direction, depth and gain of every usable frontier pixel (paper III-E).

    Dropped: pixels of zero gain (with ``drop_zero_gain``), pixels without a depth
    gradient (no occluded side), pixels whose foreground sample is invalid, and pixels
    whose frontier depth is below ``min_depth_m``.

    Args:
        frontier_mask: (H, W) bool, F.
        gain_m3: (H, W) float32 cubic metres, G.
        depth: (H, W) float32 z-depth, metres; NaN, inf or <= 0 where invalid.
        settings: the anchoring settings.
    Returns:
        The kept pixels, in row-major order.
    """
    candidates = frontier_mask & (gain_m3 > 0) if settings.drop_zero_gain else frontier_mask
    valid = valid_depth_mask(depth)
    if not candidates.any() or not valid.any():
        return FrontierPixels.empty()
    far_m = float(depth[valid].max())
    grad_u, grad_v = depth_gradient(depth, valid, far_m, settings.gradient_kernel_px)
    rows, cols = np.nonzero(candidates)
    gradient = np.stack([grad_u[rows, cols], grad_v[rows, cols]], 1).astype(np.float64)
    norm = np.linalg.norm(gradient, axis=1)
    has_gradient = norm > _MIN_GRADIENT_M_PER_PX
    rows, cols, gradient, norm = rows[has_gradient], cols[has_gradient], gradient[has_gradient], norm[has_gradient]
    occluded_side = -gradient / norm[:, None]  # down the gradient: towards the occluder

    u, v = cols.astype(np.float64), rows.astype(np.float64)
    step = settings.sample_offset_px * occluded_side
    foreground = _sample_depth(depth, u + step[:, 0], v + step[:, 1])
    background = _sample_depth(depth, u - step[:, 0], v - step[:, 1])
    background = np.where(valid_depth_mask(background), background, far_m)
    with np.errstate(invalid="ignore"):
        frontier_depth = 0.5 * (foreground + background)
        keep = valid_depth_mask(foreground) & (frontier_depth >= settings.min_depth_m)
    gain = gain_m3[rows, cols].astype(np.float64)
    return FrontierPixels(u[keep], v[keep], occluded_side[keep], frontier_depth[keep], gain[keep])

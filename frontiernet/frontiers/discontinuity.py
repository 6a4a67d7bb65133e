"""Depth discontinuities F_d and the truncated distance field D (image space).

docs/design.md section 3, paper section III-D (FrontierNet, RA-L 2025). The ground truth
(``datagen``) builds its labels from them (F = F_p & F_d, then D), and the exploration
ablations of the paper's Fig. 9 (:mod:`frontiernet.exploration.ablations`) take F_d of the
robot's own depth in place of the network's frontiers. Moved here from ``datagen/labels.py``
(which re-exports them) because the library never imports ``datagen``.

All images are (H, W) in pixel coordinates (row v, column u); depth is metric z-depth in
metres with NaN where invalid, as the simulator renders it.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage


def discontinuity_mask(depth: np.ndarray, window_px: int, relative_jump: float, min_jump_m: float,
                       invalid_is_far: bool) -> np.ndarray:
    """F_d: pixels whose depth window spans a jump (a thresholded depth gradient).

    A pixel is a discontinuity when, over the ``window_px`` x ``window_px`` window around
    it, ``max - min > max(min_jump_m, relative_jump * min)``. Comparing the jump with the
    nearer depth keeps slanted floors and walls (smooth depth) out of the mask while
    occlusion edges (a door frame in front of the next room) mark both of their sides.

    Args:
        depth: (H, W) float32 metres, NaN where invalid.
        window_px, relative_jump, min_jump_m: the rule above (datagen's values:
            ``ground_truth.discontinuity`` of ``configs/datagen.yaml``).
        invalid_is_far: invalid pixels count as farther than every valid one (the end of
            the sensor's range is an edge); otherwise they are ignored.
    Returns:
        (H, W) bool.
    """
    depth = np.asarray(depth, np.float32)
    valid = np.isfinite(depth)
    if not valid.any():
        return np.zeros(depth.shape, bool)
    size = int(window_px)
    far = np.float32(np.inf)
    # minimum over valid pixels only; maximum with invalid pixels as +inf (or ignored)
    low = ndimage.minimum_filter(np.where(valid, depth, far), size=size, mode="nearest")
    high = ndimage.maximum_filter(np.where(valid, depth, far if invalid_is_far else -far), size=size,
                                  mode="nearest")
    with np.errstate(invalid="ignore"):
        jump = high - low
        mask = np.isfinite(low) & (jump > np.maximum(min_jump_m, relative_jump * low))
    return mask


def distance_field(frontier_mask: np.ndarray, truncation_px: float, return_nearest: bool = False):
    """D: Euclidean distance (pixels) from each pixel to the nearest pixel of F, truncated.

    Exactly 0 on F; ``truncation_px`` everywhere when F is empty (paper: r = 10 px).
    Stored in plain pixels; training normalises it to ``-log(D / r)``.

    Args:
        frontier_mask: (H, W) bool, F.
        return_nearest: also return the (2, H, W) int64 row/column of the nearest F pixel
            (meaningless where F is empty).
    Returns:
        (H, W) float32 pixels in [0, truncation_px] (and the nearest indices when asked).
    """
    frontier_mask = np.asarray(frontier_mask, bool)
    if not frontier_mask.any():
        field = np.full(frontier_mask.shape, truncation_px, np.float32)
        if return_nearest:
            return field, np.zeros((2,) + frontier_mask.shape, np.int64)
        return field
    if return_nearest:
        distance, nearest = ndimage.distance_transform_edt(~frontier_mask, return_indices=True)
    else:
        distance = ndimage.distance_transform_edt(~frontier_mask)
    field = np.minimum(distance, truncation_px).astype(np.float32)
    return (field, nearest) if return_nearest else field

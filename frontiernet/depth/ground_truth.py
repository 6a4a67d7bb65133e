"""Ground-truth depth: the simulator's depth map, passed through."""

from __future__ import annotations

import numpy as np

from .base import DepthSource, check_gt_depth, check_rgb


class GroundTruthDepth(DepthSource):
    """Returns ``gt_depth`` as (H, W) float32 metres, invalid (non-finite, <= 0) as NaN."""

    name = "ground_truth"
    requires_ground_truth = True

    def __init__(self, conf) -> None:
        """`conf` (the ``ground_truth`` section, empty) is taken for a uniform factory signature;
        there is nothing to tune."""

    def estimate(self, rgb: np.ndarray, K: np.ndarray, gt_depth: np.ndarray | None = None) -> np.ndarray:
        rgb = check_rgb(rgb)
        return check_gt_depth(gt_depth, rgb.shape[:2], self.name)

"""Pictures of the network's outputs: frontier pixels coloured by gain over the image."""

from __future__ import annotations

import cv2
import numpy as np


def gain_colours(num_classes: int) -> np.ndarray:
    """(K, 3) uint8 RGB per gain class: class 0 grey, then low gain blue to high gain red (turbo)."""
    ramp = cv2.applyColorMap(np.linspace(40, 255, num_classes - 1).astype(np.uint8)[:, None], cv2.COLORMAP_TURBO)
    return np.concatenate([[[160, 160, 160]], ramp[:, 0, ::-1]]).astype(np.uint8)


def frontier_overlay(rgb: np.ndarray | None, distance_px: np.ndarray, gain_class: np.ndarray,
                     frontier_threshold_px: float = 0.3, num_classes: int = 11, dilate_px: int = 1) -> np.ndarray:
    """(H, W, 3) uint8: the image dimmed, frontier pixels ``D < l`` painted in their gain class colour.

    Args:
        rgb: (H, W, 3) uint8 (None: a black background, for depth-only models).
        distance_px: (H, W) float32 predicted D in pixels; gain_class: (H, W) int in [0, K - 1].
        dilate_px: frontier lines are thickened by this many pixels so they show at a glance.
    """
    height, width = distance_px.shape
    base = np.zeros((height, width, 3), np.uint8) if rgb is None else rgb
    picture = (base.astype(np.float32) * 0.55).astype(np.uint8)
    frontier = (distance_px < frontier_threshold_px).astype(np.uint8)
    classes = gain_class.astype(np.int64)
    if dilate_px > 0 and frontier.any():
        kernel = np.ones((2 * dilate_px + 1,) * 2, np.uint8)
        # thicken the lines and carry each pixel's class outwards with them (max class wins)
        classes = cv2.dilate(np.where(frontier > 0, classes + 1, 0).astype(np.uint8), kernel).astype(np.int64) - 1
        frontier = cv2.dilate(frontier, kernel)
    colours = gain_colours(num_classes)
    mask = frontier > 0
    picture[mask] = colours[np.clip(classes[mask], 0, num_classes - 1)]
    return picture


def distance_picture(distance_px: np.ndarray, truncation_px: float) -> np.ndarray:
    """(H, W, 3) uint8: the distance field, bright at frontiers, dark at r = `truncation_px` (the
    labels' ``truncation_px``) and beyond."""
    closeness = 1.0 - np.clip(distance_px / float(truncation_px), 0.0, 1.0)
    grey = (closeness * 255).astype(np.uint8)
    return cv2.applyColorMap(grey, cv2.COLORMAP_INFERNO)[..., ::-1].copy()

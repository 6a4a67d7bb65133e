"""3D frontiers of one posed or unposed RGB-D frame (``frontiernet predict --intrinsics``).

Without a pose, the frame is placed in a *level camera frame*: origin at the camera, +x along
the optical axis levelled, +y to the left, +z up, assuming the camera was held level (pitch and
roll 0). Every frontier is also given in the OpenCV camera frame (x right, y down, z forward),
which needs no assumption.
"""

from __future__ import annotations

import numpy as np

from ..geometry import pose_from_heading

LEVEL_FRAME = "level camera frame: origin at the camera, +x forward (levelled), +y left, +z up (camera assumed level)"


def level_camera_pose() -> np.ndarray:
    """(4, 4) ``T_level_cam`` of a level camera at the origin looking along +x."""
    return pose_from_heading(0.0, 0.0, 0.0, 0.0)


def frame_frontiers(distance_field: np.ndarray, gain_class: np.ndarray, depth: np.ndarray, K: np.ndarray,
                    K_image: np.ndarray, labels: dict, anchoring, T_world_cam: np.ndarray | None = None,
                    gain_logits: np.ndarray | None = None) -> list[dict]:
    """The 3D frontiers of one frame (paper III-E) as JSON-ready records.

    Args:
        distance_field, gain_class, depth, K: the network's outputs, the depth it saw ((h, w)
            metres, NaN invalid) and the intrinsics at its input size.
        K_image: (3, 3) intrinsics of the original image (pixels are also reported there).
        labels: the model's label encoding; anchoring: ``configs/explore.yaml`` ``anchoring``.
        T_world_cam: the frame's pose (None: the level camera frame, :data:`LEVEL_FRAME`).
        gain_logits: (K, h, w) the network's gain-class logits (``anchoring.gain_decoding: expected``).
    Returns:
        Per frontier, largest first: ``position`` / ``direction`` (world or level frame),
        ``position_camera`` / ``direction_camera`` (OpenCV camera frame), ``gain_m3``,
        ``num_pixels``, ``pixel`` (u, v in the original image).
    """
    from ..frontiers.anchoring import anchor_prediction

    T = level_camera_pose() if T_world_cam is None else np.asarray(T_world_cam, np.float64)
    T_cam_world = np.linalg.inv(T)
    records = []
    for frontier in anchor_prediction(distance_field, gain_class, depth, K, T, anchoring, labels,
                                      gain_logits=gain_logits):
        ray = np.linalg.solve(K, np.array([*frontier.pixel, 1.0]))
        pixel = (K_image @ ray)[:2]
        records.append({
            "position": np.round(frontier.position, 4).tolist(), "direction": np.round(frontier.direction, 4).tolist(),
            "position_camera": np.round(T_cam_world[:3, :3] @ frontier.position + T_cam_world[:3, 3], 4).tolist(),
            "direction_camera": np.round(T_cam_world[:3, :3] @ frontier.direction, 4).tolist(),
            "gain_m3": round(float(frontier.gain_m3), 4), "num_pixels": int(frontier.num_pixels),
            "pixel": np.round(pixel, 1).tolist()})
    return records

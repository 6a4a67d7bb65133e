"""A Z-up world frame for a posed sequence.

The pipeline's world is Z-up (docs/design.md conventions): levelled frontier directions, the
tracker's height window and the map's height band all read the world z axis. Reconstructions
and trajectories come in any frame: COLMAP's first camera, Redwood's camera 0 (y down), a
motion-capture room. Hand-held and robot cameras are held roughly level, so the mean of
their "up" axes (camera -y in the world) is the gravity direction to within a few degrees;
that is the ``cameras`` mode (COLMAP's model_orientation_aligner makes the same
assumption for its image up-vectors).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

GRAVITY_MODES = ("cameras", "none")


def up_from_cameras(T_world_cams: np.ndarray) -> np.ndarray:
    """(3,) unit world vector: the mean "up" (-y) axis of the cameras.

    Args:
        T_world_cams: (N, 4, 4) float64 camera-to-world poses (OpenCV camera axes).
    Raises:
        InputError: the cameras' up axes cancel out (no common up direction).
    """
    up = -np.asarray(T_world_cams, np.float64)[:, :3, 1].mean(axis=0)
    norm = float(np.linalg.norm(up))
    if norm < 0.5:  # cameras rolled every which way: there is no "level" to read
        raise InputError(f"the cameras' up axes do not agree (mean length {norm:.2f} < 0.5): the sequence is "
                         f"not held level; set gravity: none and give poses in a Z-up world")
    return up / norm


def rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(3, 3) the smallest rotation taking unit vector `a` onto unit vector `b` (Rodrigues)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    axis = np.cross(a, b)
    sin, cos = float(np.linalg.norm(axis)), float(a @ b)
    if sin < 1e-12:
        if cos > 0:
            return np.eye(3)
        helper = np.eye(3)[int(np.argmin(np.abs(a)))]  # a half turn about any axis orthogonal to a
        axis = np.cross(a, helper)
        axis /= np.linalg.norm(axis)
        return 2.0 * np.outer(axis, axis) - np.eye(3)
    k = axis / sin
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + sin * cross + (1.0 - cos) * cross @ cross


def gravity_alignment(T_world_cams: np.ndarray, mode: str = "cameras") -> np.ndarray:
    """(4, 4) rigid ``T_aligned_world``: a world frame with +z up and the first camera at the origin.

    Args:
        T_world_cams: (N, 4, 4) float64 camera-to-world poses.
        mode: ``cameras`` (up = the cameras' mean up axis, :func:`up_from_cameras`) or
            ``none`` (the input world is Z-up already: identity).
    """
    if mode not in GRAVITY_MODES:
        raise InputError(f"gravity mode '{mode}' is unknown; valid: {', '.join(GRAVITY_MODES)}")
    T = np.eye(4)
    if mode == "none":
        return T
    poses = np.asarray(T_world_cams, np.float64)
    T[:3, :3] = rotation_between(up_from_cameras(poses), np.array([0.0, 0.0, 1.0]))
    T[:3, 3] = -T[:3, :3] @ poses[0, :3, 3]
    return T

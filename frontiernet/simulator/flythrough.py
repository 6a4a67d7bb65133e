"""A fly-through of a scene: a smooth collision-free camera path through its rooms.

Used by ``frontiernet demo`` (until the exploration demo exists) and handy to preview
scenes. The path is planned on the explorable voxels around camera height (free over
a band of +- the clearance, so obstacles just above or below count): it starts at the most open spot, then repeatedly goes to the
reachable cell farthest (geodesically) from where it is, keeping to corridor centres.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..errors import InputError
from ..geometry import arc_lengths, points_at_arc, poses_from_headings
from ..planning.grid import clearance_cost, geodesic_distance, shortest_path


def _smooth_polyline(points: np.ndarray, sigma: float) -> np.ndarray:
    if len(points) < 3 or sigma <= 0:
        return points
    return ndimage.gaussian_filter1d(points, sigma, axis=0, mode="nearest")


def _resample(points: np.ndarray, step: float) -> np.ndarray:
    """Resample an (N, 2) polyline at constant arc-length `step` (metres)."""
    arc = arc_lengths(points)
    if arc[-1] < step:
        return points[:1]
    return points_at_arc(points, arc, np.arange(0.0, arc[-1], step))


def plan_flythrough(scene, voxels, conf) -> np.ndarray:
    """Plan a fly-through; returns (N, 4, 4) float64 ``T_world_cam`` poses.

    Args:
        scene: the :class:`~frontiernet.scenes.Scene`.
        voxels: its :class:`~frontiernet.simulator.voxels.VoxelGrid`.
        conf: the ``flythrough`` section of ``configs/demo.yaml``.
    """
    size = voxels.voxel_size
    z = scene.bounds[0, 2] + float(conf.camera_height)
    k = int(np.clip((z - voxels.origin[2]) / size, 0, voxels.shape[2] - 1))
    # free in a vertical band around camera height, so obstacles just above or below count
    band = int(np.ceil(float(conf.min_clearance) / size))
    free = voxels.explorable[:, :, max(k - band, 0):k + band + 1].all(axis=2)
    if not free.any():
        raise InputError(f"{scene.metadata.spec}: no explorable space at camera height {conf.camera_height} m")
    clearance = ndimage.distance_transform_edt(free) * size
    cost = clearance_cost(clearance, float(conf.min_clearance), float(conf.centre_weight))
    if not np.isfinite(cost).any():
        raise InputError(f"{scene.metadata.spec}: no spot with {conf.min_clearance} m clearance at camera height")
    current = np.unravel_index(np.argmax(np.where(np.isfinite(cost), clearance, -1)), cost.shape)
    cells = [np.asarray([current])]
    for _ in range(int(conf.legs)):
        distance = geodesic_distance(cost, current)
        reachable = np.isfinite(distance)
        if reachable.sum() < 2:
            break
        goal = np.unravel_index(np.argmax(np.where(reachable, distance, -1)), cost.shape)
        path = shortest_path(cost, current, goal)
        if path is None or len(path) < 2:
            break
        cells.append(path[1:])
        current = goal
    cells = np.concatenate(cells).astype(np.float64)
    xy = voxels.origin[:2] + (cells + 0.5) * size
    xy = _resample(_smooth_polyline(_resample(xy, size / 2), float(conf.smoothing_m) / (size / 2)),
                   float(conf.step_m))[: int(conf.max_frames)]
    if len(xy) < 2:
        raise InputError(f"{scene.metadata.spec}: too little free space for a fly-through")
    # look at the path a little ahead, so the camera turns into doorways before it reaches them
    ahead = xy[np.minimum(np.arange(len(xy)) + int(conf.lookahead_frames), len(xy) - 1)]
    heading = np.where((np.arange(len(xy)) < len(xy) - 1)[:, None], ahead - xy, xy[-1] - xy[-2])
    yaw = np.unwrap(np.arctan2(heading[:, 1], heading[:, 0]))
    yaw = ndimage.gaussian_filter1d(yaw, float(conf.yaw_smoothing_frames), mode="nearest")
    positions = np.concatenate([xy, np.full((len(xy), 1), z)], axis=1)
    return poses_from_headings(positions, yaw, np.radians(float(conf.pitch_deg)))

"""Training views along simulated exploration trajectories.

Uniform pose sampling (:mod:`frontiernet.simulator.poses`) sees rooms from arbitrary
spots; an exploring robot instead moves along corridors and through doorways, looking
where it goes. :func:`sample_trajectory_poses` imitates that:

1. pick a random explorable voxel, find the floor below it with a downward ray (so
   multi-storey scenes work: the slice stays in the storey of that voxel) and put the
   camera ``camera_height_m`` (uniform) above it;
2. plan on the 2D grid of voxel columns that are explorable over a vertical band of
   +- ``min_clearance_m`` around that height (:meth:`~frontiernet.simulator.voxels.VoxelGrid.column_clearance`),
   with a clearance cost that keeps paths in the middle of free space;
3. start at the picked voxel's column (or a random free cell), pick a goal uniformly
   among the cells at least ``min_path_m`` away geodesically, take the cheapest path,
   smooth it and resample it every ``spacing_m``;
4. look at the path ``lookahead_m`` ahead, plus a uniform yaw jitter of
   +- ``yaw_jitter_deg``, with a pitch uniform in ``poses.pitch_range_deg``;
5. keep the poses inside the explorable volume and at least ``poses.min_clearance_m``
   from the mesh; draw paths until there are enough.

Frames and units: world Z-up, metres, radians; ``T_world_cam`` (4, 4) float64 with an
OpenCV camera (x right, y down, z forward), no roll.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from scipy import ndimage

from frontiernet.errors import InputError, number_range, positive_number
from frontiernet.geometry import arc_lengths, atan2, points_at_arc, poses_from_headings
from frontiernet.planning.grid import clearance_cost, geodesic_distance, shortest_path
from frontiernet.simulator.poses import as_generator, height_above_surface
from frontiernet.simulator.raycast import distance_to_surface
from frontiernet.simulator.voxels import VoxelGrid

if TYPE_CHECKING:
    from omegaconf import DictConfig

    from frontiernet.scenes import Scene

MAX_FAILED_PATHS = 100  # drawn paths that give no pose before giving up
_CENTRE_WEIGHT = 1.0  # clearance_cost weight: how strongly paths keep to the middle of free space
_SMOOTHING_VOXELS = 2.0  # Gaussian smoothing of the voxel-staircase path, in voxels (sigma)


def _number(conf, key: str, prefix: str, *, allow_zero: bool) -> float:
    return positive_number(conf[key], f"{prefix}.{key}", allow_zero=allow_zero)


def _pair(conf, key: str, prefix: str, lower: float, upper: float) -> tuple[float, float]:
    return number_range(conf[key], f"{prefix}.{key}", lower, upper)


def _trajectory_settings(conf, poses_conf) -> dict:
    """Validated settings from the ``sampling.trajectory`` and ``poses`` sections."""
    if "trajectory" in conf:
        conf = conf["trajectory"]
    if "poses" in poses_conf:
        poses_conf = poses_conf["poses"]
    t, p = "sampling.trajectory", "poses"
    pitch = _pair(poses_conf, "pitch_range_deg", p, -89.0, 89.0)
    return {
        "spacing": _number(conf, "spacing_m", t, allow_zero=False),
        "jitter": math.radians(_number(conf, "yaw_jitter_deg", t, allow_zero=True)),
        "lookahead": _number(conf, "lookahead_m", t, allow_zero=True),
        "min_path": _number(conf, "min_path_m", t, allow_zero=True),
        "height": _pair(conf, "camera_height_m", t, 0.0, math.inf),
        "clearance": _number(poses_conf, "min_clearance_m", p, allow_zero=True),
        "pitch": (math.radians(pitch[0]), math.radians(pitch[1])),
    }


def slice_cost(voxels: VoxelGrid, k: int, clearance_m: float) -> np.ndarray:
    """(X, Y) float64 planning cost for cameras in voxel layer `k` (inf = blocked).

    A column is free when it is explorable over the layers ``k +- ceil(clearance_m / size)``;
    cells closer than ``clearance_m + voxel_size`` (in-plane, to the nearest non-free cell
    centre) are blocked, the margin covering where inside a voxel the surface lies.
    """
    size = voxels.voxel_size
    clearance = voxels.column_clearance(k, math.ceil(clearance_m / size - 1e-9))
    return clearance_cost(clearance, clearance_m + size, _CENTRE_WEIGHT)


def path_headings(xy: np.ndarray, spacing: float, lookahead: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Resample an (N, 2) path every `spacing` metres and aim each point `lookahead` metres ahead.

    Returns:
        positions (M, 2) float64 metres, yaws (M,) float64 radians (direction from each
        point to the path point `lookahead` further on, or along the last segment), and
        the path length in metres.
    """
    arc = arc_lengths(xy)
    length = float(arc[-1])
    s = np.arange(0.0, length, spacing) if length > 0 else np.zeros(1)
    positions = points_at_arc(xy, arc, s)
    target = points_at_arc(xy, arc, np.minimum(s + max(lookahead, 1e-3), length))
    heading = target - positions
    short = np.linalg.norm(heading, axis=1) < 1e-6
    if short.any():  # lookahead reaches the end: look along the path's last stretch
        tangent = xy[-1] - points_at_arc(xy, arc, np.array([max(length - max(spacing, lookahead), 0.0)]))[0]
        heading[short] = tangent
    return positions, atan2(heading[:, 1], heading[:, 0]), length


def _draw_path(scene: Scene, voxels: VoxelGrid, rng: np.random.Generator, s: dict, free_index: np.ndarray,
               cache: dict) -> np.ndarray | None:
    """One trajectory: (M, 6) rows ``x, y, z, yaw, pitch, clearance`` of its valid poses, or None."""
    size = voxels.voxel_size
    pick = np.array(np.unravel_index(rng.choice(free_index), voxels.shape))
    centre = voxels.index_to_world(pick)
    floor = centre[2] - float(height_above_surface(scene, centre[None])[0])
    z = floor + rng.uniform(*s["height"])
    if not np.isfinite(z):  # nothing below the voxel
        return None
    k = math.floor((z - voxels.origin[2]) / size)
    if not 0 <= k < voxels.shape[2]:
        return None
    if k not in cache:
        cost = slice_cost(voxels, k, s["clearance"])
        passable = np.isfinite(cost)
        cache[k] = (cost, np.where(passable, 1.0, np.inf), np.flatnonzero(passable))
    cost, unit, cells = cache[k]
    if len(cells) < 2:
        return None
    start = tuple(pick[:2]) if np.isfinite(cost[tuple(pick[:2])]) else np.unravel_index(rng.choice(cells), cost.shape)
    length = geodesic_distance(unit, start) * size  # metres along 8-connected moves
    goals = np.flatnonzero(np.isfinite(length) & (length >= s["min_path"]))
    if len(goals) == 0:
        return None
    goal = np.unravel_index(rng.choice(goals), cost.shape)
    path = shortest_path(cost, start, goal)
    if path is None or len(path) < 2:
        return None
    xy = voxels.origin[:2] + (path + 0.5) * size
    arc = arc_lengths(xy)  # smooth the 8-connected staircase, sampled every half voxel
    fine = points_at_arc(xy, arc, np.append(np.arange(0.0, arc[-1], size / 2), arc[-1]))
    fine = ndimage.gaussian_filter1d(fine, 2.0 * _SMOOTHING_VOXELS, axis=0, mode="nearest")
    positions, yaw, path_length = path_headings(fine, s["spacing"], s["lookahead"])
    if path_length < s["min_path"] - 1e-9:
        return None
    m = len(positions)
    yaw = yaw + rng.uniform(-s["jitter"], s["jitter"], m)
    yaw = (yaw + np.pi) % (2 * np.pi) - np.pi
    pitch = rng.uniform(*s["pitch"], m)
    position = np.concatenate([positions, np.full((m, 1), z)], axis=1)
    ok = voxels.is_explorable(position)
    dist = np.zeros(m)
    if ok.any():
        dist[ok] = distance_to_surface(scene, position[ok])
    ok &= dist >= s["clearance"]
    if not ok.any():
        return None
    return np.concatenate([position, yaw[:, None], pitch[:, None], dist[:, None]], axis=1)[ok]


def sample_trajectory_poses(scene: Scene, voxels: VoxelGrid, n: int, rng, conf: DictConfig,
                            poses_conf: DictConfig) -> np.ndarray:
    """Sample `n` camera poses along simulated exploration paths (see module docstring).

    Consecutive rows come from the same path in order (about ``spacing_m`` apart, less
    where a pose was dropped) until the path ends and the next one starts.

    Args:
        scene: the scene (world frame, Z-up, metres).
        voxels: its :func:`~frontiernet.simulator.voxels.voxelize_scene` grid.
        n: number of poses (>= 0).
        rng: ``np.random.Generator`` (advanced in place) or an integer seed.
        conf: the ``sampling.trajectory`` section of ``configs/datagen.yaml`` (``spacing_m``,
            ``yaw_jitter_deg``, ``lookahead_m``, ``min_path_m``, ``camera_height_m``), or
            the ``sampling`` section holding it.
        poses_conf: the ``poses`` section of ``configs/sim.yaml`` (``min_clearance_m``,
            ``pitch_range_deg``) or a config holding it.
    Returns:
        (n, 4, 4) float64 ``T_world_cam``; every camera lies in the explorable volume, at
        least ``min_clearance_m`` from the mesh, with no roll.
    Raises:
        InputError: bad config values or `n`; or no `n` poses after
            :data:`MAX_FAILED_PATHS` paths that gave none (the message names the scene).
    """
    if not isinstance(n, (int, np.integer)) or isinstance(n, bool) or n < 0:
        raise InputError(f"number of poses must be an integer >= 0, got {n!r}")
    s = _trajectory_settings(conf, poses_conf)
    rng = as_generator(rng)
    free_index = np.flatnonzero(voxels.explorable)
    if len(free_index) == 0:
        raise InputError(f"{scene.metadata.spec}: no explorable voxels to plan trajectories in")
    found: list[np.ndarray] = []
    count, failed, cache = 0, 0, {}
    while count < n:
        rows = _draw_path(scene, voxels, rng, s, free_index, cache)
        if rows is None:
            failed += 1
            if failed >= MAX_FAILED_PATHS:
                raise InputError(
                    f"{scene.metadata.spec}: found only {count} of {n} trajectory poses; {failed} paths gave "
                    f"none (paths >= {s['min_path']} m with {s['clearance']} m clearance at "
                    f"{list(s['height'])} m above the floor); relax sampling.trajectory.* or poses.*")
            continue
        found.append(rows[: n - count])
        count += len(found[-1])
    rows = np.concatenate(found, axis=0) if found else np.zeros((0, 6))
    return poses_from_headings(rows[:, :3], rows[:, 3], rows[:, 4])

"""Camera poses in a scene's free space: seeded sampling and validity checks.

Frames and units (docs/design.md): world Z-up, metres, radians; camera frame OpenCV
(x right, y down, z forward); ``T_world_cam`` (4, 4) float64 maps camera coordinates
into the world. Sampled cameras have no roll.

A valid sampled pose

* lies in the scene's explorable volume (:class:`~frontiernet.simulator.voxels.VoxelGrid`),
* is ``height_range_m`` above the first surface straight below it (a downward ray),
* is at least ``min_clearance_m`` from every triangle of the mesh,
* looks along a uniform yaw in [-pi, pi) and a pitch uniform in ``pitch_range_deg``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..errors import InputError, number_range, whole_number
from ..geometry import poses_from_headings
from .raycast import cast_rays, distance_to_surface
from .voxels import VoxelGrid

if TYPE_CHECKING:
    from omegaconf import DictConfig

    from ..scenes import Scene


@dataclass
class SampledPoses:
    """Poses from :func:`sample_poses_detailed`.

    Attributes:
        T_world_cam: (N, 4, 4) float64 camera-to-world poses.
        positions: (N, 3) float64 camera centres, world metres.
        yaws, pitches: (N,) float64 radians (yaw about +z from +x; pitch > 0 looks up).
        heights: (N,) float64 metres above the first surface below the camera.
        clearances: (N,) float64 metres to the nearest triangle.
    """

    T_world_cam: np.ndarray
    positions: np.ndarray
    yaws: np.ndarray
    pitches: np.ndarray
    heights: np.ndarray
    clearances: np.ndarray


def poses_config(conf: "DictConfig") -> "DictConfig":
    """The ``poses`` section from `conf` (a whole sim config or the section)."""
    return conf["poses"] if "poses" in conf else conf


def _range(conf, key: str, lower: float = -np.inf) -> tuple[float, float]:
    return number_range(conf[key], f"poses.{key}", lower)


def as_generator(rng_or_seed) -> np.random.Generator:
    """A numpy Generator as given, or a new one from an integer seed >= 0."""
    if isinstance(rng_or_seed, np.random.Generator):
        return rng_or_seed
    if isinstance(rng_or_seed, (int, np.integer)) and not isinstance(rng_or_seed, bool) and rng_or_seed >= 0:
        return np.random.default_rng(int(rng_or_seed))
    raise InputError(f"pose sampling needs a seed (integer >= 0) or a numpy Generator, got {rng_or_seed!r}")


def height_above_surface(scene: "Scene", positions: np.ndarray) -> np.ndarray:
    """(N,) float64 distance (metres) from (N, 3) world points straight down to the first surface (inf: none)."""
    positions = np.asarray(positions, np.float64).reshape(-1, 3)
    rays = np.concatenate([positions, np.tile([0.0, 0.0, -1.0], (len(positions), 1))], axis=1)
    return cast_rays(scene, rays)["t_hit"].astype(np.float64)


def sample_poses_detailed(scene: "Scene", voxels: VoxelGrid, n: int, rng_or_seed,
                          conf: "DictConfig") -> SampledPoses:
    """Sample `n` valid camera poses (see module docstring); deterministic per seed.

    Args:
        scene: the scene (world frame, Z-up, metres).
        voxels: its :func:`~frontiernet.simulator.voxels.voxelize_scene` grid.
        n: number of poses (>= 0).
        rng_or_seed: integer seed or ``np.random.Generator``.
        conf: the ``poses`` section of ``configs/sim.yaml`` (or the whole sim config).
    Returns:
        :class:`SampledPoses` with N = `n`.
    Raises:
        InputError: bad config values or `n`, or fewer than `n` valid poses found among
            ``max_candidates`` candidates (the message says how many were found).
    """
    conf = poses_config(conf)
    if not isinstance(n, (int, np.integer)) or isinstance(n, bool) or n < 0:
        raise InputError(f"number of poses must be an integer >= 0, got {n!r}")
    rng = as_generator(rng_or_seed)
    h_min, h_max = _range(conf, "height_range_m", lower=0.0)
    p_min, p_max = np.deg2rad(_range(conf, "pitch_range_deg", lower=-89.0))
    if p_max >= np.deg2rad(89.0) + 1e-12:
        raise InputError(f"poses.pitch_range_deg must stay below 89 degrees, got {list(conf.pitch_range_deg)}")
    clearance = float(conf.min_clearance_m)
    if not clearance >= 0:
        raise InputError(f"poses.min_clearance_m must be >= 0 metres, got {conf.min_clearance_m!r}")
    batch, budget = int(conf.batch_size), int(conf.max_candidates)
    free = np.flatnonzero(voxels.explorable)
    if len(free) == 0:
        raise InputError(f"{scene.metadata.spec}: no explorable voxels to sample poses in")
    found: list[np.ndarray] = []
    count, tried = 0, 0
    while count < n and tried < budget:
        m = min(batch, budget - tried)
        tried += m
        index = np.stack(np.unravel_index(rng.choice(free, m), voxels.shape), axis=1)
        xy = voxels.index_to_world(index)
        xy[:, :2] += (rng.random((m, 2)) - 0.5) * voxels.voxel_size
        height = rng.uniform(h_min, h_max, m)
        yaw = rng.uniform(-np.pi, np.pi, m)
        pitch = rng.uniform(p_min, p_max, m)
        floor = xy[:, 2] - height_above_surface(scene, xy)  # first surface below the voxel centre
        position = np.concatenate([xy[:, :2], (floor + height)[:, None]], axis=1)
        ok = np.isfinite(floor)
        below = np.full(m, np.inf)
        below[ok] = height_above_surface(scene, position[ok])  # nothing between camera and floor
        ok &= (below >= h_min - 1e-6) & (below <= h_max + 1e-6)
        ok &= voxels.is_explorable(position)
        dist = np.zeros(m)
        if ok.any():
            dist[ok] = distance_to_surface(scene, position[ok])
        ok &= dist >= clearance
        take = np.flatnonzero(ok)[: n - count]
        found.append(np.concatenate([position[take], yaw[take, None], pitch[take, None],
                                     below[take, None], dist[take, None]], axis=1))
        count += len(take)
    if count < n:
        raise InputError(f"{scene.metadata.spec}: found only {count} of {n} valid camera poses among "
                         f"{tried} candidates (height {h_min}-{h_max} m above the floor, clearance "
                         f">= {clearance} m, inside the explorable volume); relax poses.* in the config")
    rows = np.concatenate(found, axis=0) if found else np.zeros((0, 7))
    return SampledPoses(T_world_cam=poses_from_headings(rows[:, :3], rows[:, 3], rows[:, 4]),
                        positions=rows[:, :3].copy(), yaws=rows[:, 3].copy(), pitches=rows[:, 4].copy(),
                        heights=rows[:, 5].copy(), clearances=rows[:, 6].copy())


def sample_poses(scene: "Scene", voxels: VoxelGrid, n: int, rng_or_seed, conf: "DictConfig") -> np.ndarray:
    """(n, 4, 4) float64 ``T_world_cam`` of valid camera poses; see :func:`sample_poses_detailed`."""
    return sample_poses_detailed(scene, voxels, n, rng_or_seed, conf).T_world_cam


def _fmt(p: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:.3f}" for v in p) + ")"


def _reaches_explorable(scene: "Scene", voxels: VoxelGrid, position: np.ndarray) -> bool:
    """Whether `position` is explorable, or sees the centre of an explorable neighbour voxel unobstructed.

    A camera a few centimetres from a wall lies in an occupied voxel; it is in free space
    when the straight segment to an adjacent explorable voxel crosses no surface.
    """
    if voxels.is_explorable(position[None])[0]:
        return True
    offsets = np.stack(np.meshgrid(*[np.arange(-1, 2)] * 3, indexing="ij"), -1).reshape(-1, 3)
    index = voxels.world_to_index(position)[None] + offsets
    index = index[voxels.in_grid(index)]
    index = index[voxels.explorable[index[:, 0], index[:, 1], index[:, 2]]]
    if len(index) == 0:
        return False
    delta = voxels.index_to_world(index) - position
    rays = np.concatenate([np.broadcast_to(position, delta.shape), delta], axis=1)
    return bool((cast_rays(scene, rays)["t_hit"] > 1.0).any())  # t in units of the segment length


def check_pose(scene: "Scene", voxels: VoxelGrid | None, pose: np.ndarray, conf: "DictConfig") -> np.ndarray:
    """Check that a camera pose is usable in `scene`; return its (3,) float64 position.

    Args:
        scene: the scene.
        voxels: its voxel grid, or None to skip the explorable-volume check.
        pose: (4, 4) ``T_world_cam`` (a rigid transform) or a (3,) position, world metres.
        conf: the ``poses`` section of ``configs/sim.yaml`` (or the whole sim config): the
            camera keeps ``render_clearance_m`` (metres) from the mesh.
    Raises:
        InputError: a malformed pose; "pose outside the scene" (outside the scene's
            bounds, or outside the building); "pose inside an obstacle" (closer than
            ``render_clearance_m`` to the mesh, or inside a wall or closed object).
    """
    arr = np.asarray(pose, np.float64)
    if arr.shape == (4, 4):
        R = arr[:3, :3]
        if not np.isfinite(arr).all() or not np.allclose(R.T @ R, np.eye(3), atol=1e-4) \
                or not np.isclose(np.linalg.det(R), 1.0, atol=1e-4) or not np.allclose(arr[3], [0, 0, 0, 1]):
            raise InputError(f"pose must be a rigid 4x4 camera-to-world transform, got {arr.tolist()}")
        position = arr[:3, 3].copy()
    elif arr.shape == (3,):
        position = arr.copy()
    else:
        raise InputError(f"pose must be a 4x4 T_world_cam or an (x, y, z) position, got shape {arr.shape}")
    if not np.isfinite(position).all():
        raise InputError(f"pose position must be finite, got {position.tolist()}")
    clearance = float(poses_config(conf).render_clearance_m)
    lo, hi = scene.bounds
    if np.any(position < lo - 1e-6) or np.any(position > hi + 1e-6):
        raise InputError(f"pose outside the scene: camera position {_fmt(position)} m is outside the bounds of "
                         f"{scene.metadata.spec} (min {_fmt(lo)}, max {_fmt(hi)})")
    dist = float(distance_to_surface(scene, position[None])[0])
    if dist < clearance:
        raise InputError(f"pose inside an obstacle: camera position {_fmt(position)} m is {dist:.3f} m from "
                         f"the mesh of {scene.metadata.spec} (minimum clearance {clearance} m)")
    if voxels is not None and not _reaches_explorable(scene, voxels, position):
        if voxels.is_occupied(position[None])[0] or voxels.is_enclosed(position[None])[0]:
            raise InputError(f"pose inside an obstacle: camera position {_fmt(position)} m is inside a wall or "
                             f"closed object of {scene.metadata.spec} (not in its explorable volume)")
        raise InputError(f"pose outside the scene: camera position {_fmt(position)} m is outside the building "
                         f"of {scene.metadata.spec} (not in its explorable volume)")
    return position

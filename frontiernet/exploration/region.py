"""Where the robot can be in a scene: its camera height, the main region it can travel, and start
poses drawn in it (the explorer's starts, the benchmark's shared starts, the step account's
reachable columns)."""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..geometry import pose_from_heading


def camera_z(scene, voxels, conf) -> float:
    """World z (metres) of the robot's camera: ``motion.camera_height_m`` above the floor of the
    storey the explorable space counts (``voxels.floor_layer``: the centre of the layer holding
    the surface under the seed's floor, within half a voxel of it; frontiernet/scenes/explorable.py),
    or above the scene's lowest point where that layer is the grid's bottom one or there is no seed."""
    floor = float(scene.bounds[0, 2])
    if voxels.floor_layer:  # a storey over the grid's bottom layer (a thin floor over a shaft, an upper storey)
        floor = float(voxels.origin[2]) + (voxels.floor_layer + 0.5) * voxels.voxel_size
    return floor + float(conf.motion.camera_height_m)


def _camera_clearance(scene, voxels, conf) -> tuple[float, np.ndarray]:
    """Camera height z (:func:`camera_z`) and the (X, Y) float64 clearance (metres) of each
    column over the planning band around it."""
    z = camera_z(scene, voxels, conf)
    return z, voxels.column_clearance(voxels.layer(z), _band_layers(voxels, conf))


def _band_layers(voxels, conf) -> int:
    """Voxel layers the planning band ``planner.height_band_m`` reaches on each side of the camera's."""
    return max(1, int(np.ceil(float(conf.planner.height_band_m) / voxels.voxel_size)))


def _band_past_the_room(scene, voxels, conf, z: float) -> str | None:
    """What a planning band (camera height z +- ``planner.height_band_m``) that takes in the floor's layer
    or the grid's top one reaches (``the floor``, ``the top of the scene``), None if neither: every column
    then holds an obstacle, which the band, not the clearance, put there."""
    k, band = voxels.layer(z), _band_layers(voxels, conf)
    floor = voxels.floor_layer if voxels.floor_layer else voxels.layer(float(scene.bounds[0, 2]))
    if k - band <= floor:
        return "the floor"
    return "the top of the scene" if k + band >= voxels.shape[2] - 1 else None


def _largest_region(traversable: np.ndarray) -> np.ndarray:
    """(X, Y) bool: the largest 8-connected region of `traversable` (as the planner's grid search moves)."""
    from scipy import ndimage

    labels, count = ndimage.label(traversable, structure=np.ones((3, 3), bool))
    if count == 0:
        return traversable
    return labels == 1 + int(np.argmax(np.bincount(labels.ravel())[1:]))


def start_sampler(scene, voxels, conf):
    """The scene's main region and a sampler of start poses in it, from one clearance map.

    The main region is the largest 8-connected region of columns at camera height at least
    ``planner.clearance_m`` from obstacles over the planning band (the robot's true traversable
    space). A start outside it is shut in a room whose doors are too narrow for the robot (KTH
    plans draw some office doors 0.5 m wide), and every method would explore that room alone.

    Returns:
        (region, draw): region, (X, Y) bool columns of the main region; draw(rng), a (4, 4)
        start pose: camera ``motion.camera_height_m`` above the scene's floor, at a random spot
        of the region at least ``run.start_clearance_m`` from obstacles, random heading. draw
        raises :class:`InputError` when the scene has no such spot (no free space at camera height).
    """
    z, clearance = _camera_clearance(scene, voxels, conf)
    region = _largest_region(clearance >= float(conf.planner.clearance_m))
    cells = np.argwhere((clearance >= float(conf.run.start_clearance_m)) & region)

    def draw(rng: np.random.Generator) -> np.ndarray:
        if not len(cells):  # named by the clearance that left none: the robot's own, or the start's within it
            reached = None if region.any() else _band_past_the_room(scene, voxels, conf, z)
            if reached is not None:  # (or by the planning band, where it takes in the floor or the top)
                raise InputError(f"{scene.metadata.spec}: the planning band, camera height {conf.motion.camera_height_m} "
                                 f"m +- planner.height_band_m = {conf.planner.height_band_m} m, reaches {reached}: "
                                 "every column holds an obstacle, so the robot has nowhere to be; use a smaller "
                                 "planner.height_band_m")
            key, value = (("planner.clearance_m", conf.planner.clearance_m) if not region.any()
                          else ("run.start_clearance_m", conf.run.start_clearance_m))
            most = float(clearance[region].max()) if region.any() else float(clearance.max(initial=0.0))
            where = "free space" if key.startswith("planner") else "spot of the robot's region"
            raise InputError(f"{scene.metadata.spec}: no {where} at camera height {conf.motion.camera_height_m} m "
                             f"keeps {key} = {value} m from obstacles (the most there: {most:.2f} m)"
                             + (", so the robot has nowhere to be" if key.startswith("planner") else " to start from"))
        i, j = cells[rng.integers(len(cells))]
        x, y = voxels.origin[:2] + (np.array([i, j]) + 0.5) * voxels.voxel_size
        return pose_from_heading(x, y, z, float(rng.uniform(-np.pi, np.pi)),
                                 np.radians(float(conf.motion.pitch_deg)))

    return region, draw


def sample_start(scene, voxels, conf, rng: np.random.Generator) -> np.ndarray:
    """One start pose drawn by :func:`start_sampler` (raises :class:`InputError` as its draw)."""
    return start_sampler(scene, voxels, conf)[1](rng)


__all__ = ["camera_z", "start_sampler", "sample_start"]

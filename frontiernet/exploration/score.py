"""What a run is scored on, kept against the scene's ground truth (docs/exploration.md, Outputs).

The robot never reads any of it. Coverage, the metric of Vox@k, is the fraction of the scene's
explorable voxels that the camera has observed: the rays of the rendered ground-truth depth,
whatever depth the robot itself uses, integrated into a map of their own. GLEAM's surface
coverage counts the scene's surface samples that map has hit
(:class:`~frontiernet.exploration.surface.SurfaceCoverage`); the reconstruction is GLEAM's
Chamfer distance from those samples to the robot's own map at the end.
"""

from __future__ import annotations

import numpy as np

from ..mapping import OccupancyMap
from .surface import SurfaceCoverage


class GroundTruthScore:
    """The run's scorekeeper.

    Args:
        scene: the :class:`~frontiernet.scenes.Scene` (world frame, Z-up, metres).
        voxels: its :class:`~frontiernet.simulator.voxels.VoxelGrid` (the explorable volume).
        conf: the run config (``map``: the coverage map's voxels and sensor model, ``surface``).
    """

    def __init__(self, scene, voxels, conf) -> None:
        self.voxels = voxels
        self.coverage_map = OccupancyMap.like(voxels, conf.map)  # ground-truth rays only
        self.surface = SurfaceCoverage(scene, conf, int(conf.surface.seed), voxels=voxels)
        self.surface_seen = np.zeros(self.surface.num_samples, bool)  # once seen, a surface point stays seen
        self.surface_coverage = 0.0
        self.counted = np.zeros(voxels.shape, bool)  # explorable voxels observed: coverage, kept per frame
        self._num_counted = 0

    def observe(self, depth: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray) -> None:
        """Count one camera frame: (H, W) float32 ground-truth z-depth in metres (NaN no hit),
        (3, 3) intrinsics, (4, 4) pose."""
        self.coverage_map.integrate(depth, K, T_world_cam)
        frame = self.coverage_map.latest_frame
        if frame is not None:  # only the frame's box can change: a large scene's step costs what it sees
            lo, seen = frame
            box = tuple(slice(a, a + n) for a, n in zip(lo, seen.shape))
            new = seen & self.voxels.explorable[box] & ~self.counted[box]
            self.counted[box] |= new
            self._num_counted += int(np.count_nonzero(new))
        self.surface_seen |= self.surface.covered_mask(self.coverage_map)
        self.surface_coverage = float(self.surface_seen.mean()) if len(self.surface_seen) else 0.0

    def coverage(self) -> float:
        """Fraction of the scene's explorable volume observed so far."""
        return self._num_counted / max(int(self.voxels.num_explorable), 1)

    def unseen_in(self, columns: np.ndarray, band: slice) -> float:
        """Fraction of the scene's explorable volume not observed so far in the columns of `columns`
        ((X, Y) bool over the scene grid's columns, e.g. the reachable ones:
        :func:`~frontiernet.exploration.steps.reachable_columns`) that the camera never saw at its own
        height: none of the column's explorable voxels in the layers `band` (a slice of the grid's
        z index) observed. Floor and ceiling voxels that no pose at the camera's height sees (beside
        the robot, in a small room) do not count once the camera has looked over their column."""
        observed, explorable = self.coverage_map.observed, self.voxels.explorable
        open_band = np.any(explorable[:, :, band], axis=2)
        looked_over = np.any(observed[:, :, band] & explorable[:, :, band], axis=2)
        counted = np.asarray(columns, bool) & open_band & ~looked_over
        unseen = explorable & ~observed & counted[:, :, None]
        return float(unseen.sum()) / max(int(self.voxels.num_explorable), 1)

    def reconstruction(self, robot_map: OccupancyMap) -> dict:
        """GLEAM's Chamfer distance and completeness of `robot_map` (:meth:`SurfaceCoverage.chamfer`)."""
        return self.surface.chamfer(robot_map)


__all__ = ["GroundTruthScore"]

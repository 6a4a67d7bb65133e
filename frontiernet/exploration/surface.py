"""GLEAM's exploration metrics: surface coverage, its AUC and the one-way Chamfer distance.

GLEAM (Chen et al., "GLEAM: Learning generalizable exploration policy for active mapping in
complex 3D indoor scenes", ICCV 2025) scores exploration on ground-truth surface points,
Poisson-disk samples of the scene mesh (100k per scene). Here:

* **samples**: ``num_points`` roughly Poisson-disk samples of the mesh: 3 n uniform samples
  thinned by :func:`trimesh.points.remove_close` to a spacing of ``sqrt(area / (5 n))``, then
  a seeded subset of n (trimesh's ``sample_surface_even`` returns 10-20 % too few; Open3D's
  Poisson disk takes ~13 s for 20k on the shared house, this 0.1 s). A sample is kept when its
  scene voxel's centre lies within ``max_distance_to_explorable_m`` of an explorable voxel's
  centre (:attr:`VoxelGrid.explorable`, distance transform; least over the voxels 1 % of a
  voxel away along each axis: faces on voxel boundaries round to either side). This drops
  what is never seen from inside: outer faces of walls, roofs, closed furniture.
* **surface coverage**: the fraction of samples whose voxel, or one within
  ``tolerance_voxels`` of it (Chebyshev: the 3 x 3 x 3 block at 1), is observed-occupied in
  the map (some camera ray ended there). Use the run's ``GroundTruthScore.coverage_map`` (ground-truth
  depth only). The candidate voxels are computed once per map grid: a step is one gather.
* **AUC** (:func:`coverage_auc`): area under the per-step coverage curve over the budget,
  divided by it (in [0, 1]).
* **one-way Chamfer**: mean distance from the samples to the nearest occupied voxel centre
  of the robot's map (lower is better; a perfect map of 0.1 m voxels scores ~0.03-0.05 m) and
  the completeness, the fraction of samples within ``completeness_threshold_m``.

World frame Z-up, metres. Settings: the ``surface`` section of ``configs/explore.yaml``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from ..config import ConfigSection, setting
from ..errors import InputError, positive_number, whole_number
from ..mapping import OccupancyMap

_OVERSAMPLE, _RADIUS_DIVISOR = 3, 5.0  # 3 n uniform samples thinned at sqrt(area / (5 n)) leave ~1.2-1.5 n


@dataclass(frozen=True)
class SurfaceSettings(ConfigSection):
    """The ``surface`` section of ``configs/explore.yaml`` (see there for each value)."""

    SECTION = "surface"

    num_points: int = setting(whole_number, 1)
    tolerance_voxels: int = setting(whole_number, 0, 3)
    max_distance_to_explorable_m: float = setting(positive_number, "metres")
    completeness_threshold_m: float = setting(positive_number, "metres")


def even_surface_samples(vertices: np.ndarray, triangles: np.ndarray, count: int, seed: int = 0) -> np.ndarray:
    """(count, 3) float64 roughly Poisson-disk samples (metres) of a triangle mesh, deterministic
    for `seed` (see the module docstring). `vertices` (V, 3) metres, `triangles` (T, 3) int."""
    import trimesh
    from trimesh.points import remove_close

    count, seed = whole_number(count, "count", 1), whole_number(seed, "seed", 0)
    mesh = trimesh.Trimesh(np.asarray(vertices, np.float64), np.asarray(triangles, np.int64), process=False)
    points, _ = trimesh.sample.sample_surface(mesh, _OVERSAMPLE * count, seed=seed)
    radius = np.sqrt(mesh.area / (_RADIUS_DIVISOR * count))
    for _ in range(20):  # shrink the radius until enough survive (one pass on real meshes)
        kept, _ = remove_close(points, radius)
        if len(kept) >= count:
            break
        radius *= 0.8
    subset = np.sort(np.random.default_rng(seed).choice(len(kept), size=min(count, len(kept)), replace=False))
    return np.asarray(kept[subset], np.float64)


class SurfaceCoverage:
    """Ground-truth surface samples of a scene and how much of them a map has observed (GLEAM).

    Args:
        scene: a :class:`~frontiernet.scenes.Scene` (world frame, Z-up, metres).
        conf: the ``surface`` section of ``configs/explore.yaml`` (or the whole config).
        seed: seeds the sampling (non-negative integer; a run's ``surface.seed``).
        voxels: the scene's :class:`~frontiernet.simulator.voxels.VoxelGrid` (the run's), for the
            explorable filter.
    Attributes:
        points: (P, 3) float64 world metres, the kept samples (read-only); num_sampled: the
            number drawn on the whole mesh before the explorable filter.
    Raises:
        InputError: a bad config value or seed; no sample near the explorable volume.
    """

    def __init__(self, scene, conf, seed: int, *, voxels) -> None:
        self.settings = SurfaceSettings.from_config(conf)
        points = even_surface_samples(scene.vertices, scene.triangles, self.settings.num_points, seed)
        self.num_sampled = len(points)
        # metres from each voxel centre to the nearest explorable one; a sample takes the least over
        # its voxel and those 1 % of a voxel away along +-x, +-y, +-z (see the module docstring)
        distance = np.pad(ndimage.distance_transform_edt(~voxels.explorable, sampling=voxels.voxel_size),
                          1, constant_values=np.inf)
        probes = np.vstack([np.zeros(3), np.eye(3), -np.eye(3)]) * 0.01 * voxels.voxel_size
        i, j, k = np.clip(voxels.world_to_index(points[:, None] + probes) + 1, 0, np.subtract(distance.shape, 1)).T
        keep = distance[i, j, k].min(axis=0) <= self.settings.max_distance_to_explorable_m
        if not keep.any():
            raise InputError(f"{scene.metadata.spec}: no surface sample lies within surface.max_distance_to_"
                             f"explorable_m = {self.settings.max_distance_to_explorable_m} m of the explorable volume")
        self.points = points[keep]
        self.points.flags.writeable = False
        steps = np.arange(-self.settings.tolerance_voxels, self.settings.tolerance_voxels + 1)
        self._offsets = np.stack(np.meshgrid(steps, steps, steps, indexing="ij"), -1).reshape(-1, 3)
        self._candidates: dict[tuple, np.ndarray] = {}

    @property
    def num_samples(self) -> int:  # P, the number of kept samples
        return len(self.points)

    def _candidate_ids(self, occupancy: OccupancyMap) -> tuple[np.ndarray, np.ndarray]:
        """(P, n) int64 flat ids of each sample's voxel and neighbours in `occupancy`'s grid (an
        off-grid one repeats an in-grid one of its row) and (P,) bool, the row has one in the grid;
        cached per grid (origin, voxel size, shape)."""
        key = (tuple(occupancy.origin.tolist()), float(occupancy.voxel_size), tuple(occupancy.shape))
        if key not in self._candidates:
            index = occupancy.world_to_index(self.points)[:, None, :] + self._offsets  # (P, n, 3)
            inside = occupancy.in_grid(index)
            flat = np.ravel_multi_index(tuple(np.where(inside[..., None], index, 0).transpose(2, 0, 1)),
                                        occupancy.shape)
            first = flat[np.arange(len(flat)), inside.argmax(axis=1)]
            self._candidates[key] = (np.where(inside, flat, first[:, None]), inside.any(axis=1))
        return self._candidates[key]

    def covered_mask(self, coverage_map: OccupancyMap) -> np.ndarray:
        """(P,) bool: an occupied voxel of `coverage_map` lies within tolerance_voxels of the sample's."""
        if not isinstance(coverage_map, OccupancyMap):
            raise InputError(f"coverage_map must be an OccupancyMap, got {type(coverage_map).__name__}")
        ids, on_grid = self._candidate_ids(coverage_map)
        threshold = coverage_map.settings.occupied_threshold
        hit = coverage_map.log_odds.reshape(-1)[ids] > threshold  # never-updated voxels hold 0 ...
        if threshold < 0:  # ... so unknown voxels count as occupied only below 0
            hit &= coverage_map.observed.reshape(-1)[ids]
        return hit.any(axis=1) & on_grid

    def covered_fraction(self, coverage_map: OccupancyMap) -> float:
        """Surface coverage in [0, 1]: the fraction of the samples `coverage_map` has observed."""
        return float(np.count_nonzero(self.covered_mask(coverage_map))) / self.num_samples

    def chamfer(self, robot_map: OccupancyMap) -> dict:
        """One-way Chamfer distance from the samples to `robot_map`'s occupied voxel centres.

        Returns ``{"chamfer_m": mean distance in metres, "completeness": fraction of samples within
        completeness_threshold_m}``; inf and 0 for a map with no occupied voxel."""
        if not isinstance(robot_map, OccupancyMap):
            raise InputError(f"robot_map must be an OccupancyMap, got {type(robot_map).__name__}")
        occupied = np.argwhere(robot_map.occupied_mask())
        if len(occupied) == 0:
            return {"chamfer_m": float("inf"), "completeness": 0.0}
        distance, _ = cKDTree(robot_map.index_to_world(occupied)).query(self.points)
        return {"chamfer_m": float(distance.mean()),
                "completeness": float(np.mean(distance <= self.settings.completeness_threshold_m))}


def coverage_auc(fractions: np.ndarray, max_steps: int) -> float:
    """Area under the surface coverage curve over the step budget, normalised to [0, 1] (GLEAM).

    `fractions`: (S + 1,) float coverages in [0, 1] after 0, 1, ..., S <= max_steps steps (a run
    that stopped early holds its last value to the budget). Returns the trapezoidal area over
    steps [0, max_steps] / max_steps: a constant curve gives it, a ramp from 0 to 1 gives 0.5."""
    max_steps = whole_number(max_steps, "max_steps", 1)
    values = np.asarray(fractions, np.float64)
    if values.ndim != 1 or len(values) == 0:
        raise InputError(f"fractions must be a non-empty 1D array of per-step coverages, got shape {values.shape}")
    if not np.all(np.isfinite(values)) or values.min() < 0.0 or values.max() > 1.0:
        raise InputError(f"fractions must lie in [0, 1], got values in [{values.min()}, {values.max()}]")
    if len(values) > max_steps + 1:
        raise InputError(f"fractions has {len(values)} values, more than max_steps + 1 = {max_steps + 1}")
    curve = np.concatenate([values, np.full(max_steps + 1 - len(values), values[-1])])
    return float((curve[:-1] + curve[1:]).sum() / (2.0 * max_steps))

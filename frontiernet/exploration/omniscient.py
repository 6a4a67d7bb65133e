"""The all-knowing bound, ``--method omniscient``: the view that sees the most unseen true volume
per metre of travel, chosen with the scene's ground truth (issue 54).

No robot has this knowledge: the method is a reference that every other method is reported as a
share of (``frontiernet bench --report``, "Share of the bound"). It is greedy, so not optimal, but it
is strong and honest:

* **It knows the truth where perception would guess.** A candidate view's gain is the volume of the
  scene's *explorable* voxels that no ground-truth ray has observed yet (exactly what the coverage
  metric still lacks: :class:`~frontiernet.exploration.score.GroundTruthScore`), seen from the view
  through the *true* occupancy (walls occlude, unknown space does not), within the camera's field of
  view and range.
* **It moves as every method does.** Candidate views lie on the robot's own planning grid, on cells
  it can reach over the map it has built (the explorer's move check refuses moves into unknown
  space, for this method as for all), on a lattice ``omniscient.candidate_spacing_m`` apart, each with
  the best of ``omniscient.yaw_count`` headings. The explorer's planner routes to the chosen one with
  the ``rate`` goal rule (gain / path length: volume per metre, each step being a fixed length), and
  the same motion, step counting and collision check apply.
* **It stops** when no reachable view sees ``tracking.min_gain_m3`` of unseen volume any more.

Cost: one frustum integration per (cell, heading) at a coarse raster (``view_width_px``; the volume
is integrated along each ray, so the raster sets noise, not bias), numba-compiled; cells farther
than the sensor's reach from any unseen explorable voxel are skipped without a ray, and a cell's
gains are kept until a voxel within its reach is seen (a frame changes a few metres of a large
scene, so most views are not integrated again). The unseen voxels themselves are patched in the box
each frame touched (:meth:`OccupancyMap.changes <frontiernet.mapping.OccupancyMap.changes>`), not
recomputed over the whole scene.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError, positive_number
from ..frontiers.anchoring import FrontierObservation
from ..geometry import distance_to_false, poses_from_headings
from ..mapping.bands import read_only
from ..mapping.traversal import frustum_volume
from ..planning.grid import reachable_region
from ..planning.planner import PlanningGrid
from .sources import FrontierSource, Method
from .perception import plain_view


@dataclass(frozen=True)
class ViewCandidates:
    """The candidate views of one frame.

    Attributes:
        xy: (N, 2) float64 world positions (metres), cell centres of the planning grid.
        yaw: (N,) float64 best heading of each (radians, world frame, 0 = +x).
        gain_m3: (N,) float64 unseen explorable volume the view at `xy`, `yaw` sees (m^3).
    """

    xy: np.ndarray
    yaw: np.ndarray
    gain_m3: np.ndarray


def lattice_cells(reachable: np.ndarray, spacing: int) -> np.ndarray:
    """(N, 2) int64 cells of `reachable` ((X, Y) bool) on the lattice ``i % spacing == j % spacing ==
    0`` (fixed in the world, so a candidate keeps its place and its tracker id from frame to frame)."""
    lattice = np.zeros_like(reachable)
    lattice[::spacing, ::spacing] = True
    return np.argwhere(reachable & lattice)


def near_unseen(unseen_columns: np.ndarray, cells: np.ndarray, reach_cells: float) -> np.ndarray:
    """(N,) bool: whether some column with unseen explorable volume lies within `reach_cells` of
    each of the (N, 2) `cells` (a view farther than its sensor's reach from all of them sees none)."""
    if not unseen_columns.any():
        return np.zeros(len(cells), bool)
    distance = distance_to_false(~unseen_columns)
    return distance[cells[:, 0], cells[:, 1]] <= reach_cells


class OmniscientSource(FrontierSource):
    """Candidate views scored with the ground truth (see the module docstring).

    Args:
        voxels: the scene's :class:`~frontiernet.simulator.voxels.VoxelGrid` (true occupancy and
            explorable volume).
        occupancy: the robot's map (:attr:`MethodContext.map`): where views are reachable.
        seen: the map of what ground-truth rays have observed: the run's coverage map
            (:attr:`GroundTruthScore.coverage_map <frontiernet.exploration.score.GroundTruthScore>`),
            which the explorer fills before the method proposes.
        conf: the run config (``omniscient``, ``planner``, ``motion.pitch_deg``).
        camera: the sim config's ``camera`` (field of view and range of the views).
        context: the run's :class:`~frontiernet.exploration.methods.MethodContext`, whose ``traversed``
            (where the robot has been, read each frame) the views' grid keeps open as the explorer's
            planner does; None: the map alone.
    """

    def __init__(self, voxels, occupancy, seen, conf, camera, context=None) -> None:
        settings = conf.omniscient
        self.voxels, self.map, self.seen, self.conf, self.context = voxels, occupancy, seen, conf, context
        self.width = int(positive_number(settings.view_width_px, "omniscient.view_width_px"))
        self.focal = float(camera.focal_px) * self.width / float(camera.width)  # the camera's field of view
        self.max_depth = float(camera.max_depth)
        self.pitch = np.radians(float(conf.motion.pitch_deg))
        self.yaws = np.arange(int(positive_number(settings.yaw_count, "omniscient.yaw_count"))) \
            * (2 * np.pi / int(settings.yaw_count))
        spacing = positive_number(settings.candidate_spacing_m, "omniscient.candidate_spacing_m", "metres")
        self.spacing = max(1, int(round(spacing / voxels.voxel_size)))
        self.passable = np.ascontiguousarray(~voxels.occupied)
        # a view's rays reach max_depth / cos(half the diagonal field of view) from its centre
        half_diagonal = np.arctan(np.sqrt(2.0) * (self.width / 2.0) / self.focal)
        self.reach_cells = self.max_depth / np.cos(half_diagonal) / voxels.voxel_size
        self.directions = self.seen._pixel_directions(self.width, self.focal)
        self.refresh_every = int(positive_number(settings.get("refresh_every_steps", 1), "omniscient.refresh_every_steps"))
        self.cached, self.frames_since = None, 0
        # gains of earlier scorings per grid cell and the camera height they saw; the columns in which
        # unseen voxels have been seen since
        self._gains: dict[tuple[int, int], np.ndarray] = {}
        self._scored_z, self._seen_since = None, None
        # the unseen explorable voxels and their columns, patched where the coverage map changes
        self._changes = seen.changes()
        self._unseen, self._unseen_columns = None, None
        # The camera never sees the planning band right under itself: its lowest ray (half the
        # vertical field of view below the pitch) reaches the band's bottom this far out, and the
        # grid keeps planner.clearance_m from that unknown. Within the ring the explorer leaves
        # along the frontier-tree edge (the planner's c*), so views beyond it are reachable.
        lowest = np.arctan(float(camera.height) / 2.0 / float(camera.focal_px)) - self.pitch
        self.ring_m = float(conf.planner.clearance_m) + float(conf.planner.height_band_m) / np.tan(lowest)

    def __call__(self, frame, depth, stopwatch):
        with stopwatch("anchoring"):
            if self._stale(frame.T_world_cam):
                self.cached, self.frames_since = self.candidates(frame.T_world_cam), 0
            self.frames_since += 1
            candidates = self.cached
        z = float(frame.T_world_cam[2, 3])
        observations = [FrontierObservation(np.array([x, y, z]), np.array([np.cos(yaw), np.sin(yaw), 0.0]),
                                            float(gain), 1, np.full(2, np.nan), frame.T_world_cam.copy())
                        for (x, y), yaw, gain in zip(candidates.xy, candidates.yaw, candidates.gain_m3)]
        return observations, plain_view(frame, depth)

    def _ring(self, grid: PlanningGrid, xy: np.ndarray) -> np.ndarray:
        """(X, Y) bool: the grid cells within :attr:`ring_m` of the robot at `xy` (2,)."""
        i, j = np.indices(grid.cost.shape)
        centre = (np.asarray(xy) - grid.origin_xy) / grid.cell_m - 0.5
        return (i - centre[0]) ** 2 + (j - centre[1]) ** 2 <= (self.ring_m / grid.cell_m) ** 2

    def _stale(self, T_world_cam: np.ndarray) -> bool:
        """Whether the candidates are scored again this frame: every ``omniscient.refresh_every_steps``
        frames, and whenever the robot has visited one by the tracker's rule (within
        ``tracking.visited_distance_m``, heading within ``visited_angle_rad``: it has arrived, and
        the next goal is chosen from fresh gains). In between, the last candidates are proposed
        again (the planner chooses at most every ``motion.replan_every_steps``)."""
        if self.cached is None or self.frames_since >= self.refresh_every:
            return True
        near = np.linalg.norm(self.cached.xy - T_world_cam[:2, 3], axis=1) < float(self.conf.tracking.visited_distance_m)
        facing = np.cos(self.cached.yaw - np.arctan2(T_world_cam[1, 2], T_world_cam[0, 2])) \
            > np.cos(float(self.conf.tracking.visited_angle_rad))
        return bool(np.any(near & facing))

    def unseen(self) -> np.ndarray:
        """(X, Y, Z) bool: explorable voxels no ground-truth ray has observed yet (read-only)."""
        self._update_unseen()
        return read_only(self._unseen)

    def _update_unseen(self) -> None:
        """Bring the unseen voxels, their columns and the columns seen since the last scoring up to
        date: whole on the first call, then only in the box the coverage map's updates touched (its
        voxels are only ever observed, never forgotten, so nothing outside that box changes)."""
        box = self._changes.take()
        if self._unseen is None:
            self._unseen = np.ascontiguousarray(self.voxels.explorable & ~self.seen.observed)
            self._unseen_columns = self._unseen.any(axis=2)
            self._seen_since = np.zeros_like(self._unseen_columns)
        elif box is not None:
            before = self._unseen[box]
            after = before & ~self.seen.observed[box]
            self._seen_since[box[:2]] |= (before & ~after).any(axis=2)
            self._unseen[box] = after
            self._unseen_columns[box[:2]] = self._unseen[box[:2]].any(axis=2)

    def _view_gains(self, cells: np.ndarray, centres: np.ndarray, z: float) -> np.ndarray:
        """(N, yaw_count) float64 unseen volume (m^3) the views at the (N, 2) grid `cells` (world
        `centres`, camera height `z`) see in each heading. A view's gain changes only when a voxel
        within its rays' reach is seen: the gains of earlier calls are kept for cells no column seen
        since lies within :attr:`reach_cells` of, and only the others are integrated again (the
        same values: each view's integral is its own)."""
        unseen = self._unseen  # brought up to date by the caller
        if self._scored_z == z:
            if self._seen_since.any() and self._gains:
                kept = np.array(list(self._gains))
                for cell in kept[near_unseen(self._seen_since, kept, self.reach_cells)]:
                    del self._gains[tuple(cell)]
        else:
            self._gains = {}
        self._scored_z = z
        self._seen_since[...] = False
        missing = [k for k, cell in enumerate(cells) if tuple(cell) not in self._gains]
        if missing:
            yaws = np.tile(self.yaws, len(missing))
            poses = poses_from_headings(np.column_stack([np.repeat(centres[missing], len(self.yaws), axis=0),
                                                         np.full(len(yaws), z)]), yaws, self.pitch)
            fresh = np.zeros(len(poses))
            frustum_volume(np.ascontiguousarray(poses[:, :3, 3]), np.ascontiguousarray(poses[:, :3, :3]),
                           self.directions, self.max_depth, self.focal, self.voxels.origin, self.voxels.voxel_size,
                           self.passable, unseen, fresh)
            for k, gains in zip(missing, fresh.reshape(len(missing), len(self.yaws))):
                self._gains[tuple(cells[k])] = gains
        return np.array([self._gains[tuple(cell)] for cell in cells]).reshape(len(cells), len(self.yaws))

    def candidates(self, T_world_cam: np.ndarray) -> ViewCandidates:
        """The reachable lattice views from the robot at `T_world_cam` ((4, 4), world frame) whose
        best heading sees at least ``tracking.min_gain_m3``, the ``omniscient.max_candidates``
        largest gains."""
        xy, z = T_world_cam[:2, 3], float(T_world_cam[2, 3])
        traversed = getattr(self.context, "traversed", None)
        grid = PlanningGrid.from_map(self.map, z, self.conf.planner, xy, None if traversed is None else traversed.mask)
        start = grid.cell(xy)
        empty = ViewCandidates(np.zeros((0, 2)), np.zeros(0), np.zeros(0))
        if not grid.inside(*start):
            return empty
        open_cells = np.isfinite(grid.cost) | (self._ring(grid, xy) if self.ring_m > 0 else False)
        reachable = reachable_region(open_cells, start)
        self._update_unseen()
        cells = lattice_cells(reachable, self.spacing)
        cells = cells[near_unseen(self._unseen_columns, cells, self.reach_cells)]
        if not len(cells):
            return empty
        centres = grid.centres(cells)
        gains = self._view_gains(cells, centres, z)
        best = np.argmax(gains, axis=1)
        gain = gains[np.arange(len(cells)), best]
        keep = np.flatnonzero(gain >= float(self.conf.tracking.min_gain_m3))
        keep = keep[np.argsort(-gain[keep], kind="stable")][:int(self.conf.omniscient.max_candidates)]
        return ViewCandidates(centres[keep], self.yaws[best[keep]], gain[keep])


def make_omniscient(context):
    """The ``omniscient`` method (:data:`~frontiernet.exploration.methods.METHODS`): candidate views
    proposed afresh each frame, goals by the ``rate`` rule (gain / path length)."""
    if context.voxels is None or context.map is None:
        raise InputError("the omniscient method needs the scene's voxels and the run's map")
    source = OmniscientSource(context.voxels, context.map, context.ground_truth().coverage_map, context.conf,
                              context.sim_conf.camera, context)
    return Method("omniscient", source, "rate", fresh_frontiers=True)


make_omniscient.needs_map = "plans its views in the robot's map"  # no --map-free (methods.check_method)


__all__ = ["OmniscientSource", "ViewCandidates", "lattice_cells", "near_unseen", "make_omniscient"]

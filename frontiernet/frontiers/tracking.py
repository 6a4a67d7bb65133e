"""Frontier bookkeeping across frames: merge, gain adjustment, invalidation (paper III-F).

docs/design.md item 5. Each frame's :class:`~frontiernet.frontiers.anchoring.FrontierObservation`
list is folded into a :class:`FrontierTracker`, whose frontiers keep stable integer ids:

* **Merge.** An observation closer than ``merge_distance_m`` to an existing frontier whose
  view direction differs by less than ``merge_angle_deg`` updates that frontier (running
  means of position, direction and predicted gain); otherwise it becomes a new frontier.
  With ``merge: clusters`` (the public code's rule), after the gains are reduced and the set
  pruned, frontiers are also merged in clusters (:meth:`FrontierTracker.merge_clusters`).
* **Gain.** A frontier's gain is its predicted gain minus the known free volume a virtual
  camera at the frontier, looking along its direction, sees in the occupancy map (the
  public code's map-based gain reduction), by default less the part that the frame which
  predicted it observed: the prediction already left that out.
* **Drop.** Frontiers whose gain falls below ``min_gain_m3`` (g_min), that lie in occupied
  space (after a move of at most ``relocate_m`` to the nearest unoccupied voxel: a frontier
  anchored beside a thin wall often falls into the wall's voxels), or that a visited pose has looked at (closer than ``visited_distance_m`` and
  heading within ``visited_angle_rad`` of the view direction) are removed.

Each frontier remembers the trajectory pose that last registered it (its parent in the
frontier tree, :mod:`frontiernet.planning.tree`). Frames: world Z-up, metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..geometry import atan2, pose_from_heading, poses_from_headings


@dataclass
class Frontier:
    """One tracked 3D frontier.

    Attributes:
        id: stable identifier (never reused within a tracker).
        position: (3,) float64 world metres.
        direction: (3,) float64 unit world view direction (where to look from the frontier).
        predicted_gain_m3: mean of the gains anchored for it (m^3).
        gain_m3: the predicted gain after the map-based reduction (m^3); used for planning.
        parent_pose: index (into the explorer's pose list) of the pose that last registered it.
        first_step, last_step: steps at which it was first and last observed.
        observations: number of merged observations.
        known_baseline_m3: known free volume its gain view sees of what the frame of its latest
            observation observed (the ``beyond_frame`` gain reduction does not subtract it: the
            prediction already left it out); None until the next
            :meth:`FrontierTracker.update_gains`.
    """

    id: int
    position: np.ndarray
    direction: np.ndarray
    predicted_gain_m3: float
    gain_m3: float
    parent_pose: int
    first_step: int
    last_step: int
    observations: int = 1
    known_baseline_m3: float | None = None

    @property
    def yaw(self) -> float:
        """Heading of the view direction in the world xy-plane (radians)."""
        return atan2(self.direction[1], self.direction[0])

    def camera_pose(self, pitch: float = 0.0, yaw_offset: float = 0.0) -> np.ndarray:
        """(4, 4) ``T_world_cam`` of a level camera at the frontier looking along its heading
        (turned by `yaw_offset` radians)."""
        return pose_from_heading(*self.position, self.yaw + yaw_offset, pitch)

    def as_dict(self) -> dict:
        """JSON-friendly record."""
        return {"id": self.id, "position": np.round(self.position, 4).tolist(),
                "direction": np.round(self.direction, 4).tolist(),
                "predicted_gain_m3": round(float(self.predicted_gain_m3), 4),
                "gain_m3": round(float(self.gain_m3), 4), "parent_pose": self.parent_pose,
                "first_step": self.first_step, "last_step": self.last_step, "observations": self.observations}


def _unit(vectors: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(vectors, axis=-1, keepdims=True)
    return vectors / np.maximum(norm, 1e-12)


def _heading_vectors(rotations: np.ndarray) -> np.ndarray:
    """(N, 3, 3) ``R_world_cam`` -> (N, 2) unit horizontal viewing directions (camera z in xy)."""
    forward = rotations[:, :2, 2]
    return _unit(forward)


@dataclass
class FrontierTracker:
    """The set of live frontiers, configured by the ``tracking`` section of ``configs/explore.yaml``.

    `view_z` (world metres): the height at which a frontier's gain view is placed and its
    position is checked against occupied space; the robot's camera height for a robot that
    keeps it (frontiers on the floor at the end of the sensor's range lie on a surface
    otherwise). None: the frontier's own height.
    """

    conf: dict
    view_z: float | None = None
    frontiers: dict = field(default_factory=dict)
    next_id: int = 0
    removed: dict = field(default_factory=lambda: {"low_gain": 0, "visited": 0, "occupied": 0, "blacklisted": 0})
    tombstones: list = field(default_factory=list)
    buried_visits: list = field(default_factory=list)  # positions (3,) of frontiers visited yet proposed still
    removed_log: list = field(default_factory=list)  # {"reason", **Frontier.as_dict()} per removal

    def __len__(self) -> int:
        return len(self.frontiers)

    def __iter__(self):
        return iter(list(self.frontiers.values()))

    def get(self, frontier_id: int) -> Frontier | None:
        return self.frontiers.get(frontier_id)

    def add(self, observations, parent_pose: int, step: int, average: bool = True) -> list[int]:
        """Fold one frame's observations in; returns the id each observation went to (None: it
        matched a blacklisted frontier, or lay outside ``height_window_m`` around `view_z` (and
        was no floor frontier at the end of the sensor's range, ``floor_range_end_m``), and was
        discarded).

        Args:
            observations: FrontierObservation-like records (``position``, ``direction``, ``gain_m3``;
                optionally ``T_world_cam``, the camera that saw it, for ``floor_range_end_m``).
            parent_pose: index of the pose that saw them (their parent in the frontier tree).
            step: the current step count.
            average: a merged observation updates running means (image frontiers, seen again
                and again); False: it replaces the frontier's position, direction and gain
                (map frontiers, recomputed from the whole map each frame).
        """
        max_distance = float(self.conf["merge_distance_m"])
        min_cos = float(np.cos(np.radians(float(self.conf["merge_angle_deg"]))))
        ids = []
        for observation in observations:
            position = np.asarray(observation.position, np.float64)
            direction = _unit(np.asarray(observation.direction, np.float64))
            if not self._in_height_window(position, getattr(observation, "T_world_cam", None)):
                ids.append(None)
                continue
            if self._buried(position, direction, max_distance, min_cos):
                ids.append(None)  # a blacklisted frontier seen again: it stays given up
                continue
            match = self._closest_match(position, direction, max_distance, min_cos)
            if match is None:
                frontier = Frontier(self.next_id, position.copy(), direction.copy(), float(observation.gain_m3),
                                    float(observation.gain_m3), parent_pose, step, step)
                self.frontiers[frontier.id] = frontier
                self.next_id += 1
            else:
                frontier = match
                n = frontier.observations if average else 0
                frontier.position = (frontier.position * n + position) / (n + 1)
                frontier.direction = _unit(frontier.direction * n + direction)
                frontier.predicted_gain_m3 = (frontier.predicted_gain_m3 * n + float(observation.gain_m3)) / (n + 1)
                frontier.gain_m3 = frontier.predicted_gain_m3
                frontier.observations += 1
                frontier.parent_pose = parent_pose  # the latest viewer: the freshest line of sight
                frontier.known_baseline_m3 = None  # a fresh prediction, relative to today's map
                frontier.last_step = step
            ids.append(frontier.id)
        return ids

    def _in_height_window(self, position: np.ndarray, T_world_cam: np.ndarray | None) -> bool:
        """Whether a frontier at `position` is kept by ``height_window_m`` around `view_z`: inside
        it, or below it (on the floor) at least ``floor_range_end_m`` from the camera that saw it
        (`T_world_cam`, None: unknown), where the end of the sensor's range, not an occluder, made it."""
        if self.view_z is None or self.conf.get("height_window_m") is None:
            return True
        low, high = (float(v) for v in self.conf["height_window_m"])
        height = float(position[2]) - self.view_z
        if low <= height <= high:
            return True
        range_end = self.conf.get("floor_range_end_m")
        if height > high or range_end is None or T_world_cam is None:
            return False
        return float(np.linalg.norm(position - np.asarray(T_world_cam)[:3, 3])) >= float(range_end)

    def _buried(self, position, direction, max_distance, min_cos) -> bool:
        return any(float(np.linalg.norm(p - position)) < max_distance and float(d @ direction) > min_cos
                   for p, d in self.tombstones) \
            or (len(self.buried_visits) > 0  # (one array op: the places grow with the run, the proposals come each frame)
                and float(np.linalg.norm(np.asarray(self.buried_visits) - position, axis=1).min()) < max_distance)

    def _closest_match(self, position, direction, max_distance, min_cos) -> Frontier | None:
        best, best_distance = None, max_distance
        for frontier in self.frontiers.values():
            distance = float(np.linalg.norm(frontier.position - position))
            if distance < best_distance and float(frontier.direction @ direction) > min_cos:
                best, best_distance = frontier, distance
        return best

    def merge_clusters(self) -> list[int]:
        """With ``merge: clusters``: merge every cluster of frontiers into one; returns the ids
        merged away (none with ``merge: nearest``). The public code's rule (cvg/FrontierNet,
        ``FrontierManager.merge_frontiers``, run after its gain adjustment and filter): DBSCAN
        with one sample per core over d = ||p_i - p_j||_1 + w (1 - cos(v_i, v_j)), eps
        ``merge_clusters.eps`` (1.8), w ``merge_clusters.direction_weight`` (2), i.e. the
        connected components of the graph d <= eps (single linkage). A cluster becomes one
        frontier with the oldest member's id: position the gain-weighted mean (weights gain, at
        least 1e-4 m^3), direction the normalised sum, predicted gain, gain and known baseline
        the plain means, the parent pose of its most recently observed member."""
        mode = str(self.conf.get("merge", "nearest"))
        if mode not in ("nearest", "clusters"):
            raise InputError(f"tracking.merge must be nearest or clusters, got {mode!r}")
        if mode == "nearest" or len(self.frontiers) < 2:
            return []
        from scipy.sparse.csgraph import connected_components

        conf = self.conf["merge_clusters"]
        frontiers = sorted(self.frontiers.values(), key=lambda f: f.id)
        positions = np.stack([f.position for f in frontiers])
        directions = _unit(np.stack([f.direction for f in frontiers]))
        distance = (np.abs(positions[:, None] - positions[None]).sum(-1)
                    + float(conf["direction_weight"]) * (1.0 - directions @ directions.T))
        count, labels = connected_components(distance <= float(conf["eps"]), directed=False)
        merged = []
        for label in range(count):
            members = [f for f, mine in zip(frontiers, labels == label) if mine]
            if len(members) < 2:
                continue
            keep, gains = members[0], np.array([max(f.gain_m3, 1e-4) for f in members])
            latest = max(members, key=lambda f: f.last_step)
            keep.position = np.average([f.position for f in members], axis=0, weights=gains)
            keep.direction = _unit(np.sum([f.direction for f in members], axis=0))
            keep.predicted_gain_m3 = float(np.mean([f.predicted_gain_m3 for f in members]))
            keep.gain_m3 = float(np.mean([f.gain_m3 for f in members]))
            baselines = [f.known_baseline_m3 for f in members]
            keep.known_baseline_m3 = None if None in baselines else float(np.mean(baselines))
            keep.parent_pose, keep.last_step = latest.parent_pose, latest.last_step
            keep.first_step = min(f.first_step for f in members)
            keep.observations = sum(f.observations for f in members)
            for frontier in members[1:]:
                self.remove(frontier.id, "merged")
                merged.append(frontier.id)
        return merged

    def update_gains(self, occupancy) -> None:
        """Reduce gains by the known free volume a virtual camera at each frontier sees in
        `occupancy` (an :class:`~frontiernet.mapping.OccupancyMap` that has just integrated the
        frame of the latest observations), per ``gain_reduction``:

        * ``beyond_frame``: gain = predicted - (visible known volume - the part of it that the
          frame of the frontier's latest observation saw). The prediction is the volume that
          frame did not observe (the ground truth's V_out, datagen), so only what the map knows
          beyond that frame is subtracted: space explored earlier or later, never twice.
        * ``absolute`` (public code): gain = predicted - visible known volume.
        * ``none``: gains stay as predicted.

        Then, with ``unknown_cap_yaw_offsets_deg``, no gain exceeds the unknown volume the gain
        view sees from the frontier at the best of those headings around its direction (as
        datagen's label takes the best heading): mapped surroundings end a frontier whatever
        its direction.
        """
        mode = str(self.conf["gain_reduction"])
        if mode not in ("beyond_frame", "absolute", "none"):
            raise InputError(f"tracking.gain_reduction must be beyond_frame, absolute or none, got {mode!r}")
        if not self.frontiers:
            return
        frontiers = list(self.frontiers.values())
        view = self.conf["gain_view"]
        settings = (int(view["width_px"]), float(view["focal_px"]), float(view["max_depth_m"]))
        positions = np.stack([f.position for f in frontiers])
        if self.view_z is not None:
            positions[:, 2] = self.view_z
        yaws = np.array([f.yaw for f in frontiers])
        poses = poses_from_headings(positions, yaws)
        known = occupancy.visible_known_volume(poses, *settings) if mode != "none" else np.zeros(len(frontiers))
        fresh = [i for i, f in enumerate(frontiers) if f.known_baseline_m3 is None]
        if mode == "beyond_frame" and fresh:
            seen = occupancy.visible_known_volume(poses[fresh], *settings, latest_frame_only=True)
            for i, volume in zip(fresh, seen):
                frontiers[i].known_baseline_m3 = float(volume)
        gains = np.empty(len(frontiers))
        for i, (frontier, volume) in enumerate(zip(frontiers, known)):
            baseline = frontier.known_baseline_m3 if mode == "beyond_frame" else 0.0  # (none: known = 0)
            gains[i] = frontier.gain_m3 = max(0.0, frontier.predicted_gain_m3 - max(0.0, float(volume) - baseline))
        offsets = self.conf.get("unknown_cap_yaw_offsets_deg")
        if offsets:  # no frontier gains more than the unknown volume it can still see
            cap = self._unknown_cap(occupancy, positions, yaws, gains, np.radians(np.asarray(list(offsets), np.float64)),
                                    settings)
            for frontier, limit in zip(frontiers, cap):
                frontier.gain_m3 = min(frontier.gain_m3, float(limit))

    @staticmethod
    def _unknown_cap(occupancy, positions: np.ndarray, yaws: np.ndarray, gains: np.ndarray, turns: np.ndarray,
                     settings: tuple) -> np.ndarray:
        """(F,) the most unknown volume (m^3) the gain views at `positions` (F, 3), turned by each
        of `turns` (radians) from `yaws` (F,), see, as far as it matters for ``min(gains, cap)``:
        headings are tried nearest to the frontier's own first, and a frontier leaves the search
        once one of them sees at least its gain (the cap no longer binds), so only frontiers
        whose gain the map may cut are viewed at every heading. Same result as taking the
        maximum over all headings, in a fraction of the views."""
        cap = np.zeros(len(yaws))
        undecided = np.ones(len(yaws), bool)
        for turn in turns[np.argsort(np.abs(turns), kind="stable")]:
            index = np.flatnonzero(undecided)
            if not len(index):
                break
            seen = occupancy.visible_unknown_volume(poses_from_headings(positions[index], yaws[index] + turn),
                                                    *settings)
            cap[index] = np.maximum(cap[index], seen)
            undecided[index] = cap[index] < gains[index]
        return cap

    def prune(self, visited_poses: np.ndarray, occupancy=None, bury_visited: bool = False) -> list[int]:
        """Drop low-gain, visited and (with `occupancy`) occupied frontiers; returns the dropped ids.

        Args:
            visited_poses: (N, 4, 4) float64 ``T_world_cam`` of the poses visited so far.
            bury_visited: a visited frontier also buries its place (``tracking.bury_visited``, for a
                method that proposes its whole frontier set afresh each frame): observations within
                ``merge_distance_m`` of it are discarded from then on, whatever their direction, until
                :meth:`forgive`. Such a frontier is still proposed, with at least ``min_gain_m3`` of
                unknown volume in view, after a pose stood at it facing it: the camera cannot see what it
                promises from there, and a frame later it comes back under a new id (a map frontier
                whose direction follows the robot drew it back for whole budgets).
        """
        if not self.frontiers:
            return []
        frontiers = list(self.frontiers.values())
        positions = np.stack([f.position for f in frontiers])
        reason = np.full(len(frontiers), "", dtype=object)
        low = np.array([f.gain_m3 < float(self.conf["min_gain_m3"]) for f in frontiers])
        reason[low] = "low_gain"
        visited_poses = np.asarray(visited_poses, np.float64).reshape(-1, 4, 4)
        if len(visited_poses):
            seen = self._visited(positions, np.stack([f.direction for f in frontiers]), visited_poses)
            reason[(reason == "") & seen] = "visited"
        if occupancy is not None:
            for index in np.flatnonzero(reason == ""):
                if not self._out_of_walls(frontiers[index], occupancy):
                    reason[index] = "occupied"
        dropped = []
        for frontier, why in zip(frontiers, reason):
            if why:
                if why == "visited" and bury_visited:
                    self.buried_visits.append(frontier.position.copy())
                self.remove(frontier.id, why)
                dropped.append(frontier.id)
        self._keep_best(int(self.conf["max_frontiers"]))
        return dropped

    def _out_of_walls(self, frontier: Frontier, occupancy) -> bool:
        """Whether `frontier` lies in space the map does not mark occupied (at `view_z`), after
        moving it to the nearest such voxel centre within ``relocate_m`` if it did not."""
        from ..mapping import OCCUPIED

        at = frontier.position.copy()
        if self.view_z is not None:
            at[2] = self.view_z
        if occupancy.state_at(at[None])[0] != OCCUPIED:
            return True
        radius = float(self.conf.get("relocate_m", 0.0))
        if radius <= 0:
            return False
        size = float(occupancy.voxel_size)
        centre = occupancy.origin + (np.floor((at - occupancy.origin) / size) + 0.5) * size
        steps = np.arange(-np.ceil(radius / size), np.ceil(radius / size) + 1) * size
        offsets = np.stack(np.meshgrid(steps, steps, indexing="ij"), -1).reshape(-1, 2)
        candidates = np.column_stack([centre[:2] + offsets, np.full(len(offsets), at[2])])
        distance = np.linalg.norm(candidates[:, :2] - at[:2], axis=1)
        order = np.argsort(distance[distance <= radius], kind="stable")
        candidates = candidates[distance <= radius][order]
        free = np.flatnonzero(occupancy.state_at(candidates) != OCCUPIED)
        if not len(free):
            return False
        frontier.position[:2] = candidates[free[0], :2]
        return True

    def _visited(self, positions: np.ndarray, directions: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """(F,) bool: some pose is within the visited distance and looks within the visited angle."""
        distance = np.linalg.norm(positions[:, None, :2] - poses[None, :, :2, 3], axis=-1)
        near = distance < float(self.conf["visited_distance_m"])
        if not near.any():
            return np.zeros(len(positions), bool)
        headings = _heading_vectors(poses[:, :3, :3])
        cos = _unit(directions[:, :2]) @ headings.T
        aligned = cos > np.cos(float(self.conf["visited_angle_rad"]))
        return (near & aligned).any(axis=1)

    def _keep_best(self, limit: int) -> None:
        if len(self.frontiers) <= limit:
            return
        ranked = sorted(self.frontiers.values(), key=lambda f: f.gain_m3, reverse=True)
        for frontier in ranked[limit:]:
            self.remove(frontier.id, "low_gain")

    def remove(self, frontier_id: int, reason: str) -> None:
        """Remove one frontier and count why (``low_gain``, ``visited``, ``occupied``, ``blacklisted``,
        ``merged``, ``stale``).

        A blacklisted frontier leaves a tombstone: observations matching it later are discarded,
        so a goal given up on (e.g. a window onto the outside) does not come back under a new id."""
        frontier = self.frontiers.pop(frontier_id, None)
        if frontier is not None:
            self.removed[reason] = self.removed.get(reason, 0) + 1
            self.removed_log.append({"reason": reason, **frontier.as_dict()})
            if reason == "blacklisted":
                self.tombstones.append((frontier.position.copy(), frontier.direction.copy()))

    def forgive(self) -> None:
        """Let every buried frontier be proposed again (the blacklist's tombstones and the visited places
        of ``bury_visited``)."""
        self.tombstones.clear()
        self.buried_visits.clear()

    def as_list(self) -> list[dict]:
        return [f.as_dict() for f in self.frontiers.values()]

"""The robot's move check: whether its own map allows one increment (docs/exploration.md).

The planner keeps routes ``planner.clearance_m`` from occupied cells; the move check tests each
increment against the map the robot has now, with the largest body those routes keep clear
(:func:`body_radius`), so that a fresh route passes it and a route that newer frames contradict
does not. It reads the robot's map only, never the scene: with ``planner.mode: map_free`` there
is no map to read. There every increment passes (the simulator's collision check is what stops
the robot), unless ``planner.obstacle_memory_frames`` > 0: then the check's only obstacles are
the robot's own depth points of that many recent frames within the planning band and within
reach of the body before they are forgotten (:meth:`MoveCheck.remember`), and an increment that
brings the body closer to one than its radius, and closer than it stands now, fails.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from ..errors import InputError, whole_number
from ..geometry import atan2, back_projected_points, grid_cells, squared_distance_to_cells
from ..mapping import FREE, UNKNOWN
from .motion import Motion, wrap_angle, yaw_of

ROUTE_SLACK_M = 0.01  # route points between two cell centres lie this much closer to a voxel, at most
LOOKED_AT_DEG = 20.0  # a point within this of the heading is faced (a quarter of the field of view)


def body_radius(planner_conf, voxel_size: float, agent_radius: float) -> float:
    """The body the move check tests, metres: ``planner.clearance_m`` (kept between route cell
    centres and occupied voxel centres) less a voxel's half diagonal and :data:`ROUTE_SLACK_M`
    for route points between cell centres, so a fresh route passes the occupied test on the
    map it was planned on.

    Raises:
        InputError: a clearance that leaves less than the agent's radius.
    """
    margin = float(voxel_size) / np.sqrt(2.0) + ROUTE_SLACK_M
    radius = float(planner_conf.clearance_m) - margin
    if radius < agent_radius:
        raise InputError(f"planner.clearance_m = {planner_conf.clearance_m} is too small for the agent radius "
                         f"{agent_radius} m: it must be at least {agent_radius + margin:.3f} m (radius + "
                         f"half a voxel's diagonal + {ROUTE_SLACK_M} m)")
    return radius


def looked_at(T_world_cam: np.ndarray, xy: np.ndarray) -> bool:
    """Whether the camera at the (4, 4) pose `T_world_cam` faces world point `xy` ((2,) metres;
    within :data:`LOOKED_AT_DEG` of its heading)."""
    offset = np.asarray(xy, np.float64) - T_world_cam[:2, 3]
    return abs(wrap_angle(atan2(offset[1], offset[0]) - yaw_of(T_world_cam))) < np.radians(LOOKED_AT_DEG)


class MoveCheck:
    """``check(T, target) -> (verdict, xy)``: whether the robot's map allows the increment from
    `T` to `target` ((4, 4) poses, world frame), with the world point ((2,) xy, metres) to face
    first when it says ``look``:

    - ``ok``: a turn, or a move into known free space where an upright cylinder of `radius`
      over the planning band (the planning grid's view of the body) touches no occupied voxel
      and, at the camera's height, no unknown one;
    - ``look``: the target, or an unknown voxel at the camera's height within the body, has
      not been faced yet (the camera maps it when it turns there);
    - ``fail``: occupied, or the target itself still unknown once faced.

    An unknown voxel beside the target that is still unknown once faced is passed and remembered
    (:attr:`faced_unknown`): the camera cannot map it from here, and facing it again would not
    either. The explorer holds a look over the next increments until the point is faced or
    mapped: turning back towards the waypoint in between undid each turn, forever (a livelock,
    docs/benchmark.md).

    The unknown test keeps the body off wall ends the camera never saw, which a move along a
    frontier-tree edge beyond the mapped space may pass close beside (the published
    benchmark's one collision, docs/benchmark.md). It looks at the camera's layer only: a voxel
    there within reach of the body is in the middle of the image once faced, whereas the band's
    lowest and highest layers lie below and above the field of view that close.

    Args:
        robot_map: the robot's :class:`~frontiernet.mapping.OccupancyMap`.
        motion: the run's :class:`~frontiernet.exploration.motion.Motion` (camera height, turns).
        planner_conf: the ``planner`` section (``height_band_m``, ``mode``, ``obstacle_memory_frames``).
        radius: the body's radius, metres (:func:`body_radius`).
        traversed: where the robot has been (:class:`~frontiernet.planning.traversed.TraversedCells`,
            with ``planner.traversed_is_free``; None: off): a move whose target lies in such a cell
            passes (``ok``) whatever the map says there now, as the planner plans through them.
    """

    def __init__(self, robot_map, motion: Motion, planner_conf, radius: float, traversed=None) -> None:
        self.map, self.motion, self.radius, self.traversed = robot_map, motion, float(radius), traversed
        half_band = float(planner_conf.height_band_m)
        self.band = (motion.z - half_band, motion.z + half_band)  # the planning grid's height band, metres
        self.map_free = str(planner_conf.mode) == "map_free"
        self.faced_unknown: list[np.ndarray] = []  # (2,) xy of camera-layer voxels faced and still unknown
        frames = whole_number(planner_conf.obstacle_memory_frames, "planner.obstacle_memory_frames")
        self.memory = deque(maxlen=frames) if self.map_free and frames > 0 else None  # (N, 2) xy per frame
        # a point farther than this from the camera cannot reach the body before it is forgotten
        self.memory_reach_m = self.radius + frames * motion.max_translation

    def remember(self, depth: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray) -> None:
        """Map-free mode with ``obstacle_memory_frames``: keep the frame's depth points ((H, W)
        float32 metres, NaN invalid; (3, 3) K; (4, 4) pose) in the planning band within
        :attr:`memory_reach_m` of the camera, as (N, 2) xy, for the next frames' checks. Pixels
        are taken at the stride that leaves samples at that reach one map voxel apart at most
        (nearer ones closer), far finer than the body."""
        if self.memory is None:
            return
        stride = max(1, int(self.map.voxel_size * float(K[0, 0]) / self.memory_reach_m))
        points = back_projected_points(depth, None, K, T_world_cam, self.memory_reach_m, stride)[0]
        in_band = (points[:, 2] >= self.band[0]) & (points[:, 2] <= self.band[1])
        near = np.hypot(*(points[:, :2] - T_world_cam[:2, 3]).T) <= self.memory_reach_m
        self.memory.append(points[in_band & near, :2])

    def _remembered_obstacle(self, T: np.ndarray, target: np.ndarray) -> bool:
        """Whether the target's body (`radius` around its xy) holds a remembered point, closer than
        the body at `T` is to its nearest one (moving away from an obstacle is allowed)."""
        points = np.concatenate(list(self.memory)) if self.memory else np.empty((0, 2))
        if not len(points):
            return False
        to_target = float(np.min(np.hypot(*(points - target[:2, 3]).T)))
        return to_target < self.radius and to_target < float(np.min(np.hypot(*(points - T[:2, 3]).T)))

    def __call__(self, T: np.ndarray, target: np.ndarray) -> tuple[str, np.ndarray | None]:
        if np.allclose(T[:2, 3], target[:2, 3]):
            return "ok", None
        if self.map_free:
            return ("fail", None) if self.memory is not None and self._remembered_obstacle(T, target) else ("ok", None)
        xy = target[:2, 3]
        if self._traversed(xy):
            return "ok", None
        if self.map.cylinder_touches_occupied(xy, self.radius, *self.band):
            return "fail", None
        if self.map.state_at(target[None, :3, 3])[0] != FREE:
            return ("fail" if looked_at(T, xy) else "look"), xy
        while True:
            unknown_xy = self.map.nearest_unknown_in_disk(xy, self.radius, self.motion.z, exclude=self.faced_unknown)
            if unknown_xy is None:
                return "ok", None
            if not looked_at(T, unknown_xy):
                return "look", unknown_xy
            # faced and still unknown: the camera cannot map it (between its rays, or hidden), so
            # facing it again would not either; it no longer holds the body back (the occupied test
            # still does, should it be mapped occupied later)
            self.faced_unknown.append(unknown_xy)

    def nearest_obstacle(self, xy: np.ndarray, reach_m: float) -> np.ndarray | None:
        """The point ((2,) float64 world xy, metres) nearest to world point `xy` ((2,) metres) on
        the squares of the planning band's occupied columns (as the occupied test sees them), among
        those within `reach_m`; None when there is none."""
        _, occupied = self.map.slice_2d(*self.band)  # the planner's band, cached until the map changes
        cell, origin = float(self.map.voxel_size), np.asarray(self.map.origin[:2], np.float64)
        lo = np.clip(grid_cells(xy[None] - reach_m, origin, cell)[0], 0, occupied.shape)
        hi = np.clip(grid_cells(xy[None] + reach_m, origin, cell)[0] + 1, 0, occupied.shape)
        cells = lo + np.argwhere(occupied[lo[0]:hi[0], lo[1]:hi[1]])
        if not len(cells):
            return None
        squared = squared_distance_to_cells(cells, origin, cell, xy)
        if squared.min() > reach_m ** 2:
            return None
        corner = origin + cells[int(np.argmin(squared))] * cell
        return np.clip(xy, corner, corner + cell)  # the square's point nearest to xy

    def blocked(self, xy: np.ndarray) -> bool:
        """Whether the map has an occupied voxel in the planning band over world point `xy` (2,):
        the planning grid's obstacle test, so the robot never walks (along a tree edge) onto cells
        it cannot plan from, such as a counter top below its body). Never where the robot has been
        (`traversed`)."""
        return not self._traversed(xy) and self.map.cylinder_touches_occupied(xy, 1e-6, *self.band)

    def _traversed(self, xy: np.ndarray) -> bool:
        """Whether the robot has passed through the cell under world point `xy` (2,) (False when
        ``planner.traversed_is_free`` is off)."""
        return self.traversed is not None and self.traversed.contains(xy)

    def unknown(self, xy: np.ndarray) -> bool:
        """Whether the map's voxel at world point `xy` ((2,) metres) at the camera's height is unknown."""
        return self.map.state_at(np.array([[xy[0], xy[1], self.motion.z]]))[0] == UNKNOWN

    def face(self, T: np.ndarray, xy: np.ndarray) -> np.ndarray:
        """The next pose turning on the spot from `T` towards world point `xy` (2,)."""
        offset = np.asarray(xy, np.float64) - T[:2, 3]
        return self.motion.turn_to(T, atan2(offset[1], offset[0]))[0]


__all__ = ["MoveCheck", "body_radius", "looked_at", "ROUTE_SLACK_M"]

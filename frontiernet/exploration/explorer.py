"""The closed exploration loop (paper III-E, III-F; docs/design.md items 4 to 7).

Each iteration: **sense** (render the camera frame, get the depth prior from the depth
source, run the perception (an image method's every ``tracking.observe_every_steps`` frames),
anchor its frontier pixels to 3D frontiers, integrate the depth
into the occupancy map, fold the frontiers into the tracker, reduce their gains by the
known volume, drop visited ones) -> **plan** (when the route is done, failed, or every
``replan_every_steps``: the best frontier by utility, its route over the map and the
frontier tree) -> **move** one increment (one paper step) with the simulator's collision
check. It stops when the step budget is spent or no frontier is left after looking around.

Coverage, the metric, is measured against the scene's ground truth: the fraction of the
explorable voxels that the camera has observed (rays of the rendered ground-truth depth),
whatever depth the robot itself uses (:mod:`.score`). Each increment passes the robot's move
check first (:mod:`.move_check`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError, whole_number
from ..frontiers import FrontierTracker
from ..planning.planner import FrontierPlanner, PlanningGrid, resample_route
from ..planning.traversed import TraversedCells
from ..planning.tree import PoseGraph
from ..simulator.agent import Agent
from ..timing import Stopwatch
from .methods import Method
from .motion import Motion, yaw_of
from .move_check import MoveCheck, body_radius, looked_at
from .perception import plain_view
from .steps import reachable_columns, run_account

STAGES = ("render", "depth", "perception", "anchoring", "map", "tracking", "planning", "motion", "coverage")
SIMULATOR_STAGES = ("motion", "coverage")
"""Timed stages of a step. ``motion`` (the simulator's collision check) and ``coverage`` (the
metric's ground-truth bookkeeping) are the simulator's cost, the others the robot's."""


@dataclass
class StepRecord:
    """What happened at one loop iteration (after its move and sensing)."""

    iteration: int
    step: int
    position: list
    yaw: float
    coverage: float
    surface_coverage: float
    known_m3: float
    frontiers: int
    goal: int | None
    collided: bool
    timings: dict


@dataclass
class ExplorationResult:
    """Everything a run produced (see :mod:`frontiernet.exploration.outputs` for the files)."""

    records: list = field(default_factory=list)
    poses: list = field(default_factory=list)
    goals: list = field(default_factory=list)
    stop_reason: str = ""
    collisions: int = 0
    path_length_m: float = 0.0
    explorable_m3: float = 0.0
    reconstruction: dict = field(default_factory=dict)  # GLEAM's Chamfer distance and completeness
    account: dict = field(default_factory=dict)  # where the steps go (:func:`.steps.run_account`)
    forgiven: int = 0  # times the goals given up on had another chance before a stop (planner.forgive_before_stop)
    widened_at_step: int | None = None  # the step the frontier source widened at, before a stop (FrontierSource.widen)


class Explorer:
    """One exploration run in the simulator.

    Args:
        context: the run's :class:`~frontiernet.exploration.methods.MethodContext`, which the
            method was built with: the scene and its
            :class:`~frontiernet.simulator.voxels.VoxelGrid` (the ground-truth explorable volume
            for coverage; the robot never reads it), the run config (``configs/explore.yaml`` with
            its sections), the sim config (the agent) and the robot's map, which the explorer
            fills and the method reads.
        renderer: a :class:`~frontiernet.simulator.camera.Renderer` of the scene.
        method: a :class:`~frontiernet.exploration.methods.Method`.
        depth_source: a :class:`~frontiernet.depth.DepthSource` (reset by the caller).
        T_start: (4, 4) start pose (level camera at the configured height).
        on_step: what consumes each iteration, in order: callables ``(explorer, record, frame,
            perception_result)`` (video frames and progress, a recording); none by default.
    """

    def __init__(self, context, renderer, method: Method, depth_source, T_start: np.ndarray, on_step=()) -> None:
        scene, voxels, conf = context.scene, context.voxels, context.conf
        self.scene, self.voxels, self.renderer = scene, voxels, renderer
        self.method, self.depth_source, self.conf = method, depth_source, conf
        self.map_free = str(conf.planner.mode) == "map_free"
        if str(conf.planner.mode) not in ("map", "map_free"):
            raise InputError(f"planner.mode must be 'map' or 'map_free', got {conf.planner.mode!r}")
        self.agent = Agent(scene, T_start, context.sim_conf.agent, voxels)
        # moves are checked with the largest body that planned routes keep clear of occupied voxels
        self.body_radius = body_radius(conf.planner, float(conf.map.voxel_size), self.agent.radius)
        self.motion = Motion(conf.motion, float(T_start[2, 3]))
        self.map = context.map
        # where the robot has been, open to the planner, the move check and the methods that plan their
        # own free space (planner.traversed_is_free; planner.monocular_traversed_is_free: with a depth
        # source whose map smears walls into the doorways the robot came through)
        keep_open = bool(conf.planner.traversed_is_free) or (
            bool(conf.planner.monocular_traversed_is_free) and bool(depth_source.flying_pixels))
        context.traversed = TraversedCells.like(self.map) if keep_open and not self.map_free else None
        self.traversed = context.traversed
        self.bumps_are_obstacles = bool(conf.planner.bumps_are_obstacles) and not self.map_free
        self.move_check = MoveCheck(self.map, self.motion, conf.planner, self.body_radius, self.traversed)
        self.score = context.ground_truth()  # the metrics; the robot never reads them
        self.tracker = FrontierTracker(conf.tracking, view_z=self.motion.z)
        self.planner = FrontierPlanner(conf.planner, goal=method.goal, seed=int(conf.run.seed),
                                       body_radius_m=self.body_radius)
        self.graph = PoseGraph(float(conf.planner.pose_link_m))
        self.poses: list[np.ndarray] = []
        self.on_step = tuple(on_step)
        self.route = None
        self.backoff = None  # (2,) xy to step back to: after a collision (map-free mode), or boxed in
        self.retreat_index = None  # while boxed in on the planning grid: the trajectory index stepped back to
        self.waypoint = 0
        self.look_xy = None  # (2,) world point the move check asked to face: turned to until faced or mapped
        self.steps_since_plan = 0
        self.look_around_left = np.radians(float(conf.motion.look_around_deg))
        self.start_turn_left = np.radians(float(conf.motion.start_turn_deg))
        self.result = ExplorationResult(explorable_m3=float(voxels.explorable_volume_m3))
        self.stopwatch = Stopwatch()  # this step's wall time per stage (StepRecord.timings, in ms)
        self.observe_every = whole_number(conf.tracking.observe_every_steps, "tracking.observe_every_steps", 1)
        start_failure = str(conf.planner.get("start_failure", "blame"))
        if start_failure not in ("blame", "step_back"):
            raise InputError(f"planner.start_failure must be 'blame' or 'step_back', got {start_failure!r}")
        self.step_back, self.start_failed_at = start_failure == "step_back", None
        self.escape = None  # (4, 4) pose to step to first: off a spot a fresh route could not start from
        self.forgive, self.forgiven_at_m3 = bool(conf.planner.get("forgive_before_stop", False)), -np.inf
        self.bury_visited = bool(conf.tracking.get("bury_visited", False))

    # -- sensing --------------------------------------------------------------------------------

    def sense(self):
        """Render at the current pose and update map and frontiers; returns (frame, perception result)."""
        T = self.agent.pose
        with self.stopwatch("render"):
            frame = self.renderer.render(T)
        # a monocular source degrades the depth of every hit, far ones included; the map keeps its range
        far = self.depth_source.sees_past_range and frame.hit_depth is not None
        ground_truth = frame.hit_depth if far else frame.depth
        with self.stopwatch("depth"):
            depth = self.depth_source.estimate(frame.rgb, frame.K, ground_truth)
        with self.stopwatch("map"):
            self._integrate(depth, frame, T)
        with self.stopwatch("coverage"):  # before the method: a reference that knows the truth reads it
            self.score.observe(frame.depth, frame.K, T)
        if self.method.fresh_frontiers or len(self.poses) % self.observe_every == 0:  # poses: frames tracked
            observations, seen = self.method.propose(frame, depth, self.stopwatch)
        else:  # between an image method's observations: the map and the bookkeeping go on
            observations, seen = [], plain_view(frame, depth)
        with self.stopwatch("tracking"):
            self._track(observations, T)
        return frame, seen

    def _integrate(self, depth, frame, T) -> None:
        self.map.integrate(depth, frame.K, T, monocular=self.depth_source.flying_pixels)
        self.map.clear_sphere(T[:3, 3], self.agent.radius)  # the robot stands in free space
        self.move_check.remember(depth, frame.K, T)  # map-free mode's recent obstacles (when asked for)

    def _track(self, observations, T) -> None:
        self.poses.append(T)
        index = self.graph.add(T[:2, 3])
        if self.traversed is not None:
            self.traversed.add(T[:2, 3])
        fresh = self.method.fresh_frontiers
        ids = self.tracker.add(observations, index, self.agent.steps, average=not fresh)
        if fresh:  # the proposals are the whole current set (map frontiers): the others are gone
            for frontier in list(self.tracker):
                if frontier.id not in ids:
                    self.tracker.remove(frontier.id, "stale")
        elif not self.map_free:
            self.tracker.update_gains(self.map)
        self.tracker.prune(np.stack(self.poses), None if self.map_free else self.map,
                           bury_visited=self.method.map_regions and self.bury_visited)
        if not fresh and self.tracker.merge_clusters():  # (merge: clusters) the public code filters again
            self.tracker.prune(np.stack(self.poses), None if self.map_free else self.map)

    # -- planning and motion --------------------------------------------------------------------

    def _parent_xy(self, index: int) -> np.ndarray:
        return self.poses[index][:2, 3]

    def plan(self) -> None:
        """Choose the goal and its route (keeping the current goal unless another is clearly better)."""
        xy = self.agent.position[:2]
        keep = self.route.frontier_id if self.route is not None and self.tracker.get(self.route.frontier_id) else None
        if self.map_free:
            route = self.planner.best_route(self.tracker, xy, self._parent_xy, graph=self.graph,
                                            robot_index=len(self.graph) - 1, keep=keep,
                                            keep_margin=float(self.conf.planner.goal_switch_margin))
        else:
            grid = PlanningGrid.from_map(self.map, self.motion.z, self.conf.planner, xy,
                                         None if self.traversed is None else self.traversed.mask)
            if grid.boxed_in(xy, float(self.conf.planner.clearance_m)):  # no goal is to blame: step back first
                self.route, self.backoff = None, self._retreat_point(xy)
                return
            self.retreat_index = None
            route = self.planner.best_route(self.tracker, xy, self._parent_xy, grid=grid, keep=keep,
                                            keep_margin=float(self.conf.planner.goal_switch_margin))
        for frontier_id in self.planner.blacklist:
            self.tracker.remove(frontier_id, "blacklisted")
        if route is not None:
            route = resample_route(route, xy, self.motion.max_translation)
        last = self.result.goals[-1]["frontier"] if self.result.goals else None
        if route is not None and route.frontier_id != last:  # a new goal (not the same one replanned)
            self.result.goals.append({"step": self.agent.steps, "frontier": route.frontier_id,
                                      "utility": round(route.utility, 4), "distance_m": round(route.distance_m, 3)})
        self.route, self.waypoint, self.steps_since_plan, self.look_xy = route, 0, 0, None

    def _away_pose(self, T: np.ndarray) -> np.ndarray | None:
        """Where to step before planning again when a fresh route could not start at `T` ((4, 4)
        pose): one increment straight away from the nearest occupied voxel of the planning band
        within reach of the body, heading kept (the robot backs or sidesteps off the wall), if the
        move check allows it; None otherwise. A (4, 4) pose."""
        xy = T[:2, 3]
        wall = self.move_check.nearest_obstacle(xy, self.body_radius + self.motion.max_translation)
        if wall is None or np.linalg.norm(xy - wall) < 1e-6:
            return None
        away = T.copy()
        away[:2, 3] = xy + (xy - wall) / np.linalg.norm(xy - wall) * self.motion.max_translation
        return away if self.move_check(T, away)[0] == "ok" else None

    def _retreat_point(self, xy: np.ndarray) -> np.ndarray | None:
        """The next earlier trajectory position (xy) to step back to while the robot is boxed in
        on the planning grid: it stands where the map allows no step (a counter top under the
        camera in the grid's height band: the body passed over it, the band does not), and every
        route would fail there and blacklist its goal. None when the trajectory is used up."""
        if self.retreat_index is None:
            self.retreat_index = len(self.poses) - 1
        while self.retreat_index > 0:
            self.retreat_index -= 1
            point = self.poses[self.retreat_index][:2, 3]
            if np.linalg.norm(point - xy) > 0.5 * self.motion.max_translation:
                return point.copy()
        return None

    def _route_failed(self) -> None:
        """The next increment of the route is not allowed by the map. A route planned on an
        older map is only dropped (the next round replans on today's map); a fresh one counts
        as a failure of its goal. With ``planner.start_failure: step_back``, a fresh route that
        cannot even start here (its first increment refused) counts once per step at most while the
        robot can step off the nearest wall (:meth:`_away_pose`), which it does before planning again:
        the spot, not the goal, is what the route could not leave, and replanning from it gives the
        same route."""
        if self.steps_since_plan > 0:
            self.route = None
        elif self.step_back and self.waypoint == 0:
            escape = self._away_pose(self.agent.pose)
            if escape is None or self.start_failed_at != self.agent.steps:  # without a step off, every time:
                self.start_failed_at = self.agent.steps  # nothing else would change before the next try
                self._goal_failed()
            self.route, self.escape = None, escape
        else:
            self._goal_failed()

    def _goal_failed(self) -> None:
        if self.route is not None:
            if self.planner.fail(self.route.frontier_id):
                self.tracker.remove(self.route.frontier_id, "blacklisted")
        self.route = None

    def next_pose(self) -> np.ndarray | None:
        """The pose of the next increment: the method's own move (:attr:`Method.moves
        <frontiernet.exploration.methods.Method.moves>`), else along the route (None: nothing to do)."""
        T = self.agent.pose
        if self.method.moves is not None:
            return self.method.moves.next_pose(T, self.motion, self.move_check)
        if self.escape is not None:  # off the spot a route could not start from (planner.start_failure)
            target, self.escape = self.escape, None
            return target
        if self.backoff is not None:
            target, self.backoff = self.backoff, None
            return self.motion.towards(T, target)
        if self.route is None:
            if self.look_around_left <= 0:
                return None
            self.look_around_left -= self.motion.max_rotation
            return self.motion.turn_by(T, self.motion.max_rotation)
        waypoints = self.route.waypoints
        while self.waypoint < len(waypoints) and self.motion.reached(T[:2, 3], waypoints[self.waypoint]):
            self.waypoint += 1
        if self.waypoint < len(waypoints):
            if self.waypoint >= self.route.mapped_until and not self.map_free and self.move_check.blocked(waypoints[self.waypoint]):
                self._route_failed()  # the frontier-tree edge runs into a mapped obstacle
                return None
            if self.look_xy is not None and not looked_at(T, self.look_xy) and self.move_check.unknown(self.look_xy):
                return self.move_check.face(T, self.look_xy)  # keep turning until faced or mapped, then check again
            self.look_xy = None
            target = self.motion.towards(T, waypoints[self.waypoint])
            verdict, look_xy = self.move_check(T, target)
            if verdict == "look":  # unknown ahead or beside: face it first, so the camera maps it
                # held over the next increments: turning back towards the waypoint in between
                # (a point more than one increment's turn off) would undo each turn, forever
                self.look_xy = look_xy
                return self.move_check.face(T, look_xy)
            if verdict == "fail":
                self._route_failed()
                return None
            return target
        frontier = self.tracker.get(self.route.frontier_id)
        if frontier is None:  # dropped on the way: visited, mapped or gain used up
            self.route = None
            return None
        pose, aligned = self.motion.turn_to(T, frontier.yaw)
        if aligned:
            self.route = None  # arrived; if the frontier survives the next prune it is not explained
            self.planner.fail(frontier.id)
        return pose

    def _forgive(self) -> bool:
        """With ``planner.forgive_before_stop``, before the run stops with no frontier left: give
        the goals given up on (blacklisted, and the frontiers their tombstones buried, and the places
        ``tracking.bury_visited`` buried) another chance when the map has learnt at least
        ``tracking.min_gain_m3`` since they last had one (a goal was given up on the map of its time; a
        longer run spends its steps instead of stopping while a route may now exist). Returns whether it
        did: the loop then looks around again, and the next frame proposes the buried frontiers anew."""
        known = float(self.map.known_volume_m3)
        if not self.forgive or not (self.planner.blacklist or self.tracker.buried_visits) \
                or known < self.forgiven_at_m3 + float(self.conf.tracking.min_gain_m3):
            return False
        self.forgiven_at_m3 = known
        self.planner.blacklist.clear()
        self.planner.failures.clear()
        self.tracker.forgive()
        self.look_around_left = np.radians(float(self.conf.motion.look_around_deg))
        self.result.forgiven += 1
        return True

    def _widen(self) -> bool:
        """Before the run stops with no frontier left (and nothing to forgive): the method's
        source proposes what it held back as noise (:meth:`~.sources.FrontierSource.widen`), and
        the loop looks around again. A run is the same up to the step it would have stopped at.
        Returns whether the source widened."""
        if self.method.source is None or not self.method.source.widen():
            return False
        self.look_around_left = np.radians(float(self.conf.motion.look_around_deg))
        self.result.widened_at_step = int(self.agent.steps)
        return True

    def _start_turn(self) -> np.ndarray | None:
        """The next increment of the turn on the spot at the start (``motion.start_turn_deg``), or
        None once it is done: the first goal is chosen from what the camera saw all around, not
        from the first frame's field of view only. Every method turns alike."""
        if self.start_turn_left <= 0:
            return None
        turn = min(self.motion.max_rotation, self.start_turn_left)
        self.start_turn_left -= turn
        self.look_around_left -= turn  # it is a look around: no second one if it finds no frontier
        return self.motion.turn_by(self.agent.pose, turn)

    def move(self, T_target: np.ndarray) -> bool:
        """One increment with the collision check; returns whether it collided."""
        result = self.agent.move_to(T_target)
        self.result.path_length_m += result.distance_m
        if result.collided or result.left_free_space:
            self.result.collisions += int(result.collided)
            if self.bumps_are_obstacles and result.contact_point is not None:  # (planner.bumps_are_obstacles)
                self.map.mark_contact(result.contact_point)  # then step off it before planning again
                if self.traversed is not None:
                    self.traversed.forget(result.contact_point[:2], float(self.conf.planner.clearance_m))
                self.escape = self._away_pose(self.agent.pose)
            self._goal_failed()
            if self.method.moves is not None:
                self.method.moves.bumped(self.agent.pose)
            if self.map_free and len(self.poses) > 1:  # no map to plan around it: step back first
                self.backoff = self.poses[-2][:2, 3].copy()
            return True
        return False

    # -- the loop -------------------------------------------------------------------------------

    def run(self, max_steps: int) -> ExplorationResult:
        """Explore until `max_steps` paper steps are spent or nothing is left to explore."""
        if int(max_steps) < 1:
            raise InputError(f"the step budget must be at least 1, got {max_steps}")
        max_iterations = 4 * int(max_steps) + 100  # increments that do not count as steps are rare
        collided = False
        frame, seen = self.sense()
        self._record(0, collided, frame, seen)
        for iteration in range(1, max_iterations + 1):
            if self.agent.steps >= max_steps:
                self.result.stop_reason = "step budget spent"
                break
            self.stopwatch.reset()
            start = time.perf_counter()
            target = self._start_turn()
            if target is None:
                if self.route is None or self.steps_since_plan >= int(self.conf.motion.replan_every_steps):
                    if len(self.tracker) or self.route is not None:
                        self.plan()
                self.stopwatch.seconds["planning"] = time.perf_counter() - start
                target = self.next_pose()
            if target is None:
                if self.route is None and not len(self.tracker) and self.look_around_left <= 0:
                    if self._forgive() or self._widen():
                        continue
                    self.result.stop_reason = "no frontiers left"
                    break
                continue  # a goal was dropped or failed: plan again (failures blacklist frontiers)
            if self.route is not None:
                self.look_around_left = np.radians(float(self.conf.motion.look_around_deg))
            with self.stopwatch("motion"):
                collided = self.move(target)
            self.steps_since_plan += 1
            frame, seen = self.sense()
            self._record(iteration, collided, frame, seen)
        else:
            self.result.stop_reason = "iteration limit"
        self.result.poses = [T.tolist() for T in self.agent.trajectory]
        self.result.reconstruction = self.score.reconstruction(self.map)
        unseen = self.score.unseen_in(*reachable_columns(self.scene, self.voxels, self.conf))
        self.result.account = run_account(self.result.records, max_steps, self.result.stop_reason,
                                          self.result.explorable_m3, unseen, self.conf)
        return self.result

    def _record(self, iteration: int, collided: bool, frame, seen) -> None:
        T = self.agent.pose
        record = StepRecord(iteration, self.agent.steps, np.round(T[:3, 3], 4).tolist(), round(yaw_of(T), 4),
                            self.score.coverage(), self.score.surface_coverage, float(self.map.known_volume_m3), len(self.tracker),
                            None if self.route is None else self.route.frontier_id, collided,
                            {k: round(v * 1e3, 2) for k, v in self.stopwatch.seconds.items()})
        self.result.records.append(record)
        for consumer in self.on_step:
            consumer(self, record, frame, seen)


__all__ = ["Explorer", "ExplorationResult", "StepRecord", "STAGES", "SIMULATOR_STAGES"]

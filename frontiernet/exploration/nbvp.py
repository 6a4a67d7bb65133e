"""NBVP, ``--method nbvp``: the receding-horizon next-best-view planner of Bircher et al.
("Receding Horizon Next-Best-View Planner for 3D Exploration", ICRA 2016; ethz-asl/nbvplanner).

Each planning call grows a rapidly-exploring random tree (RRT) in the robot's own map from the
robot's pose, as nbvplanner's ``RrtTree`` does:

1. **Root.** The robot's pose. The rest of the previous best branch is inserted first (nbvplanner's
   ``bestBranchMemory``), each node steered from its nearest tree node and checked again, so the
   work of the previous call is not lost.
2. **Nodes.** A position drawn uniformly over the free cells of the robot's map at the camera's
   height (known free there and ``planner.clearance_m`` from the obstacles of the planning grid:
   :meth:`NbvpPlanner.free_space`), in the connected region the robot stands in, is steered from
   its nearest tree node by at most ``nbvp.extension_m``; the edge (and ``nbvp.overshoot_m`` beyond
   it) must cross free cells only. Its yaw is drawn uniformly within ``nbvp.yaw_window_deg`` of its
   incoming edge's direction (the best of ``nbvp.yaw_samples`` draws; nbvplanner: one, uniform over
   the circle, which its MAV turns to while flying the edge; a ground robot holds a heading within
   ``motion.turn_in_place_deg`` of its travel only).
3. **Gain.** ``gain(node) = gain(parent) + v(node) * exp(-lambda * length)``, with ``v`` the unknown
   volume (m^3) a camera at the node sees through the map (walls occlude, unknown space does not:
   :meth:`~frontiernet.mapping.OccupancyMap.visible_unknown_volume`, the camera's field of view and
   pitch, up to ``nbvp.gain_range_m``), ``length`` the branch length from the root (metres) and
   ``lambda`` = ``nbvp.degressive_coeff``.
4. **Stop.** Once at least ``nbvp.init_iterations`` nodes exist and gain is found, or with no gain
   after ``nbvp.cutoff_iterations`` nodes: NBVP is done. Gain is found when the best node's branch
   promises more than ``tracking.min_gain_m3`` (g_min, below which the tracker drops every method's
   frontiers): with ``nbvp.found_on: views`` in the undiscounted sum of its views (the target's gain
   then), with ``discounted`` in its discounted gain; nbvplanner's threshold is ``nbvp/gain/zero``
   (0: any unknown voxel, discounted or not).
5. **Execute.** The best branch is the one ending at the node of highest gain; only its first edge
   is executed (the receding horizon), then the robot plans again from where it is.

How this fits the shared loop: :class:`NbvpSource` proposes each frame at most one
:class:`~frontiernet.frontiers.anchoring.FrontierObservation`: the first node of the best branch
(position at the camera's height, level direction along the node's yaw, gain = the branch's gain)
with ``fresh_frontiers``, and the explorer routes to it and moves with its own motion, move check,
step counting and collision check like every method. The target stays until a pose reaches it by
the tracker's visited rule (``tracking.visited_distance_m`` and ``visited_angle_rad``); then the
tree is grown again from there. Two deviations, both forced by the loop: a branch node that an
earlier pose has already reached by that rule would be dropped by the tracker at once, so the
target is the branch's first node no pose has reached (the edges before it were executed already);
and a target the loop cannot use (its spot now closer to an obstacle than the body's radius, or
the robot only turning on the spot for more than ``nbvp.stall_frames`` frames, as it does when the
tracker refused or gave up a target) is dropped and the tree grown anew. The next tree starts at
the robot's pose, not at the node (nbvplanner's ``exact_root``): the tree must start where the
robot is. Draws come from the run's generator (:attr:`MethodContext.rng`): a run repeats with its
seed. Frames: world Z-up, metres, radians (yaw about world z, 0 = +x).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..frontiers.anchoring import FrontierObservation
from .motion import wrap_angle, yaw_of
from .move_check import body_radius
from .nbvp_tree import NbvpPlanner, RrtTree
from .perception import plain_view
from .sources import FrontierSource, Method


@dataclass(frozen=True)
class ViewTarget:
    """The view the robot is sent to: a node of the best branch.

    Attributes:
        xy: (2,) float64 world position, metres. yaw: heading, radians.
        gain_m3: the best branch's gain, m^3 (``nbvp.found_on: views``: the undiscounted sum of its
            views, which the tracker holds against g_min). memory: (M, 3) float64 [x, y, yaw] of the branch's
            nodes after this one (inserted into the next tree).
    """

    xy: np.ndarray
    yaw: float
    gain_m3: float
    memory: np.ndarray


def visited(xy: np.ndarray, yaw: np.ndarray, poses: np.ndarray, distance_m: float, angle_rad: float) -> np.ndarray:
    """(K,) bool: whether one of the (P, 3) [x, y, yaw] `poses` stands within `distance_m` of each
    of the (K, 2) views `xy` looking within `angle_rad` of its (K,) `yaw`: the tracker's visited
    rule (:meth:`~frontiernet.frontiers.FrontierTracker.prune`)."""
    if not len(poses) or not len(xy):
        return np.zeros(len(xy), bool)
    near = np.hypot(*(xy[:, None, :] - poses[None, :, :2]).transpose(2, 0, 1)) < distance_m
    aligned = np.cos(yaw[:, None] - poses[None, :, 2]) > np.cos(angle_rad)
    return (near & aligned).any(axis=1)


class NbvpSource(FrontierSource):
    """NBVP's one proposal per frame (see the module docstring); timed as ``planning``.

    Args:
        occupancy: the run's map (:attr:`MethodContext.map`). conf: the run config (``nbvp``,
            ``planner``, ``tracking``, ``motion``, ``map.voxel_size``). camera: the sim config's
            ``camera``. rng: the run's generator. context: the run's
            :class:`~frontiernet.exploration.methods.MethodContext` (its ``traversed``, read for each
            tree: :meth:`NbvpPlanner.free_space`); None: the map alone.
    Attributes:
        planner: the :class:`NbvpPlanner`. target: the current :class:`ViewTarget` (None: none).
        tree: the latest tree grown (None before the first). trees: how many were grown.
        poses: (P, 3) float64 [x, y, yaw] of every frame so far (the tracker's visited poses).
    """

    def __init__(self, occupancy, conf, camera, rng: np.random.Generator, context=None) -> None:
        if occupancy is None:
            raise InputError("nbvp needs the run's map (a MethodContext with voxels)")
        self.planner = NbvpPlanner(occupancy, conf, camera, rng, context)
        self.map, self.conf = occupancy, conf
        self.body_m = body_radius(conf.planner, float(occupancy.voxel_size), 0.0)
        self.band = float(conf.planner.height_band_m)
        self.target: ViewTarget | None = None
        self.memory: np.ndarray | None = None  # (M, 3) the rest of the best branch, for the next tree
        self.tree: RrtTree | None = None
        self.trees = 0
        self.poses = np.zeros((0, 3))
        self.on_the_spot = 0  # frames without a change of position since the target was set

    def __call__(self, frame, depth, stopwatch):
        T = frame.T_world_cam
        with stopwatch("planning"):
            self.observe(T)
        observations = [] if self.target is None else [self.observation(float(T[2, 3]), T)]
        return observations, plain_view(frame, depth)

    def observe(self, T_world_cam: np.ndarray) -> ViewTarget | None:
        """One frame at the (4, 4) pose `T_world_cam`: keep, drop or replace the target; returns it."""
        pose = np.array([T_world_cam[0, 3], T_world_cam[1, 3], yaw_of(T_world_cam)])
        moved = not len(self.poses) or np.hypot(*(pose[:2] - self.poses[-1, :2])) > 1e-6
        self.poses = np.vstack([self.poses, pose])
        self.on_the_spot = 0 if moved else self.on_the_spot + 1
        if self.target is not None and self._target_done(pose, float(T_world_cam[2, 3])):
            self.target = None
        if self.target is None:
            self.target = self._plan(T_world_cam)
            self.on_the_spot = 0
        return self.target

    def _target_done(self, pose: np.ndarray, z: float) -> bool:
        """Whether the target is reached by `pose` ((3,) [x, y, yaw]), now too close to a mapped
        obstacle for the body, or stalled (turns on the spot only for over ``stall_frames`` frames)."""
        target = self.target
        if visited(target.xy[None], np.array([target.yaw]), pose[None], *self._visited_rule())[0]:
            return True
        if self.map.cylinder_touches_occupied(target.xy, self.body_m, z - self.band, z + self.band):
            return True
        return self.on_the_spot > self.planner.settings.stall_frames

    def _visited_rule(self) -> tuple[float, float]:
        return float(self.conf.tracking.visited_distance_m), float(self.conf.tracking.visited_angle_rad)

    def _plan(self, T_world_cam: np.ndarray) -> ViewTarget | None:
        """A new tree from the robot (with the remembered branch) and its target: the best branch's
        first node that no pose so far has reached (None: no gain, or every node reached)."""
        tree = self.planner.grow(T_world_cam, self.memory)
        self.tree, self.trees = tree, self.trees + 1
        if not tree.found:
            self.memory = None
            return None
        branch = tree.branch(tree.best)
        done = visited(tree.xy[branch], tree.yaw[branch], self.poses, *self._visited_rule())
        if done.all():
            self.memory = None
            return None
        first = int(np.argmin(done))  # the first node not reached
        rest = branch[first + 1:]
        self.memory = np.column_stack([tree.xy[rest], tree.yaw[rest]])
        node = branch[first]
        promise = tree.gain_m3 if tree.view_sum_m3 is None else tree.view_sum_m3  # nbvp.found_on
        return ViewTarget(tree.xy[node].copy(), float(wrap_angle(tree.yaw[node])), float(promise[tree.best]),
                          self.memory)

    def observation(self, z: float, T_world_cam: np.ndarray) -> FrontierObservation:
        """The target as the tracker takes it: at height `z` (metres), level direction along its
        yaw, gain the branch's; `T_world_cam` (4, 4) the frame's pose."""
        target = self.target
        return FrontierObservation(np.array([target.xy[0], target.xy[1], z]),
                                   np.array([np.cos(target.yaw), np.sin(target.yaw), 0.0]), target.gain_m3, 1,
                                   np.full(2, np.nan), np.array(T_world_cam, np.float64))


def make_nbvp(context) -> Method:
    """The ``nbvp`` method (:data:`~frontiernet.exploration.methods.METHODS`): one target a frame,
    the first node of the tree's best branch, routed to by the planner (goal rule ``utility``)."""
    source = NbvpSource(context.map, context.conf, context.sim_conf.camera, context.rng, context)
    return Method("nbvp", source, "utility", fresh_frontiers=True)


make_nbvp.needs_map = "grows its tree in the robot's map"  # no --map-free (methods.check_method)


__all__ = ["NbvpSource", "ViewTarget", "visited", "make_nbvp"]

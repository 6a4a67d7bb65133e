"""NBVP's tree (:mod:`.nbvp`): a rapidly-exploring random tree of views grown in the robot's own map,
node gains discounted by branch length, and the stop rule, as ethz-asl/nbvplanner's ``RrtTree``.
Frames: world Z-up, metres, radians (yaw about world z, 0 = +x)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from scipy import ndimage

from ..errors import InputError, positive_number, whole_number
from ..geometry import cells_inside, distance_to_false, grid_cells, poses_from_headings
from .motion import yaw_of
from .move_check import body_radius


FOUND_ON = ("discounted", "views")
SAMPLE_REGIONS = ("known_free", "box")
EDGE_CHECKS = ("body", "cells")


@dataclass(frozen=True)
class NbvpSettings:
    """The checked ``nbvp`` section of ``configs/explore.yaml`` (see there for each value's source).

    Attributes:
        extension_m: longest tree edge, metres. degressive_coeff: lambda, 1 / metres.
        init_iterations: nodes grown at least. cutoff_iterations: nodes grown at most without gain.
        gain_range_m: depth (metres) up to which a node's camera counts unknown volume.
        gain_width_px: raster of the gain view (the camera's field of view).
        yaw_samples: yaws drawn per node (the best is kept). overshoot_m: edges are checked this far
            beyond their node, metres. attempts_per_node: a planning call gives up after this many
            goals per node of its tree (nbvplanner's 1000 x (nodes + 1) iterations).
        stall_frames: a target is dropped after more on-the-spot frames than this.
        found_on: what must exceed the threshold (g_min) for "gain found": ``discounted``, the best
            node's discounted gain; ``views``, the undiscounted sum of the views along the best
            node's branch (see configs/explore.yaml).
        yaw_window_deg: a sampled node's yaw is drawn within this of its incoming edge's direction
            (180: uniform, nbvplanner's).
        sample_region: where the tree's goals are drawn: ``box``, uniformly over the map's XY extent
            (nbvplanner's sphere of the exploration box's diagonal around the root, clipped to the box);
            ``known_free``, uniformly over the known-free cells connected to the robot's.
        edge_check: what each point of a new edge must clear: ``body``, its cell free and the move
            check's body (:func:`~frontiernet.exploration.move_check.body_radius`) clear of the band's
            occupied cells (but within ``planner.clearance_m`` of the robot, which may stand closer);
            ``cells``, its cell free only (a point at a cell's edge may bring the body into a wall).
    """

    extension_m: float
    degressive_coeff: float
    init_iterations: int
    cutoff_iterations: int
    gain_range_m: float
    gain_width_px: int
    yaw_samples: int
    overshoot_m: float
    attempts_per_node: int
    stall_frames: int
    found_on: str = "discounted"
    yaw_window_deg: float = 180.0
    sample_region: str = "known_free"
    edge_check: str = "cells"

    @classmethod
    def from_config(cls, section) -> "NbvpSettings":
        """From the ``nbvp`` section (DictConfig or dict); InputError naming a bad or missing key."""
        if section is None:
            raise InputError("the explore config has no nbvp section (configs/explore.yaml)")
        get = section.get if hasattr(section, "get") else (lambda key: None)

        def number(key: str, unit: str, zero: bool = False) -> float:
            return positive_number(get(key), f"nbvp.{key}", unit, allow_zero=zero)

        def count(key: str) -> int:
            return whole_number(get(key), f"nbvp.{key}", 1)

        settings = cls(number("extension_m", "metres"), number("degressive_coeff", "1 / metres", True),
                       count("init_iterations"), count("cutoff_iterations"), number("gain_range_m", "metres"),
                       count("gain_width_px"), count("yaw_samples"), number("overshoot_m", "metres", True),
                       count("attempts_per_node"), count("stall_frames"), str(get("found_on") or "discounted"),
                       180.0 if get("yaw_window_deg") is None else number("yaw_window_deg", "degrees"),
                       str(get("sample_region") or "known_free"), str(get("edge_check") or "cells"))
        if settings.edge_check not in EDGE_CHECKS:
            raise InputError(f"nbvp.edge_check must be one of {', '.join(EDGE_CHECKS)}, got {settings.edge_check!r}")
        if settings.sample_region not in SAMPLE_REGIONS:
            raise InputError(f"nbvp.sample_region must be one of {', '.join(SAMPLE_REGIONS)}, "
                             f"got {settings.sample_region!r}")
        if settings.found_on not in FOUND_ON:
            raise InputError(f"nbvp.found_on must be one of {', '.join(FOUND_ON)}, got {settings.found_on!r}")
        if settings.yaw_window_deg > 180.0:
            raise InputError(f"nbvp.yaw_window_deg must be at most 180 degrees, got {settings.yaw_window_deg}")
        if settings.cutoff_iterations < settings.init_iterations:
            raise InputError(f"nbvp.cutoff_iterations ({settings.cutoff_iterations}) must be at least "
                             f"nbvp.init_iterations ({settings.init_iterations})")
        return settings


@dataclass(frozen=True)
class FreeSpace:
    """Where NBVP's tree may grow (:meth:`NbvpPlanner.free_space`).

    Attributes:
        free: (X, Y) bool cells of the map's XY grid, cell ``[i, j]`` spanning ``origin_xy + [i, i + 1)
            x [j, j + 1) cell_m``. origin_xy: (2,) float64 world corner, metres. cell_m: metres.
    """

    free: np.ndarray
    origin_xy: np.ndarray
    cell_m: float
    occupied: np.ndarray | None = None  # (X, Y) bool, the band's occupied cells (the move check's)
    traversed: np.ndarray | None = None  # (X, Y) bool, cells the robot has passed through (the move check passes them)


@dataclass
class RrtTree:
    """One planning call's tree (node 0 is the root: the robot).

    Attributes:
        xy: (N, 2) float64 world node positions, metres.
        yaw: (N,) float64 node headings, radians (world z, 0 = +x); the root's is the robot's.
        parent: (N,) int64 parent node of each node (-1 for the root); a parent precedes its child.
        length_m: (N,) float64 branch length from the root along the edges, metres.
        view_gain_m3: (N,) float64 unknown volume the node's camera sees, m^3 (root: 0).
        gain_m3: (N,) float64 accumulated gain ``parent's + view * exp(-lambda * length)``, m^3.
        found: some node's gain exceeds the threshold (else NBVP is done).
        view_sum_m3: (N,) float64 the undiscounted sum of the views from the root to each node, m^3
            (None: not computed).
    """

    xy: np.ndarray
    yaw: np.ndarray
    parent: np.ndarray
    length_m: np.ndarray
    view_gain_m3: np.ndarray
    gain_m3: np.ndarray
    found: bool
    view_sum_m3: np.ndarray | None = None

    @property
    def best(self) -> int:
        """The node of the highest gain (the first of equals; 0 for a bare root)."""
        return int(np.argmax(self.gain_m3))

    def branch(self, node: int) -> np.ndarray:
        """(K,) int64 nodes from the root's child to `node` (the root left out)."""
        path = []
        while node > 0:
            path.append(node)
            node = int(self.parent[node])
        return np.asarray(path[::-1], np.int64)


def accumulated_gains(view_gain_m3: np.ndarray, parent: np.ndarray, length_m: np.ndarray, lam: float,
                      start: int = 1, gain_m3: np.ndarray | None = None) -> np.ndarray:
    """(N,) float64 NBVP gains ``gain[parent] + view * exp(-lam * length)`` (root 0) of nodes in
    parent-first order, computed from node `start` on into `gain_m3` (None: a new array)."""
    gain = np.zeros(len(parent)) if gain_m3 is None else gain_m3
    discounted = view_gain_m3 * np.exp(-lam * length_m)
    for node in range(start, len(parent)):
        gain[node] = gain[parent[node]] + discounted[node]
    return gain


def stop_node(gain_m3: np.ndarray, start: int, stop: int, init_iterations: int, threshold: float,
              view_sum_m3: np.ndarray | None = None) -> int | None:
    """The first node n in [start, stop) after whose insertion nbvplanner stops growing: at least
    `init_iterations` nodes (n counts them, the root not) and some gain of nodes 1..n above
    `threshold`; None when none in the range does. With `view_sum_m3` ((N,), ``found_on: views``)
    the best node of nodes 1..n (the first of equal gains) must promise more than `threshold` in
    the undiscounted sum of its branch's views instead."""
    if stop <= 1:
        return None
    nodes = np.arange(1, stop)
    if view_sum_m3 is None:
        running = np.maximum.accumulate(gain_m3[1:stop])  # running[n - 1]: the best of nodes 1..n
    else:
        gains = gain_m3[1:stop]
        new_best = np.concatenate([[True], gains[1:] > np.maximum.accumulate(gains)[:-1]])
        best = np.maximum.accumulate(np.where(new_best, nodes, 0))  # best[n - 1]: the best of nodes 1..n
        running = view_sum_m3[best]
    hits = np.flatnonzero((nodes >= max(start, init_iterations)) & (running > threshold))
    return int(nodes[hits[0]]) if len(hits) else None


@numba.njit(cache=True)
def _segment_free(free, occupied, passed, body, root_x, root_y, exempt_m, origin_x, origin_y, cell_m, x0, y0, ux,
                  uy, reach, step):  # pragma: no cover
    """Whether the points from (x0, y0) along the unit direction (ux, uy) every `step` metres up to
    `reach` (the end included, the start not) all lie in `free` cells of the grid and, outside the
    `passed` cells and farther than `exempt_m` from the root (root_x, root_y), keep a disk of
    radius `body` off the `occupied` cells (exact disk-square test; `body` 0: no such test)."""
    count = int(math.ceil(reach / step))
    for s in range(1, count + 1):
        t = min(s * step, reach)
        px, py = x0 + t * ux, y0 + t * uy
        i = int(math.floor((px - origin_x) / cell_m))
        j = int(math.floor((py - origin_y) / cell_m))
        if i < 0 or j < 0 or i >= free.shape[0] or j >= free.shape[1] or not free[i, j]:
            return False
        if body > 0.0 and not passed[i, j] and (px - root_x) ** 2 + (py - root_y) ** 2 >= exempt_m ** 2:
            for a in range(max(int(math.floor((px - body - origin_x) / cell_m)), 0),
                           min(int(math.floor((px + body - origin_x) / cell_m)) + 1, occupied.shape[0])):
                dx = max(origin_x + a * cell_m - px, 0.0, px - origin_x - (a + 1) * cell_m)
                for b in range(max(int(math.floor((py - body - origin_y) / cell_m)), 0),
                               min(int(math.floor((py + body - origin_y) / cell_m)) + 1, occupied.shape[1])):
                    if occupied[a, b]:
                        dy = max(origin_y + b * cell_m - py, 0.0, py - origin_y - (b + 1) * cell_m)
                        if dx * dx + dy * dy < body * body:
                            return False
    return True


@numba.njit(cache=True)
def grow_tree(free, occupied, passed, body, exempt_m, origin_x, origin_y, cell_m, goals, extension_m, overshoot_m, xy,
              parent, length, goal_of, attempts_per_node):  # pragma: no cover
    """The RRT's geometry: for each goal in turn, a node steered from its nearest node.

    Args:
        free: (X, Y) bool traversable cells; occupied: (X, Y) bool cells a body of radius `body`
            (metres; 0: none) must keep off, except in the (X, Y) bool `passed` cells and within
            `exempt_m` metres of the root (row 0 of `xy`: the robot may stand closer); origin_x,
            origin_y: world corner of cell (0, 0);
            cell_m: cell size, metres.
        goals: (G, 2) float64 world points (memory nodes first, then samples).
        extension_m: longest edge; overshoot_m: the edge is checked this far beyond its node.
        xy, parent, length, goal_of: (C, 2) float64, (C,) int64, (C,) float64, (C,) int64 node
            arrays (C = the most nodes, the root included), written; row 0 holds the root on entry.
        attempts_per_node: goals are taken while fewer than this many per node (the root included)
            have been, as nbvplanner gives up after 1000 x (nodes + 1) iterations.
    Returns:
        the node count n (rows 0 .. n-1 written): goals are taken until C nodes exist.
    """
    n = 1
    step = 0.5 * cell_m
    for g in range(goals.shape[0]):
        if n >= xy.shape[0] or g >= attempts_per_node * n:
            break
        best, best_d2 = 0, np.inf
        for i in range(n):
            d2 = (xy[i, 0] - goals[g, 0]) ** 2 + (xy[i, 1] - goals[g, 1]) ** 2
            if d2 < best_d2:
                best, best_d2 = i, d2
        distance = math.sqrt(best_d2)
        if distance < 1e-9:
            continue
        ux, uy = (goals[g, 0] - xy[best, 0]) / distance, (goals[g, 1] - xy[best, 1]) / distance
        edge = min(distance, extension_m)
        if not _segment_free(free, occupied, passed, body, xy[0, 0], xy[0, 1], exempt_m, origin_x, origin_y, cell_m,
                             xy[best, 0], xy[best, 1], ux, uy, edge + overshoot_m, step):
            continue
        xy[n, 0], xy[n, 1] = xy[best, 0] + edge * ux, xy[best, 1] + edge * uy
        parent[n], length[n], goal_of[n] = best, length[best] + edge, g
        n += 1
    return n


class NbvpPlanner:
    """Grows NBVP's tree in the robot's map (see the module docstring).

    Args:
        occupancy: the robot's :class:`~frontiernet.mapping.OccupancyMap`.
        conf: the run config (``nbvp``, ``planner``, ``tracking.min_gain_m3``, ``motion.pitch_deg``).
        camera: the sim config's ``camera`` (the gain view's field of view).
        rng: the run's generator (positions and yaws).
        context: where to read the cells the robot has been from, each time (its ``traversed``:
            the run's :class:`~frontiernet.exploration.methods.MethodContext`); None: the map alone.
    """

    def __init__(self, occupancy, conf, camera, rng: np.random.Generator, context=None) -> None:
        self.map, self.conf, self.rng, self.context = occupancy, conf, rng, context
        self.settings = NbvpSettings.from_config(conf.get("nbvp"))
        # goals drawn per planning call: the most a tree can take before it gives up (its cutoff's nodes)
        self.draws = self.settings.attempts_per_node * (self.settings.cutoff_iterations + 1)
        self.threshold = float(conf.tracking.min_gain_m3)
        self.pitch = np.radians(float(conf.motion.pitch_deg))
        self.focal_px = float(camera.focal_px) * self.settings.gain_width_px / float(camera.width)
        self.body_m = body_radius(conf.planner, float(occupancy.voxel_size), 0.0)  # the move check's body

    def free_space(self, xy: np.ndarray, z: float) -> FreeSpace:
        """Where tree nodes and edges may lie, for the robot at world `xy` (2,) with its camera at
        height `z`: cells whose voxel at the camera's height is known free and whose centres lie at
        least ``planner.clearance_m`` from every cell occupied in the band ``z +- planner.height_band_m``
        and from every cell unknown at the camera's height (the planning grid's obstacles,
        :meth:`~frontiernet.planning.planner.PlanningGrid.from_map` with ``unknown_is_obstacle``).
        Unlike the planning grid, the band's top and bottom need not be known: the camera never sees
        them within ~0.45 m of itself, and the explorer's move check does not ask for them. Within
        ``clearance_m`` of the robot, cells no nearer to an obstacle than the robot's own are free
        too: it may leave a spot it stands on (as the grid keeps the robot's cell open); so are the
        cells the robot has passed through when the context keeps them open (``traversed``, as the
        grid and the move check do)."""
        band, clearance_m = float(self.conf.planner.height_band_m), float(self.conf.planner.clearance_m)
        cell = float(self.map.voxel_size)
        layer_free, layer_occupied = self.map.slice_2d(z, z)
        occupied = self.map.slice_2d(z - band, z + band)[1]
        to_occupied = distance_to_false(~occupied) * cell
        to_unknown = distance_to_false(layer_free | layer_occupied) * cell
        to_obstacle = np.minimum(to_occupied, to_unknown)
        free = layer_free & (to_obstacle >= clearance_m)
        origin = np.asarray(self.map.origin[:2], np.float64)
        i, j = grid_cells(xy, origin, cell)[0]
        if cells_inside(np.array([i, j]), free.shape):
            reach = int(np.ceil(clearance_m / cell))
            lo, hi = np.maximum([i - reach, j - reach], 0), np.minimum([i + reach + 1, j + reach + 1], free.shape)
            window = (slice(lo[0], hi[0]), slice(lo[1], hi[1]))
            cells = np.stack(np.meshgrid(np.arange(lo[0], hi[0]), np.arange(lo[1], hi[1]), indexing="ij"), -1)
            near = np.hypot(*(origin + (cells + 0.5) * cell - xy).transpose(2, 0, 1)) < clearance_m
            free[window] |= near & layer_free[window] & (to_occupied[window] >= to_occupied[i, j])
            free[i, j] = True  # the robot stands in free space whatever the map says
        traversed = getattr(self.context, "traversed", None)
        if traversed is not None:
            free |= traversed.mask
        return FreeSpace(free, origin, cell, occupied, None if traversed is None else traversed.mask)

    def samples(self, space: FreeSpace, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:attr:`draws` draws: (S, 2) float64 world positions, and (S, yaw_samples) float64 yaws in
        [-pi, pi). Positions are uniform over `space`'s whole grid with ``sample_region: box`` (most
        fall outside free space: the tree steers its nearest node towards them, so it grows towards
        the unexplored, RRT's Voronoi bias), else over the free cells of `space` connected
        (8-neighbours) to the robot's at `xy`. Always the same number of draws (a run repeats with
        its seed)."""
        if self.settings.sample_region == "box":
            count = self.draws
            positions = space.origin_xy + self.rng.random((count, 2)) * np.asarray(space.free.shape) * space.cell_m
            return positions, self.rng.uniform(-np.pi, np.pi, (count, self.settings.yaw_samples))
        labels, _ = ndimage.label(space.free, structure=np.ones((3, 3), bool))
        i, j = grid_cells(xy, space.origin_xy, space.cell_m)[0]
        inside = bool(cells_inside(np.array([i, j]), space.free.shape)) and labels[i, j] > 0
        cells = np.argwhere(labels == labels[i, j]) if inside else np.zeros((0, 2), np.int64)
        count = self.draws
        picks = self.rng.integers(max(len(cells), 1), size=count)
        jitter = self.rng.random((count, 2))
        yaws = self.rng.uniform(-np.pi, np.pi, (count, self.settings.yaw_samples))
        if not len(cells):
            return np.zeros((0, 2)), np.zeros((0, self.settings.yaw_samples))
        return space.origin_xy + (cells[picks] + jitter) * space.cell_m, yaws

    def grow(self, T_world_cam: np.ndarray, memory: np.ndarray | None = None) -> RrtTree:
        """The tree from the robot at the (4, 4) pose `T_world_cam`, with `memory` ((M, 3) [x, y, yaw],
        the rest of the previous best branch, or None) inserted first; grown until nbvplanner stops."""
        s, z = self.settings, float(T_world_cam[2, 3])
        root = np.asarray(T_world_cam[:2, 3], np.float64)
        space = self.free_space(root, z)
        positions, yaws = self.samples(space, root)
        memory = np.zeros((0, 3)) if memory is None else np.asarray(memory, np.float64).reshape(-1, 3)
        goals = np.ascontiguousarray(np.concatenate([memory[:, :2], positions]))
        goal_yaws = np.concatenate([np.repeat(memory[:, 2:], s.yaw_samples, axis=1), yaws])
        capacity = s.cutoff_iterations + 1
        xy, parent = np.zeros((capacity, 2)), np.full(capacity, -1, np.int64)
        length, goal_of = np.zeros(capacity), np.full(capacity, -1, np.int64)
        xy[0] = root
        checks_body = s.edge_check == "body" and space.occupied is not None
        occupied = space.occupied if checks_body else np.zeros((1, 1), bool)
        passed = space.traversed if checks_body and space.traversed is not None else np.zeros_like(space.free)
        body, exempt_m = (self.body_m if checks_body else 0.0), float(self.conf.planner.clearance_m)
        origin_x, origin_y = float(space.origin_xy[0]), float(space.origin_xy[1])
        n = grow_tree(space.free, occupied, passed, body, exempt_m, origin_x, origin_y, space.cell_m, goals,
                      s.extension_m, s.overshoot_m, xy, parent, length, goal_of, s.attempts_per_node)
        tree = RrtTree(xy[:n], np.full(n, yaw_of(T_world_cam)), parent[:n], length[:n], np.zeros(n), np.zeros(n), False,
                       np.zeros(n) if s.found_on == "views" else None)
        return self._score(tree, self.node_yaws(tree, goal_yaws, goal_of[:n], len(memory)), z)

    def node_yaws(self, tree: RrtTree, goal_yaws: np.ndarray, goal_of: np.ndarray, remembered: int) -> np.ndarray:
        """(N, yaw_samples) float64 the yaws drawn for each node of `tree` (the root's row unused):
        a sampled node's draw u in [-pi, pi) (`goal_yaws`, rows by `goal_of`) becomes its incoming
        edge's direction + u x ``yaw_window_deg`` / 180 (the draw itself with 180: nbvplanner's
        uniform yaw); the first `remembered` goals (the remembered branch) keep their yaws."""
        yaws = np.array(goal_yaws[goal_of], np.float64)
        window = self.settings.yaw_window_deg
        if window >= 180.0 or len(tree.parent) < 2:
            return yaws
        offset = tree.xy[1:] - tree.xy[tree.parent[1:]]
        heading = np.arctan2(offset[:, 1], offset[:, 0])
        sampled = np.flatnonzero(goal_of[1:] >= remembered) + 1
        yaws[sampled] = heading[sampled - 1, None] + yaws[sampled] * (window / 180.0)
        return yaws

    def _score(self, tree: RrtTree, node_yaws: np.ndarray, z: float) -> RrtTree:
        """`tree` with its gains, cut after the node at which nbvplanner stops (views are scored in
        growing chunks: init_iterations nodes first, then twice as many each time, so a call that
        finds gain early scores few views)."""
        s, n = self.settings, len(tree.parent)
        done, upto = 1, min(n, s.init_iterations + 1)
        while done < n:
            tree.view_gain_m3[done:upto], tree.yaw[done:upto] = self.view_gains(tree.xy[done:upto],
                                                                                node_yaws[done:upto], z)
            accumulated_gains(tree.view_gain_m3, tree.parent, tree.length_m, s.degressive_coeff, done, tree.gain_m3)
            if tree.view_sum_m3 is not None:
                accumulated_gains(tree.view_gain_m3, tree.parent, tree.length_m, 0.0, done, tree.view_sum_m3)
            stop = stop_node(tree.gain_m3, done, upto, s.init_iterations, self.threshold, tree.view_sum_m3)
            if stop is not None:
                return _cut(tree, stop + 1, True)
            done, upto = upto, min(n, 2 * upto)
        # no stop: the cutoff without gain (NBVP is done), or the samples ran out (nbvplanner: "return
        # to previous point"), where a tree of fewer than init_iterations nodes is used if it found gain
        promise = tree.gain_m3 if tree.view_sum_m3 is None else tree.view_sum_m3
        return _cut(tree, n, n - 1 < s.init_iterations and n > 1 and float(promise[tree.best]) > self.threshold)

    def view_gains(self, xy: np.ndarray, yaws: np.ndarray, z: float) -> tuple[np.ndarray, np.ndarray]:
        """The unknown volume (m^3) the cameras (the robot's field of view and ``motion.pitch_deg``) at
        (K, 2) world `xy` and height `z` see at the best of their (K, Y) `yaws` (radians), up to
        ``gain_range_m``: ((K,) float64 volumes, (K,) float64 the best yaws)."""
        k, count = len(xy), yaws.shape[1]
        if not k:
            return np.zeros(0), np.zeros(0)
        positions = np.column_stack([np.repeat(xy, count, axis=0), np.full(k * count, z)])
        poses = poses_from_headings(positions, yaws.reshape(-1), self.pitch)
        volumes = self.map.visible_unknown_volume(poses, self.settings.gain_width_px, self.focal_px,
                                                  self.settings.gain_range_m).reshape(k, count)
        best = np.argmax(volumes, axis=1)
        return volumes[np.arange(k), best], yaws[np.arange(k), best]


def _cut(tree: RrtTree, n: int, found: bool) -> RrtTree:
    return RrtTree(tree.xy[:n], tree.yaw[:n], tree.parent[:n], tree.length_m[:n], tree.view_gain_m3[:n],
                   tree.gain_m3[:n], found, None if tree.view_sum_m3 is None else tree.view_sum_m3[:n])


__all__ = ["NbvpSettings", "NbvpPlanner", "FreeSpace", "RrtTree", "accumulated_gains", "stop_node", "grow_tree"]

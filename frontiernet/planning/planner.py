"""Goal selection and paths: utility u = gain^e / distance (paper Eq. 8) over the frontier tree.

docs/design.md item 6, paper III-F. Each planning round:

1. every live frontier gets a route: on the map (``planner.mode: map``) the frontier-tree
   edge is walked back to ``c*``, the first point the robot can reach on the map's 2D
   planning grid (:class:`PlanningGrid`), and the route is the grid path to ``c*`` followed
   by the rest of the edge; without a map (``map_free``) the route runs back along the
   trajectory (:class:`~frontiernet.planning.tree.PoseGraph`) to the frontier's parent pose
   and then along the edge;
2. its utility is ``gain^e / max(distance, min_distance_m)`` with the route's length (e:
   ``planner.gain_exponent``, 2; the paper's Eq. 8 has 1);
3. the best frontier that is not blacklisted is the goal.

A frontier whose route fails (no reachable ``c*``, or the motion along it is blocked) gets a
failure; after ``max_failures`` it is blacklisted and never chosen again. A frontier whose tree
edge beyond ``c*`` already brings the body (the explorer's move check) into a mapped obstacle,
such as a counter the camera saw over, would fail there. It is approached instead from the
reachable cell nearest to it that sees it (:func:`approach_edge`, within
``planner.approach_radius_m``); failing that, it ranks after every frontier with a clear edge,
and is chosen only when none is left (the robot then goes as near as it can and looks, where a
noisy depth prior's walls may turn out free).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np

from ..geometry import arc_lengths, disks_touch_cells, distance_to_false, grid_cells, grid_values, points_at_arc
from .grid import clearance_cost, geodesic_paths
from .tree import PoseGraph, edge_points, walk_back


@dataclass
class PlanningGrid:
    """The occupancy map seen from the robot's height, as a 2D cost grid.

    Attributes:
        origin_xy: (2,) float64 world corner of cell (0, 0), metres.
        cell_m: cell size, metres.
        cost: (X, Y) float64 traversal cost per cell (inf = blocked), indexed [i, j] for
            ``x = origin_x + (i + 0.5) * cell_m`` and likewise y.
        clearance: (X, Y) float64 metres from each cell centre to the nearest occupied cell's
            (None when the grid was not made from a map).
        occupied: (X, Y) bool, cells occupied somewhere in the band (None: no map).
    """

    origin_xy: np.ndarray
    cell_m: float
    cost: np.ndarray
    clearance: np.ndarray | None = None
    occupied: np.ndarray | None = None

    @classmethod
    def from_map(cls, occupancy, z: float, conf, start_xy: np.ndarray | None = None,
                 traversed: np.ndarray | None = None) -> "PlanningGrid":
        """Grid over the band ``z +- planner.height_band_m`` of an OccupancyMap.

        A cell is traversable when it is free over the band and at least ``clearance_m``
        from the obstacle cells; its cost is ``1 + centre_weight / clearance``. Obstacle cells
        are those occupied in the band and, with ``unknown_is_obstacle``, those unknown in the
        voxel layer at height `z`: a wall the camera never faced is unknown, and a route beside
        it would touch it. (The layer at the camera's height is what the camera sees at every
        range; the band's top and bottom are unseen within ~0.45 m of it, so counting those
        would wall the robot in wherever it turned.) The cell under `start_xy` (the robot,
        which stands in free space whatever the map says) is kept open, and so are the cells of
        `traversed` ((X, Y) bool on the map's XY grid: where the robot has been,
        :class:`~frontiernet.planning.traversed.TraversedCells`, with ``planner.traversed_is_free``),
        at the cost of a cell at the clearance limit.
        """
        band = float(conf["height_band_m"])
        free, occupied = occupancy.slice_2d(z - band, z + band)
        cell = float(occupancy.voxel_size)
        clearance = distance_to_false(~occupied) * cell
        to_obstacle = clearance
        if bool(conf.get("unknown_is_obstacle", False)):
            layer_free, layer_occupied = occupancy.slice_2d(z, z)
            to_obstacle = np.minimum(clearance, distance_to_false(layer_free | layer_occupied) * cell)
        cost = clearance_cost(to_obstacle, float(conf["clearance_m"]), float(conf["centre_weight"]))
        cost[~free] = np.inf
        if traversed is not None:
            cost[traversed & ~np.isfinite(cost)] = 1.0 + float(conf["centre_weight"]) / float(conf["clearance_m"])
        grid = cls(np.asarray(occupancy.origin[:2], np.float64), cell, cost, clearance, occupied)
        if start_xy is not None:
            i, j = grid.cell(start_xy)
            if grid.inside(i, j) and not np.isfinite(grid.cost[i, j]):
                grid.cost[i, j] = 1.0 + float(conf["centre_weight"]) / max(float(to_obstacle[i, j]), 1e-3)
        return grid

    def boxed_in(self, xy: np.ndarray, clearance_m: float) -> bool:
        """Whether the cell under world point `xy` (2,) lies closer than `clearance_m` to an occupied
        cell and none of its 8 neighbours is traversable: a robot there (on a counter top under
        the band, say) can plan no route at all. (At the start the neighbours are unknown, not
        occupied: routes leave along the frontier-tree edges.)"""
        i, j = self.cell(xy)
        if not self.inside(i, j) or self.clearance is None or self.clearance[i, j] >= clearance_m:
            return False
        block = self.cost[max(i - 1, 0):i + 2, max(j - 1, 0):j + 2]
        return int(np.isfinite(block).sum()) - int(np.isfinite(self.cost[i, j])) == 0

    def touches_occupied(self, xy: np.ndarray, radius_m: float) -> np.ndarray:
        """(N,) bool: whether a disk of `radius_m` around each of the (N, 2) world points overlaps an
        occupied cell (exact disk-square test): the explorer's move check of a body there
        (``OccupancyMap.cylinder_touches_occupied`` over the same band). All False without a map."""
        if self.occupied is None:
            return np.zeros(len(xy), bool)
        return disks_touch_cells(self.occupied, self.origin_xy, self.cell_m, xy, radius_m)

    def cells(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) world points -> (N, 2) int64 cell indices (may lie outside the grid)."""
        return grid_cells(xy, self.origin_xy, self.cell_m)

    def cell(self, xy: np.ndarray) -> tuple[int, int]:
        i, j = self.cells(xy)[0]
        return int(i), int(j)

    def inside(self, i: int, j: int) -> bool:
        return 0 <= i < self.cost.shape[0] and 0 <= j < self.cost.shape[1]

    def centres(self, cells: np.ndarray) -> np.ndarray:
        """(N, 2) cells -> (N, 2) world centres, metres."""
        return self.origin_xy + (np.asarray(cells, np.float64) + 0.5) * self.cell_m

    def lookup(self, field: np.ndarray, xy: np.ndarray, outside=np.inf) -> np.ndarray:
        """Values of an (X, Y) `field` at (N, 2) world points (`outside` off the grid)."""
        return grid_values(field, self.origin_xy, self.cell_m, xy, outside)


@dataclass
class Route:
    """How to reach one frontier.

    Attributes:
        frontier_id: the frontier.
        waypoints: (N, 2) float64 world xy from the robot to the frontier, metres.
        mapped_until: number of leading waypoints on the mapped, planned part (the rest is
            the frontier-tree edge beyond ``c*``, followed while mapping).
        distance_m: route length used in the utility.
        utility: ``gain^e / max(distance, min)``.
    """

    frontier_id: int
    waypoints: np.ndarray
    mapped_until: int
    distance_m: float
    utility: float


class _Candidate(NamedTuple):
    """One frontier scored in a planning round."""

    frontier: object
    distance_m: float  # route length used in the utility
    utility: float  # the goal rule's score
    detail: object  # what the tracer needs (map mode: the edge's points and the c* index)
    blocked: bool = False  # the tree edge beyond c* brings the body into a mapped obstacle


@dataclass
class FrontierPlanner:
    """Chooses goals and routes; configured by the ``planner`` section of ``configs/explore.yaml``.

    `goal` is the method's goal rule (:meth:`score`); `seed` seeds the ``random`` rule.
    `body_radius_m`: the radius the explorer's move check keeps from occupied cells
    (``Explorer.body_radius``); a frontier whose tree edge beyond ``c*`` comes closer to one
    ranks after those whose edges are clear, as following it would fail there."""

    conf: dict
    goal: str = "utility"
    seed: int = 0
    body_radius_m: float = 0.0
    failures: dict = field(default_factory=dict)
    blacklist: set = field(default_factory=set)
    _random_scores: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self._rng = np.random.default_rng(self.seed)

    def fail(self, frontier_id: int) -> bool:
        """Count a failure of `frontier_id`; returns True when it is now blacklisted."""
        self.failures[frontier_id] = self.failures.get(frontier_id, 0) + 1
        if self.failures[frontier_id] >= int(self.conf["max_failures"]):
            self.blacklist.add(frontier_id)
            return True
        return False

    def utility(self, gain_m3: float, distance_m: float) -> float:
        """Paper Eq. 8: ``gain^e / max(distance, min_distance_m)``."""
        return float(gain_m3) ** float(self.conf["gain_exponent"]) / max(distance_m, float(self.conf["min_distance_m"]))

    def score(self, frontier, distance_m: float) -> float:
        """How good `frontier` is as the goal at route length `distance_m`, by the goal rule:
        ``utility`` (Eq. 8), ``nearest`` (1 / distance: Yamauchi's nearest frontier first) or
        ``random`` (a uniform draw, fixed per frontier id, seeded) or ``rate`` (gain / distance:
        volume per metre of travel, whatever ``gain_exponent``; the omniscient bound's rule)."""
        if self.goal == "nearest":
            return 1.0 / max(distance_m, float(self.conf["min_distance_m"]))
        if self.goal == "rate":
            return float(frontier.gain_m3) / max(distance_m, float(self.conf["min_distance_m"]))
        if self.goal == "random":
            return self._random_scores.setdefault(frontier.id, float(self._rng.random()))
        return self.utility(frontier.gain_m3, distance_m)

    def best_route(self, frontiers, robot_xy: np.ndarray, parent_xy, grid: PlanningGrid | None = None,
                   graph: PoseGraph | None = None, robot_index: int | None = None,
                   keep: int | None = None, keep_margin: float = 0.0) -> Route | None:
        """The best :class:`Route` over the live, non-blacklisted frontiers, or None.

        Args:
            frontiers: tracked :class:`~frontiernet.frontiers.tracking.Frontier` records.
            robot_xy: (2,) world position of the robot.
            parent_xy: function ``pose index -> (2,) world xy`` of the frontiers' parent poses.
            grid: the planning grid (map mode). graph, robot_index: the pose graph and the
                robot's index in it (map-free mode).
            keep: id of the current goal; it stays the goal unless another frontier's utility
                beats it by more than the fraction `keep_margin` (avoids back-and-forth).
        """
        candidates = [f for f in frontiers if f.id not in self.blacklist]
        if not candidates:
            return None
        if grid is not None:
            scored, trace = self._map_candidates(candidates, robot_xy, parent_xy, grid)
        else:
            scored, trace = self._tree_candidates(candidates, robot_xy, parent_xy, graph, robot_index)
        scored.sort(key=lambda c: (c.blocked, -c.utility))  # clear edges first, then by utility
        current = [c for c in scored if c.frontier.id == keep]
        if current and current[0].blocked == scored[0].blocked \
                and scored[0].utility <= current[0].utility * (1.0 + keep_margin):
            scored = current + [c for c in scored if c.frontier.id != keep]
        for candidate in scored:
            route = trace(candidate.frontier, candidate.detail)
            if route is None:
                self.fail(candidate.frontier.id)
                continue
            waypoints, mapped_until = route
            return Route(candidate.frontier.id, waypoints, mapped_until, candidate.distance_m, candidate.utility)
        return None

    def _map_candidates(self, frontiers, robot_xy, parent_xy, grid: PlanningGrid):
        """:class:`_Candidate` records (detail: the tree edge's points and the c* index into them)
        for frontiers with a reachable ``c*``, and the tracer."""
        start = grid.cell(robot_xy)
        if not grid.inside(*start):
            return [], None
        cumulative, path_to = geodesic_paths(grid.cost, start)  # clearance-weighted: picks the paths
        reachable = np.isfinite(cumulative)
        if str(self.conf["distance"]) == "path":  # their lengths: unit costs over the same cells
            length, _ = geodesic_paths(np.where(reachable, 1.0, np.inf), start)
            length = length * grid.cell_m
        spacing = float(self.conf["edge_spacing_m"])
        radius = max(self.body_radius_m, 1e-6)  # 0: the edge point's own cell
        approach_radius = float(self.conf["approach_radius_m"])
        scored = []
        for frontier in frontiers:
            parent = parent_xy(frontier.parent_pose)
            at = walk_back(frontier.position[:2], parent, lambda p: grid.lookup(reachable, p, outside=0) > 0, spacing)
            if at is None:
                self.fail(frontier.id)
                continue
            edge = edge_points(frontier.position[:2], parent, spacing)
            c_star = edge[at]
            if str(self.conf["distance"]) == "path":
                distance = float(grid.lookup(length, c_star[None])[0]) + spacing * at
            else:
                distance = float(np.linalg.norm(frontier.position[:2] - np.asarray(robot_xy)[:2]))
            blocked = bool(at and grid.touches_occupied(edge[:at], radius).any())
            if blocked and approach_radius > 0:  # a reachable cell that sees the frontier, instead of the edge
                approach = approach_edge(frontier.position[:2], grid, reachable, approach_radius, spacing)
                if approach is not None:
                    (edge, at), blocked = approach, False
                    if str(self.conf["distance"]) == "path":
                        distance = float(grid.lookup(length, edge[at][None])[0])
            scored.append(_Candidate(frontier, distance, self.score(frontier, distance), (edge, at), blocked))

        def trace(frontier, detail):
            edge, at = detail
            cells = path_to(grid.cell(edge[at]))
            if cells is None:
                return None
            path = grid.centres(cells[1:]) if len(cells) > 1 else edge[at:at + 1]
            beyond = edge[:at][::-1]  # from c* towards the frontier, followed while mapping
            if len(cells) <= 2 and len(beyond):  # the robot stands at c* (its cell or the next): follow
                return beyond, 0  # the edge from here, not a sub-step detour to c*'s cell centre first
            return (np.concatenate([path, beyond]) if len(beyond) else path), len(path)

        return scored, trace

    def _tree_candidates(self, frontiers, robot_xy, parent_xy, graph: PoseGraph, robot_index: int):
        """:class:`_Candidate` records along the pose graph (never blocked), and the tracer (map-free mode).

        The route runs back along the trajectory to the frontier's parent pose, then along the edge
        (the parent's line of sight to the frontier), unless the robot already stands on the edge:
        within ``pose_link_m`` (the distance at which the pose graph links trajectory poses) of one
        of its points, it goes on along the edge from there when that is shorter. Going back to the
        parent first from the middle of the edge, re-planned every ``replan_every_steps`` while each
        reversal costs a half turn, kept a robot between the two ends of one edge for hundreds of
        steps (procedural:1000, docs/exploration.md)."""
        distances, predecessors = graph.distances_from(robot_index)
        spacing, link = float(self.conf["edge_spacing_m"]), float(self.conf["pose_link_m"])
        robot_xy = np.asarray(robot_xy, np.float64)
        scored = []
        for frontier in frontiers:
            parent = frontier.parent_pose
            if parent >= len(distances) or not np.isfinite(distances[parent]):
                self.fail(frontier.id)
                continue
            edge = edge_points(parent_xy(parent), frontier.position[:2], spacing)  # parent -> frontier
            distance, joined = float(distances[parent]) + float(np.linalg.norm(edge[-1] - edge[0])), None
            gaps = np.linalg.norm(edge - robot_xy, axis=1)
            nearest = int(np.argmin(gaps))
            along = float(gaps[nearest]) + float(np.linalg.norm(edge[-1] - edge[nearest]))
            if gaps[nearest] <= link and along < distance:
                distance, joined = along, nearest
            scored.append(_Candidate(frontier, distance, self.score(frontier, distance), (edge, joined)))

        def trace(frontier, detail):
            edge, joined = detail
            if joined is not None:  # on the edge already: on along it
                return edge[joined:], 0
            back = graph.path(predecessors, frontier.parent_pose)
            return np.concatenate([back[1:], edge[1:]]), len(back) - 1

        return scored, trace


def approach_edge(frontier_xy: np.ndarray, grid: PlanningGrid, reachable: np.ndarray, radius_m: float,
                  spacing_m: float) -> tuple[np.ndarray, int] | None:
    """Another way to a frontier whose tree edge is blocked: the reachable grid cell nearest to it
    (within `radius_m`) that sees it, in the form of :func:`walk_back`'s result (an edge and its
    ``c*`` index), here a one-point edge: the robot plans to that cell and looks from there.

    A cell *sees* the frontier when the straight line from its centre to the frontier, sampled
    at most `spacing_m` apart, crosses no occupied cell (the frontier's own last 0.15 m excepted: it may
    lie against a wall). The robot does not walk that line, which may pass a door jamb closer than
    the grid's paths do. A frontier-tree edge is the line of sight from the pose that registered
    the frontier, which may have passed over a counter or a jamb's corner that the body cannot.

    Args:
        frontier_xy: (2,) world metres. grid: the planning grid; reachable: (X, Y) bool, cells the
            robot can reach on it. radius_m: search radius around the frontier, metres.
    Returns:
        ((1, 2) the cell's centre, metres; c* index 0), or None when no reachable cell within
        `radius_m` sees the frontier.
    """
    frontier_xy = np.asarray(frontier_xy, np.float64)
    lo, hi = grid.cells(np.stack([frontier_xy - radius_m, frontier_xy + radius_m]))
    lo, hi = np.maximum(lo, 0), np.minimum(hi + 1, reachable.shape)
    if np.any(hi <= lo) or grid.occupied is None:
        return None
    centres = grid.centres(np.argwhere(reachable[lo[0]:hi[0], lo[1]:hi[1]]) + lo)
    distance = np.linalg.norm(centres - frontier_xy, axis=1)
    near = np.flatnonzero(distance <= radius_m)
    if not len(near):
        return None
    near = near[np.argsort(distance[near], kind="stable")]  # nearest first
    centres, distance = centres[near], distance[near]
    t = np.linspace(0.0, 1.0, int(np.ceil(radius_m / spacing_m)) + 1)  # (K,) along each line
    lines = frontier_xy + t[None, :, None] * (centres - frontier_xy)[:, None, :]  # (N, K, 2)
    crossed = grid.touches_occupied(lines.reshape(-1, 2), 1e-6).reshape(len(centres), len(t))
    crossed &= (t[None, :] * distance[:, None]) > 0.15
    sees = np.flatnonzero(~crossed.any(axis=1))
    return (centres[sees[0]][None], 0) if len(sees) else None


def resample_route(route: Route, start_xy: np.ndarray, spacing_m: float) -> Route:
    """`route` with its waypoints resampled every `spacing_m` metres of arc from `start_xy`
    (the last waypoint kept), so that each motion increment is a full step."""
    points = np.concatenate([np.asarray(start_xy, np.float64)[None, :2], route.waypoints])
    arc = arc_lengths(points)
    if arc[-1] <= spacing_m:
        return replace(route, waypoints=route.waypoints[-1:], mapped_until=min(route.mapped_until, 1))
    s = np.append(np.arange(spacing_m, arc[-1], spacing_m), arc[-1])
    mapped_arc = arc[min(route.mapped_until, len(route.waypoints))]
    return replace(route, waypoints=points_at_arc(points, arc, s),
                   mapped_until=int(np.searchsorted(s, mapped_arc + 1e-9)))

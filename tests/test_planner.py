"""Planning (docs/design.md item 6): the frontier tree, the pose graph, utility = gain / distance,
goal keeping, blacklisting, map and map-free routes, route resampling."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy import ndimage

from conftest import TWO_ROOM, explore_section
from frontiernet.config import load_config
from frontiernet.frontiers.tracking import Frontier
from frontiernet.geometry import arc_lengths, pose_from_heading
from frontiernet.mapping import OccupancyMap
from frontiernet.planning.planner import FrontierPlanner, PlanningGrid, Route, approach_edge, resample_route
from frontiernet.planning.traversed import TraversedCells
from frontiernet.planning.tree import PoseGraph, edge_points, walk_back
from frontiernet.simulator.camera import PinholeCamera, Renderer

SMALL = PinholeCamera(120, 120, 75.0, 75.0, 59.5, 59.5, 3.5)  # the paper's field of view, 120 px
Z = 1.2


def planner_conf(**changes) -> dict:
    return explore_section("planner", **changes)


def frontier(fid: int, xy, gain: float, parent: int, yaw: float = 0.0) -> Frontier:
    direction = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    return Frontier(fid, np.array([xy[0], xy[1], Z], float), direction, gain, gain, parent, 0, 0)


def open_grid(size_m: float = 6.0, cell: float = 0.1) -> PlanningGrid:
    """An obstacle-free grid of unit cell cost over [0, size_m]^2: path costs are lengths in metres."""
    n = round(size_m / cell)
    return PlanningGrid(np.zeros(2), cell, np.ones((n, n)))


def parents(*xy):
    points = [np.asarray(p, float) for p in xy]
    return lambda index: points[index]


# -- the frontier tree ------------------------------------------------------------------------------


def test_edge_points_run_from_the_frontier_to_the_parent_at_most_spacing_apart():
    points = edge_points(np.array([3.0, 1.0]), np.array([0.0, 5.0]), 0.1)
    np.testing.assert_allclose(points[0], [3.0, 1.0])
    np.testing.assert_allclose(points[-1], [0.0, 5.0])
    steps = np.linalg.norm(np.diff(points, axis=0), axis=1)
    assert len(points) == 51 and np.allclose(steps, 0.1)
    # a frontier on its parent is one point pair, not an empty edge
    assert len(edge_points(np.zeros(2), np.zeros(2), 0.1)) == 2


def test_walk_back_finds_the_first_reachable_point_from_the_frontier_end():
    frontier_xy, parent_xy = np.array([4.0, 0.0]), np.array([0.0, 0.0])
    # the map reaches x <= 2.5: c* is the first edge point (from the frontier) at x <= 2.5
    index = walk_back(frontier_xy, parent_xy, lambda p: p[:, 0] <= 2.5 + 1e-9, 0.1)
    assert edge_points(frontier_xy, parent_xy, 0.1)[index][0] == pytest.approx(2.5)
    assert index == 15
    assert walk_back(frontier_xy, parent_xy, lambda p: np.ones(len(p), bool), 0.1) == 0  # the frontier itself
    assert walk_back(frontier_xy, parent_xy, lambda p: np.zeros(len(p), bool), 0.1) is None
    # a map with a hole: the first reachable point from the frontier side wins, not the longest run
    index = walk_back(frontier_xy, parent_xy, lambda p: (p[:, 0] < 1.0) | ((p[:, 0] > 3.0) & (p[:, 0] < 3.5)), 0.1)
    assert 3.0 < edge_points(frontier_xy, parent_xy, 0.1)[index][0] < 3.5


def loop_trajectory() -> np.ndarray:
    """Out along y = 0 to x = 3, up to y = 2, back to x = 0 and down to (0, 0.1): 0.1 m apart."""
    legs = [np.c_[np.arange(0, 3.0, 0.1), np.zeros(30)], np.c_[np.full(20, 3.0), np.arange(0, 2.0, 0.1)],
            np.c_[np.arange(3.0, 0.0, -0.1), np.full(30, 2.0)], np.c_[np.zeros(20), np.arange(2.0, 0.05, -0.1)]]
    return np.concatenate(legs)


def test_pose_graph_links_revisits_so_the_return_is_short():
    xy = loop_trajectory()
    assert np.allclose(xy[-1], [0.0, 0.1])
    graph = PoseGraph(link_radius_m=0.3)
    assert [graph.add(p) for p in xy] == list(range(len(xy)))
    last = len(xy) - 1
    distances, predecessors = graph.distances_from(last)
    assert distances[0] == pytest.approx(0.1, abs=1e-3)  # the revisit closes the loop
    # (0.5, 0): straight-line 0.51 m; along the linked poses at most 0.6 m (back to the start, then the first leg)
    assert 0.5 < distances[5] <= 0.6 + 1e-3
    path = graph.path(predecessors, 5)
    np.testing.assert_allclose(path[0], xy[last])
    np.testing.assert_allclose(path[-1], xy[5])
    assert arc_lengths(path)[-1] == pytest.approx(distances[5], abs=1e-3)
    assert np.all(np.linalg.norm(np.diff(path, axis=0), axis=1) <= 0.3 + 1e-9)  # only linked poses are joined

    # without the link the way back re-traces the whole loop
    retrace = PoseGraph(link_radius_m=0.05)
    for p in xy:
        retrace.add(p)
    assert retrace.distances_from(last)[0][0] == pytest.approx(arc_lengths(xy)[-1], abs=1e-3)
    assert arc_lengths(xy)[-1] > 9.5


# -- utility and goal choice ------------------------------------------------------------------------


def test_utility_is_gain_over_distance_with_a_floor_on_the_distance():
    planner = FrontierPlanner(planner_conf(gain_exponent=1.0, min_distance_m=0.5))
    assert planner.utility(6.0, 2.0) == pytest.approx(3.0)  # paper Eq. 8
    assert planner.utility(1.0, 0.1) == pytest.approx(2.0)  # 0.1 m counts as 0.5 m
    assert planner.utility(0.0, 1.0) == 0.0
    assert FrontierPlanner(planner_conf(gain_exponent=2.0)).utility(3.0, 3.0) == pytest.approx(3.0)


@pytest.mark.parametrize("exponent, far_gain, chosen", [(1.0, 9.0, 1), (1.0, 5.0, 0), (2.0, 5.0, 1), (2.0, 3.0, 0)])
def test_best_route_maximises_gain_over_path_distance(exponent, far_gain, chosen):
    """Near: 1 m away, gain 2. Far: 3 m away. Exponent 1 (the paper's): u = 2 near, 3 (gain 9) or 1.67
    (gain 5) far. Exponent 2 (the default): u = 4 near, 8.33 (gain 5) or 3 (gain 3) far."""
    robot = np.array([1.05, 3.05])  # a cell centre of the open grid
    frontiers = [frontier(0, robot + [0.0, 1.0], 2.0, 0), frontier(1, robot + [3.0, 0.0], far_gain, 0)]
    planner = FrontierPlanner(planner_conf(gain_exponent=exponent))
    route = planner.best_route(frontiers, robot, parents(robot), grid=open_grid())
    assert route.frontier_id == chosen
    expected_distance = [1.0, 3.0][chosen]
    assert route.distance_m == pytest.approx(expected_distance, abs=1e-9)
    assert route.utility == pytest.approx([2.0, far_gain][chosen] ** exponent / expected_distance)
    np.testing.assert_allclose(route.waypoints[-1], frontiers[chosen].position[:2], atol=0.051)
    assert not planner.failures and not planner.blacklist


def test_blacklisted_or_missing_frontiers_give_no_route():
    planner = FrontierPlanner(planner_conf())
    robot = np.array([1.05, 1.05])
    assert planner.best_route([], robot, parents(robot), grid=open_grid()) is None
    planner.blacklist.add(0)
    assert planner.best_route([frontier(0, (2.0, 1.05), 5.0, 0)], robot, parents(robot), grid=open_grid()) is None


@pytest.mark.parametrize("other_gain, switch", [(4.9, False), (5.2, True)])
def test_the_current_goal_is_kept_unless_another_is_better_by_the_margin(other_gain, switch):
    """Both 2 m away, gain exponent 1: the goal's utility is 2.0; the other's is 2.45 (22.5 % better)
    or 2.6 (30 %)."""
    robot = np.array([3.05, 3.05])
    frontiers = [frontier(7, robot + [2.0, 0.0], 4.0, 0), frontier(8, robot - [2.0, 0.0], other_gain, 0)]
    planner = FrontierPlanner(planner_conf(goal_switch_margin=0.25, gain_exponent=1.0))
    route = planner.best_route(frontiers, robot, parents(robot), grid=open_grid(), keep=7, keep_margin=0.25)
    assert route.frontier_id == (8 if switch else 7)
    # without a current goal the better one always wins
    assert planner.best_route(frontiers, robot, parents(robot), grid=open_grid()).frontier_id == 8


def test_unreachable_frontier_is_blacklisted_after_max_failures_and_never_returned():
    robot = np.array([1.05, 1.05])
    grid = open_grid()
    walled = PlanningGrid(grid.origin_xy, grid.cell_m, grid.cost.copy())
    walled.cost[30, :] = np.inf  # a wall at x = 3.0 .. 3.1 cuts the grid in two
    unreachable = frontier(3, (4.55, 1.05), 50.0, 1)  # behind the wall, seen from behind the wall
    reachable = frontier(4, (2.05, 1.05), 1.0, 0)
    where = parents(robot, (5.05, 1.05))
    planner = FrontierPlanner(planner_conf(max_failures=3))
    for _ in range(3):
        assert 3 not in planner.blacklist
        route = planner.best_route([unreachable, reachable], robot, where, grid=walled)
        assert route.frontier_id == 4  # the valuable one cannot be reached
    assert planner.failures[3] == 3 and planner.blacklist == {3}
    assert 4 not in planner.failures
    # even once a path exists (the wall was a mapping error), a blacklisted frontier is never the goal again
    assert planner.best_route([unreachable, reachable], robot, where, grid=grid).frontier_id == 4
    assert planner.best_route([unreachable], robot, where, grid=grid) is None


def test_a_blacklisted_frontier_seen_again_does_not_become_the_goal_again():
    """The explorer's sequence: the goal fails max_failures times (e.g. its motion collides), the planner
    blacklists it and the explorer removes it from the tracker; the next frame sees it again."""
    from types import SimpleNamespace

    from frontiernet.frontiers import FrontierTracker

    robot = np.array([1.05, 1.05])
    seen = SimpleNamespace(position=np.array([3.05, 1.05, Z]), direction=np.array([1.0, 0.0, 0.0]), gain_m3=5.0)
    tracker = FrontierTracker(dict(load_config("explore").tracking))
    planner = FrontierPlanner(planner_conf(max_failures=3))
    tracker.add([seen], parent_pose=0, step=0)
    assert planner.best_route(tracker, robot, parents(robot), grid=open_grid()).frontier_id == 0
    for _ in range(3):
        planner.fail(0)
    assert 0 in planner.blacklist
    tracker.remove(0, "blacklisted")
    assert tracker.add([seen], parent_pose=0, step=1) == [None]  # the same frontier, from the same pose
    route = planner.best_route(tracker, robot, parents(robot), grid=open_grid())
    assert route is None, f"frontier {route.frontier_id} at the blacklisted frontier's place is the goal again"


def test_fail_reports_the_blacklisting_call():
    planner = FrontierPlanner(planner_conf(max_failures=2))
    assert planner.fail(5) is False
    assert planner.fail(5) is True and 5 in planner.blacklist


def test_robot_off_the_grid_gets_no_route():
    planner = FrontierPlanner(planner_conf())
    route = planner.best_route([frontier(0, (1.0, 1.0), 5.0, 0)], np.array([-3.0, 1.0]), parents((1.0, 1.0)),
                               grid=open_grid())
    assert route is None


# -- routes on a real map: two rooms and a door -----------------------------------------------------


@pytest.fixture(scope="module")
def two_room_map(two_room_scene, two_room_voxels):
    """The robot's map after turning on the spot at (1.5, 2.0) in the left room (it sees through the
    door up to the sensor range, x ~ 5 m, into the right room), as the explorer builds it."""
    conf = load_config("explore")
    occupancy = OccupancyMap.like(two_room_voxels, conf.map)
    renderer = Renderer(two_room_scene, SMALL, (0, 0, 0))
    for yaw in range(0, 360, 45):
        T = pose_from_heading(1.5, 2.0, Z, np.radians(yaw), np.radians(-5.0))
        frame = renderer.render(T)
        occupancy.integrate(frame.depth, frame.K, T)
        occupancy.clear_sphere(T[:3, 3], 0.2)
    return occupancy


def test_a_robot_standing_at_c_star_follows_the_edge_without_a_detour():
    """The robot stands next to c* (the mapped grid ends one cell on): the route is the tree edge
    from c* on, not a sub-step hop to c*'s cell centre first. Off the edge's line, that hop made
    the robot turn on the spot towards it and back, and every replanning started it again."""
    grid = open_grid()
    grid.cost[12:, :] = np.inf  # unknown beyond x = 1.2
    grid.cost[:, 12:] = np.inf  # ... and beyond y = 1.2
    parent, goal_xy = np.array([0.5, 0.52]), np.array([3.05, 3.1])  # an edge slightly off the diagonal
    robot = np.array([1.08, 1.12])
    route = FrontierPlanner(planner_conf()).best_route([frontier(0, goal_xy, 10.0, 0)], robot, parents(parent),
                                                        grid=grid)
    assert route is not None and route.mapped_until == 0
    direction = (goal_xy - parent) / np.linalg.norm(goal_xy - parent)
    offsets = route.waypoints - parent
    off_line = np.abs(offsets[:, 0] * direction[1] - offsets[:, 1] * direction[0])
    assert np.all(off_line < 1e-9)  # every waypoint on the edge ...
    assert np.all(np.diff(offsets @ direction) > 0)  # ... towards the frontier
    assert np.linalg.norm(route.waypoints[0] - robot) < 0.2


def test_a_frontier_whose_edge_crosses_a_mapped_obstacle_ranks_after_clear_ones():
    """The camera saw a frontier over a counter: its tree edge beyond c* crosses the counter's
    occupied cells, so following it would fail at the counter. The planner takes the next
    frontier with a clear edge instead of walking to c* first (house, oracle: a row of such
    frontiers along a counter cost a trip each; Vox@100 45 % -> 78 % on one start)."""
    def grid_with(counter: bool) -> PlanningGrid:
        grid = open_grid()
        grid.occupied = np.zeros(grid.cost.shape, bool)
        grid.cost[25:, :] = np.inf  # unknown beyond x = 2.5 (not an obstacle)
        if counter:
            grid.cost[20:22, :] = np.inf  # the counter at x in [2.0, 2.2): occupied
            grid.occupied[20:22, :] = True
        return grid

    over_counter = frontier(0, (3.5, 1.0), 20.0, 0)  # seen from (1, 1) over the counter
    beside = frontier(1, (1.0, 4.0), 5.0, 0)  # reachable, less utility
    robot, parent = np.array([1.0, 1.0]), parents((1.0, 1.0))
    planner = FrontierPlanner(planner_conf())
    route = planner.best_route([over_counter, beside], robot, parent, grid=grid_with(counter=True), keep=0,
                               keep_margin=0.25)
    assert route is not None and route.frontier_id == 1  # not kept as the goal either
    # without the counter the same edge only runs into unknown space: it is followed while mapping
    route = planner.best_route([over_counter, beside], robot, parent, grid=grid_with(counter=False))
    assert route is not None and route.frontier_id == 0 and route.mapped_until < len(route.waypoints)
    # with no clear edge left, the blocked one is the goal: the robot goes as near as it can and looks
    route = planner.best_route([over_counter], robot, parent, grid=grid_with(counter=True))
    assert route is not None and route.frontier_id == 0
    assert planner.failures == {}  # ranking is no failure: a noisy map's wall may turn out free


def test_an_edge_passing_closer_to_an_obstacle_than_the_body_radius_counts_as_blocked():
    """The move check refuses a body (``Explorer.body_radius``) that touches an occupied cell, so an
    edge beyond c* passing 0.15 m beside a post is blocked for a 0.22 m body, not for a point."""
    grid = open_grid()
    grid.occupied = np.zeros(grid.cost.shape, bool)
    grid.cost[25:, :] = np.inf  # unknown beyond x = 2.5
    grid.occupied[30, 11] = True  # a post: the cell [3.0, 3.1) x [1.1, 1.2), 0.15 m from the edge y = 0.95
    goals = [frontier(0, (4.0, 0.95), 20.0, 0), frontier(1, (1.0, 4.0), 5.0, 0)]
    robot, parent = np.array([1.0, 0.95]), parents((1.0, 0.95))
    for radius, goal in ((0.0, 0), (0.14, 0), (0.22, 1)):
        route = FrontierPlanner(planner_conf(), body_radius_m=radius).best_route(goals, robot, parent, grid=grid)
        assert route.frontier_id == goal, radius


def walled_grid() -> PlanningGrid:
    """An open 6 m grid with a wall along y in [3.0, 3.1) and a post at x in [1.0, 1.2), y in [1.0, 2.6);
    cells closer than 0.3 m to either are not traversable."""
    grid = open_grid()
    grid.occupied = np.zeros(grid.cost.shape, bool)
    grid.occupied[:, 30] = True
    grid.occupied[10:12, 10:26] = True
    near = ndimage.distance_transform_edt(~grid.occupied) * grid.cell_m < 0.3
    grid.cost[near] = np.inf
    return grid


def test_a_frontier_against_a_wall_is_approached_from_the_nearest_cell_that_sees_it():
    """A map frontier lies against a wall, and the tree edge from the pose that saw it passes the
    post: following the edge would fail. The planner approaches it from the nearest reachable cell
    in sight of it instead, so it is neither left for last nor blacklisted on the spot."""
    grid = walled_grid()
    robot = np.array([2.0, 1.5])
    labels, _ = ndimage.label(np.isfinite(grid.cost))
    reachable = labels == labels[grid.cell(robot)]  # the wall runs across: its far side is out of reach
    goal_xy = np.array([0.55, 2.9])  # against the wall, 0.1 m from its face
    edge, at = approach_edge(goal_xy, grid, reachable, 1.5, 0.1)
    cell = edge[at]
    assert at == len(edge) - 1 and reachable[grid.cell(cell)]
    assert len(edge) == 1  # the robot plans to the cell and looks from there: no line to follow
    # no reachable cell in sight of the frontier is nearer (brute force over every cell in range)
    nearest = np.linalg.norm(cell - goal_xy)
    for other in grid.centres(np.argwhere(reachable)):
        d = np.linalg.norm(other - goal_xy)
        if d < nearest - 1e-9:
            sight = edge_points(goal_xy, other, 0.1)
            sight = sight[np.linalg.norm(sight - goal_xy, axis=1) > 0.15]
            assert grid.touches_occupied(sight, 1e-6).any()
    # beyond the wall nothing reachable sees it (the near side's line of sight crosses the wall)
    assert approach_edge(np.array([2.0, 3.3]), grid, reachable, 1.5, 0.1) is None
    # in the planner: the edge from (2.0, 1.5), the pose that saw it, passes the post
    goal = frontier(0, goal_xy, 10.0, 0)
    for radius, approached in ((0.0, False), (1.5, True)):
        planner = FrontierPlanner(planner_conf(approach_radius_m=radius), body_radius_m=0.22)
        route = planner.best_route([goal], robot, parents(robot), grid=grid)
        assert route is not None and route.frontier_id == 0
        beyond = route.waypoints[route.mapped_until:]
        assert grid.touches_occupied(beyond, 0.22).any() != approached, radius


def test_route_behind_the_door_goes_through_it_and_keeps_the_clearance(two_room_map):
    conf = planner_conf()
    robot = np.array([1.0, 0.8])  # the left room's lower corner: the door is up and to the right
    grid = PlanningGrid.from_map(two_room_map, Z, conf, robot)
    parent = np.array([1.5, 2.0])  # the pose that saw the frontier through the door
    goal = frontier(0, (5.7, 2.0), 10.0, 0)  # beyond the sensor range: unknown on the map
    assert not np.isfinite(grid.lookup(grid.cost, goal.position[None, :2])[0])
    route = FrontierPlanner(conf).best_route([goal], robot, parents(parent), grid=grid)
    assert route is not None and route.frontier_id == 0

    waypoints = route.waypoints
    mapped, beyond = waypoints[:route.mapped_until], waypoints[route.mapped_until:]
    assert 0 < route.mapped_until < len(waypoints)  # planned to c*, then along the tree edge
    np.testing.assert_allclose(waypoints[-1], [5.7, 2.0])
    assert np.allclose(beyond[:, 1], 2.0) and np.all(np.diff(beyond[:, 0]) > 0)  # the straight line of sight
    assert 4.0 < mapped[-1, 0] < 5.7  # c* lies in the mapped part of the right room

    # the mapped part: consecutive cells, through the door, every cell free with the clearance
    assert np.linalg.norm(mapped[0] - robot) < 0.25  # the first cell next to the robot's
    assert np.all(np.linalg.norm(np.diff(mapped, axis=0), axis=1) < 0.15)
    (px0, px1), (dy0, dy1) = TWO_ROOM["partition_x"], TWO_ROOM["door_y"]
    in_wall = (mapped[:, 0] > px0 - 0.05) & (mapped[:, 0] < px1 + 0.05)
    assert in_wall.any()
    clearance = float(conf["clearance_m"])
    assert np.all(mapped[in_wall, 1] > dy0 + clearance - 0.05) and np.all(mapped[in_wall, 1] < dy1 - clearance + 0.05)
    free, occupied = two_room_map.slice_2d(Z - conf["height_band_m"], Z + conf["height_band_m"])
    to_obstacle = ndimage.distance_transform_edt(~occupied) * two_room_map.voxel_size
    assert np.all(grid.lookup(free.astype(float), mapped, outside=0) == 1)
    assert np.all(grid.lookup(to_obstacle, mapped, outside=0) >= clearance)
    # and against the true walls (the agent's collision sphere is 0.2 m)
    assert np.all((mapped[:, 0] > 0.2) & (mapped[:, 1] > 0.2) & (mapped[:, 1] < 3.8))
    # the distance used in the utility is at least the route's length
    assert route.distance_m >= arc_lengths(np.vstack([robot, waypoints]))[-1] - 0.2
    assert route.utility == pytest.approx(10.0 ** conf["gain_exponent"] / route.distance_m)  # Eq. 8, gain^e


def test_planning_grid_blocks_unknown_and_obstacles_and_keeps_the_robot_cell_open(two_room_map):
    conf = planner_conf()
    robot_in_unknown = np.array([4.0, 0.4])  # the right room's corner behind the partition: never seen
    grid = PlanningGrid.from_map(two_room_map, Z, conf, robot_in_unknown)
    costs = grid.lookup(grid.cost, np.array([[1.5, 1.0], [1.5, 0.05], [3.0, 1.0], [4.0, 0.6], [4.0, 0.4],
                                             [-9.0, 0.0]]))
    free_middle, wall_side, partition, unknown, robot, outside = costs
    assert np.isfinite(free_middle) and free_middle >= 1.0
    assert not np.isfinite(wall_side) and not np.isfinite(partition) and not np.isfinite(unknown)
    assert np.isfinite(robot)  # the robot stands in free space whatever the map says
    assert outside == np.inf
    # the cost grows towards walls: paths keep to the middle
    assert grid.lookup(grid.cost, np.array([[1.0, 0.5]]))[0] > grid.lookup(grid.cost, np.array([[1.0, 1.5]]))[0]


def corridor_stub_map():
    """A 4 m x 1 m corridor along x (0.1 m cells, 40 x 10 free; the same in every band and layer) whose upper wall (y = 1.0) is mapped
    and whose lower wall (y < 0) the camera never faced: unknown, like a wall beside a route taken
    after a turn on the spot (KTH 50052750, the collision at step 3,788)."""
    free = np.zeros((40, 14), bool)
    free[:, 2:12] = True  # y in [0.2, 1.2): the corridor's cells, 0.2 m from the unknown side
    occupied = np.zeros_like(free)
    occupied[:, 12] = True  # the mapped wall
    return SimpleNamespace(slice_2d=lambda z0, z1: (free, occupied), voxel_size=0.1, origin=np.zeros(3))  # every band


@pytest.mark.parametrize("unknown_is_obstacle", [True, False])
def test_routes_keep_the_clearance_to_unknown_cells_beside_them(unknown_is_obstacle):
    conf = planner_conf(unknown_is_obstacle=unknown_is_obstacle)
    occupancy = corridor_stub_map()
    robot, goal = np.array([0.55, 0.75]), frontier(0, (3.55, 0.75), 10.0, 0)
    grid = PlanningGrid.from_map(occupancy, Z, conf, robot)
    beside_unknown = grid.lookup(grid.cost, np.array([[2.05, 0.25], [2.05, 0.35]]))
    # the old rule (occupied only) plans 0.1-0.2 m from the unknown wall: a 0.2 m body there touches it
    assert np.isfinite(beside_unknown).all() != unknown_is_obstacle
    route = FrontierPlanner(conf).best_route([goal], robot, parents(robot), grid=grid)
    assert route is not None and route.mapped_until == len(route.waypoints)  # all on the map
    free, _ = occupancy.slice_2d(0, 0)
    to_not_free = ndimage.distance_transform_edt(free) * 0.1
    clearance = float(conf["clearance_m"])
    if unknown_is_obstacle:
        assert grid.lookup(to_not_free, route.waypoints, outside=0).min() >= clearance - 1e-9


def test_boxed_in_only_beside_obstacles_with_no_way_out():
    conf = planner_conf()
    free = np.zeros((30, 30), bool)
    free[5:25, 5:25] = True
    occupied = np.zeros_like(free)
    occupied[12:18, 12:18] = True  # a counter top in the band, free above the camera's layer
    free[occupied] = False
    occupancy = SimpleNamespace(slice_2d=lambda z0, z1: (free, occupied), voxel_size=0.1, origin=np.zeros(3))
    on_counter = np.array([1.45, 1.45])
    grid = PlanningGrid.from_map(occupancy, Z, conf, on_counter)
    assert grid.boxed_in(on_counter, conf["clearance_m"])
    # beside the counter, closer than the clearance, but with a free neighbour further away: not boxed in
    beside = np.array([1.05, 1.45])
    assert not PlanningGrid.from_map(occupancy, Z, conf, beside).boxed_in(beside, conf["clearance_m"])
    # at the start the neighbours are unknown, not obstacles: the routes leave along the tree edges
    unknown = np.zeros_like(free)
    start = np.array([1.45, 1.45])
    empty = SimpleNamespace(slice_2d=lambda z0, z1: (unknown, unknown), voxel_size=0.1, origin=np.zeros(3))
    assert not PlanningGrid.from_map(empty, Z, conf, start).boxed_in(start, conf["clearance_m"])


def test_traversed_cells_are_the_cells_the_path_passed_through():
    record = TraversedCells(np.zeros(2), 0.1, np.zeros((40, 40), bool))
    record.add((0.55, 0.55))
    assert record.mask.sum() == 1 and record.mask[5, 5]  # the first point: its own cell
    record.add((1.55, 0.55))  # along x: cells 5..15 of row j = 5
    record.add((1.55, 2.05))  # then along y: 6..20 of column i = 15
    assert record.mask.sum() == 11 + 15 and record.mask[5:16, 5].all() and record.mask[15, 5:21].all()
    assert record.contains((1.02, 0.51)) and not record.contains((1.02, 0.75)) and not record.contains((-1.0, 0.5))
    record.add((1.55, -0.95))  # off the grid: the cells inside are marked, nothing fails
    assert record.mask[15, 0] and record.mask.sum() == 26 + 5
    # a bump at (1.55, 1.0) unmarks the cells whose squares come within 0.2 m of it (i = 14..16, j = 8..11)
    record.forget((1.55, 1.0), 0.2)
    assert not record.mask[15, 8:12].any() and record.mask[15, 7] and record.mask[15, 12]
    assert record.mask.sum() == 31 - 4
    record.forget((-5.0, -5.0), 0.2)  # off the grid: nothing
    assert record.mask.sum() == 27


def sealed_corridor_map():
    """:func:`corridor_stub_map` after the robot walked it from x = 3.55 to x = 0.55, its map then
    sealed at x = 2.0-2.2 (a monocular depth's smeared walls)."""
    occupancy = corridor_stub_map()
    free, occupied = occupancy.slice_2d(0, 0)
    occupied[20:23, 2:12] = True  # the phantom wall across
    free[occupied] = False
    return occupancy


def test_cells_the_robot_passed_through_stay_open_when_the_map_seals_them():
    """With ``planner.traversed_is_free`` the way back through a doorway the map has since sealed
    stays open: the frontier seen from the far side is reached, not blacklisted."""
    conf = planner_conf(max_failures=1)
    occupancy = sealed_corridor_map()
    came_from, robot = np.array([3.55, 0.75]), np.array([0.55, 0.75])
    goal = frontier(0, (3.95, 0.75), 10.0, 0)  # seen from where the robot came from
    sealed = PlanningGrid.from_map(occupancy, Z, conf, robot)
    assert FrontierPlanner(conf).best_route([goal], robot, parents(came_from), grid=sealed) is None
    traversed = TraversedCells.like(SimpleNamespace(origin=np.zeros(3), voxel_size=0.1, shape=(40, 14, 1)))
    for x in np.arange(3.55, 0.5, -0.11):  # the walk, in increments
        traversed.add((x, 0.75))
    open_grid_ = PlanningGrid.from_map(occupancy, Z, conf, robot, traversed.mask)
    route = FrontierPlanner(conf).best_route([goal], robot, parents(came_from), grid=open_grid_)
    assert route is not None and route.frontier_id == 0
    assert np.allclose(route.waypoints[:, 1], 0.75)  # back along the cells it walked, through the phantom wall
    # the cells it walked that were open anyway keep their cost; the sealed ones cost a cell at the clearance limit
    walked = traversed.mask & np.isfinite(sealed.cost)
    np.testing.assert_array_equal(open_grid_.cost[walked], sealed.cost[walked])
    assert np.allclose(open_grid_.cost[20:23, 7], 1.0 + conf["centre_weight"] / conf["clearance_m"])
    assert not np.isfinite(open_grid_.cost[20:23, 3]).any()  # the rest of the phantom wall stays shut


# -- map-free mode: the tree and the trajectory -----------------------------------------------------


def test_map_free_route_follows_the_trajectory_back_to_the_parent_then_the_edge():
    """An L-shaped trajectory (0,0) -> (2,0) -> (2,2); the frontier at (1,-1) was seen from (1,0)."""
    xy = np.concatenate([np.c_[np.arange(0, 2.0, 0.1), np.zeros(20)], np.c_[np.full(21, 2.0), np.arange(0, 2.01, 0.1)]])
    graph = PoseGraph(0.05)
    for p in xy:
        graph.add(p)
    robot = len(xy) - 1
    target = frontier(0, (1.0, -1.0), 8.0, parent=10, yaw=-np.pi / 2)
    planner = FrontierPlanner(planner_conf(edge_spacing_m=0.1))
    route = planner.best_route([target], xy[robot], lambda i: xy[i], graph=graph, robot_index=robot)
    assert route.distance_m == pytest.approx(2.0 + 1.0 + 1.0, abs=1e-3)  # back up, back along, then the edge
    assert route.utility == pytest.approx(8.0 ** planner.conf["gain_exponent"] / 4.0, rel=1e-3)
    back = route.waypoints[:route.mapped_until]
    np.testing.assert_allclose(back, xy[robot - 1:9:-1])  # the poses visited, in reverse, to the parent
    np.testing.assert_allclose(route.waypoints[-1], [1.0, -1.0])
    edge = route.waypoints[route.mapped_until:]
    assert np.allclose(edge[:, 0], 1.0) and np.all(np.diff(edge[:, 1]) < 0)


def test_map_free_route_goes_on_along_the_edge_from_a_robot_standing_on_it():
    """The robot walked from its parent pose (0, 0) along the edge to (0, 0.5), towards the frontier
    at (0, 1): the route goes on to the frontier instead of back to the parent first (which kept a
    robot between the two ends of one edge for hundreds of steps)."""
    xy = np.c_[np.zeros(6), np.arange(0, 0.51, 0.1)]
    graph = PoseGraph(0.3)
    for p in xy:
        graph.add(p)
    robot = len(xy) - 1
    target = frontier(0, (0.0, 1.0), 8.0, parent=0, yaw=np.pi / 2)
    route = FrontierPlanner(planner_conf(edge_spacing_m=0.1, pose_link_m=0.3)).best_route(
        [target], xy[robot], lambda i: xy[i], graph=graph, robot_index=robot)
    assert route.distance_m == pytest.approx(0.5, abs=1e-6)
    assert np.all(np.diff(route.waypoints[:, 1]) > 0) and route.waypoints[0, 1] >= 0.5 - 1e-9
    np.testing.assert_allclose(route.waypoints[-1], [0.0, 1.0])
    # off the edge by more than a pose link: back to the parent first, as before
    aside = np.array([0.4, 0.5])
    graph.add(aside)
    route = FrontierPlanner(planner_conf(edge_spacing_m=0.1, pose_link_m=0.3)).best_route(
        [target], aside, lambda i: np.vstack([xy, aside])[i], graph=graph, robot_index=len(xy))
    assert route.waypoints[route.mapped_until - 1] == pytest.approx([0.0, 0.0])


def test_map_free_prefers_the_frontier_that_is_closer_along_the_trajectory():
    """Two frontiers equally far from the robot in a straight line; one's parent is far back along the path."""
    xy = np.concatenate([np.c_[np.arange(0, 3.0, 0.1), np.zeros(30)], np.c_[np.full(21, 3.0), np.arange(0, 2.01, 0.1)]])
    graph = PoseGraph(0.05)
    for p in xy:
        graph.add(p)
    robot = len(xy) - 1  # at (3, 2)
    late = frontier(0, (3.5, 2.5), 3.0, parent=robot - 1)
    early = frontier(1, (0.0, 0.5), 3.0, parent=0)
    route = FrontierPlanner(planner_conf()).best_route([late, early], xy[robot], lambda i: xy[i], graph=graph,
                                                        robot_index=robot)
    assert route.frontier_id == 0


# -- resampling into motion increments --------------------------------------------------------------


def test_resample_route_spaces_waypoints_by_arc_and_keeps_the_mapped_part():
    route = Route(0, np.array([[1.0, 0.0], [1.0, 1.0]]), mapped_until=1, distance_m=2.0, utility=1.0)
    spacing = 0.11
    resampled = resample_route(route, np.array([0.0, 0.0]), spacing)
    points = np.vstack([[0.0, 0.0], resampled.waypoints])
    steps = np.linalg.norm(np.diff(points, axis=0), axis=1)
    assert np.all(steps <= spacing + 1e-9)  # no increment longer than one step
    arc = np.append(np.arange(spacing, 2.0, spacing), 2.0)
    assert len(resampled.waypoints) == len(arc)
    np.testing.assert_allclose(resampled.waypoints[-1], [1.0, 1.0])  # the frontier is kept
    straight = np.abs(resampled.waypoints[:, 0] - 1.0) > 1e-9
    np.testing.assert_allclose(resampled.waypoints[straight, 0], arc[straight])  # along the first leg
    # the mapped part ends where the original did (arc 1.0, the corner)
    assert resampled.mapped_until == 9
    assert np.all(resampled.waypoints[:9, 1] == 0.0) and np.all(resampled.waypoints[9:, 1] > 0.0)
    assert (resampled.frontier_id, resampled.distance_m, resampled.utility) == (0, 2.0, 1.0)


def test_resample_short_route_is_its_last_waypoint():
    route = Route(2, np.array([[0.03, 0.0], [0.05, 0.02]]), mapped_until=2, distance_m=0.1, utility=1.0)
    resampled = resample_route(route, np.zeros(2), 0.11)
    np.testing.assert_allclose(resampled.waypoints, [[0.05, 0.02]])
    assert resampled.mapped_until == 1

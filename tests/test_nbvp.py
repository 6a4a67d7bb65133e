"""NBVP, ``--method nbvp`` (Bircher et al. ICRA 2016, ethz-asl/nbvplanner): its tree stays in the
known free space with edges of at most the extension length, its gains are discounted by
exp(-lambda x branch length), and the method explores, repeats with its seed and stops when done."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from frontiernet.exploration.methods import MethodContext, make_method, method_names
from frontiernet.exploration.move_check import body_radius
from frontiernet.exploration.nbvp import NbvpSource, visited
from frontiernet.errors import InputError
from frontiernet.exploration.motion import wrap_angle
from frontiernet.exploration.nbvp_tree import NbvpSettings, accumulated_gains, grow_tree, stop_node
from frontiernet.exploration.run import load_run_config
from frontiernet.geometry import pose_from_heading, poses_from_headings
from frontiernet.mapping import FREE
from frontiernet.simulator.camera import PinholeCamera, Renderer
from conftest import seal_the_door
from frontiernet.planning.traversed import TraversedCells
from test_methods import run_method

Z = 1.2  # the camera height of the fixtures' poses, metres


@pytest.fixture
def looked_around(two_room_scene, two_room_voxels):
    """The nbvp method in the two-room box, its map filled by a look around from (1.5, 2.0) in the
    first room (the door to the second at x = 3): (method, context, the robot's pose)."""
    conf = load_run_config()
    context = MethodContext(conf, conf.sim, scene=two_room_scene, voxels=two_room_voxels,
                            rng=np.random.default_rng(5))
    renderer = Renderer(two_room_scene, PinholeCamera.from_config(conf.sim.camera), (0, 0, 0))
    pitch = np.radians(float(conf.motion.pitch_deg))
    for turn in range(8):
        T = pose_from_heading(1.5, 2.0, Z, turn * np.pi / 4, pitch)
        frame = renderer.render(T)
        context.map.integrate(frame.depth, frame.K, T)
        context.map.clear_sphere(T[:3, 3], 0.2)
    return make_method("nbvp", context), context, pose_from_heading(1.5, 2.0, Z, 0.0, pitch)


def test_nbvp_is_a_method_with_one_fresh_target_and_its_settings_from_the_config(looked_around):
    method, context, _ = looked_around
    assert "nbvp" in method_names()
    assert isinstance(method.source, NbvpSource) and method.fresh_frontiers and method.moves is None
    assert method.source.planner.rng is context.rng and method.source.map is context.map
    settings = method.source.planner.settings
    assert (settings.extension_m, settings.degressive_coeff) == (1.0, 0.5)  # nbvplanner's
    assert (settings.init_iterations, settings.cutoff_iterations) == (15, 200)
    assert settings.found_on == "views" and settings.yaw_window_deg == 45.0  # ours (configs/explore.yaml)
    assert settings.sample_region == "box"  # nbvplanner's


def test_bad_found_on_or_yaw_window_is_refused_and_missing_keys_keep_nbvplanners_rules():
    section = dict(load_run_config().nbvp)
    with pytest.raises(InputError, match="nbvp.found_on"):
        NbvpSettings.from_config({**section, "found_on": "sometimes"})
    with pytest.raises(InputError, match="nbvp.yaw_window_deg"):
        NbvpSettings.from_config({**section, "yaw_window_deg": 270.0})
    bare = {k: v for k, v in section.items() if k not in ("found_on", "yaw_window_deg")}
    settings = NbvpSettings.from_config(bare)
    assert settings.found_on == "discounted" and settings.yaw_window_deg == 180.0


def test_a_sampled_nodes_yaw_lies_within_the_window_of_its_incoming_edge(looked_around):
    method, context, T = looked_around
    planner = method.source.planner
    tree = planner.grow(T)
    offset = tree.xy[1:] - tree.xy[tree.parent[1:]]
    off = np.array([wrap_angle(a) for a in tree.yaw[1:] - np.arctan2(offset[:, 1], offset[:, 0])])
    window = np.radians(planner.settings.yaw_window_deg)
    assert np.all(np.abs(off) <= window + 1e-9) and np.abs(off).max() > 0.5 * window


@pytest.mark.parametrize("region", ["box", "known_free"])
def test_the_tree_lies_in_known_free_space_with_edges_of_at_most_the_extension(looked_around, region):
    method, context, T = looked_around
    conf, planner = context.conf, method.source.planner
    planner.settings = dataclasses.replace(planner.settings, sample_region=region)
    tree = planner.grow(T)
    assert tree.found and len(tree.xy) >= 1 + planner.settings.init_iterations
    parents = tree.parent[1:]
    assert np.all(parents < np.arange(1, len(tree.xy)))  # a parent comes first
    edges = np.hypot(*(tree.xy[1:] - tree.xy[parents]).T)
    assert np.all(edges <= planner.settings.extension_m + 1e-9) and edges.max() > 0.5
    np.testing.assert_allclose(tree.length_m[1:], tree.length_m[parents] + edges)
    # every node and every point of every edge: free at the camera's height, the body clear of
    # occupied voxels over the planning band (the explorer's move check)
    t = np.linspace(0.0, 1.0, 21)[:, None, None]
    points = (tree.xy[parents][None] + t * (tree.xy[1:] - tree.xy[parents])[None]).reshape(-1, 2)
    assert np.all(context.map.state_at(np.column_stack([points, np.full(len(points), Z)])) == FREE)
    radius, band = body_radius(conf.planner, 0.1, 0.0), float(conf.planner.height_band_m)
    assert not any(context.map.cylinder_touches_occupied(p, radius, Z - band, Z + band) for p in points)
    assert tree.length_m.max() > planner.settings.extension_m  # branches of more than one edge


def test_the_tree_grows_back_through_a_door_the_map_sealed_where_the_robot_has_been(looked_around):
    """With the context's ``traversed`` (``planner.monocular_traversed_is_free`` on a monocular source), the
    cells the robot passed through are free space for the tree, as for the planner and the move check."""
    method, context, T = looked_around
    planner, xy = method.source.planner, T[:2, 3]
    planner.settings = dataclasses.replace(planner.settings, sample_region="known_free")  # draws in the region

    def farthest_east() -> float:  # of the node positions drawn, over the free space the robot's region holds
        return float(planner.samples(planner.free_space(xy, Z), xy)[0][:, 0].max())

    assert farthest_east() > 3.1  # the door is open: the second room is in reach
    seal_the_door(context)
    assert farthest_east() < 2.9  # sealed in the map: the first room only
    context.traversed = TraversedCells.like(context.map)
    for x in (4.5, 1.5):  # the robot came from the second room through the door
        context.traversed.add((x, 2.0))
    assert farthest_east() > 3.1


def test_a_nodes_gain_is_its_parents_plus_its_view_discounted_by_the_branch_length(looked_around):
    method, context, T = looked_around
    planner = method.source.planner
    tree = planner.grow(T)
    lam = planner.settings.degressive_coeff
    poses = poses_from_headings(np.column_stack([tree.xy, np.full(len(tree.xy), Z)]), tree.yaw, planner.pitch)
    view = context.map.visible_unknown_volume(poses[1:], planner.settings.gain_width_px, planner.focal_px,
                                              planner.settings.gain_range_m)
    np.testing.assert_allclose(tree.view_gain_m3[1:], view)
    discounted = view * np.exp(-lam * tree.length_m[1:])
    np.testing.assert_allclose(tree.gain_m3[1:], tree.gain_m3[tree.parent[1:]] + discounted)
    assert tree.gain_m3[0] == 0.0 and tree.view_gain_m3.max() > 1.0
    # a chain root -> a (1 m) -> b (2 m from the root)
    gains = accumulated_gains(np.array([0.0, 2.0, 3.0]), np.array([-1, 0, 1]), np.array([0.0, 1.0, 2.0]), 0.5)
    np.testing.assert_allclose(gains, [0.0, 2.0 * np.exp(-0.5), 2.0 * np.exp(-0.5) + 3.0 * np.exp(-1.0)])


def test_a_tree_gives_up_after_its_attempts_per_node_as_nbvplanner_does():
    """nbvplanner's planner loop gives up after 1000 x (nodes + 1) iterations (``nbvp.attempts_per_node``):
    goals whose edge leaves the free space are attempts too, and each node added allows as many more."""
    free = np.ones((10, 10), bool)  # a free 1 m square at the origin
    outside = np.tile([[5.0, 5.0]], (5, 1))  # the edge towards them leaves the square: refused
    goals = np.concatenate([outside, [[0.8, 0.5]], outside, [[0.5, 0.8]]])

    def nodes(attempts_per_node: int) -> int:
        xy, parent = np.zeros((10, 2)), np.full(10, -1, np.int64)
        xy[0] = (0.5, 0.5)
        no_body = np.zeros((1, 1), bool), np.zeros_like(free), 0.0, 0.0  # cells only (edge_check: cells)
        return grow_tree(free, *no_body, 0.0, 0.0, 0.1, goals, 1.0, 0.0, xy, parent, np.zeros(10),
                         np.full(10, -1, np.int64), attempts_per_node)

    assert nodes(5) == 1  # five refused goals: the root's five attempts spent
    assert nodes(6) == 3  # the sixth is taken, and the second node allows six more: the last is taken too
    assert load_run_config().nbvp.attempts_per_node == 1000  # nbvplanner's


def test_growth_stops_at_the_first_node_with_enough_nodes_and_some_gain():
    gains = np.array([0.0, 0.0, 3.0, 0.5, 0.2, 0.0])
    assert stop_node(gains, 1, 6, init_iterations=3, threshold=1.0) == 3  # 3 nodes, node 2 above 1
    assert stop_node(gains, 1, 6, init_iterations=1, threshold=1.0) == 2
    assert stop_node(gains, 1, 6, init_iterations=3, threshold=5.0) is None
    assert stop_node(gains, 4, 6, init_iterations=3, threshold=1.0) == 4  # only nodes from `start` on
    # found_on: views: the best node by discounted gain must promise the threshold undiscounted
    discounted = np.array([0.0, 0.2, 0.1, 0.3, 0.3, 0.0])
    views = np.array([0.0, 0.5, 3.0, 1.5, 9.0, 0.0])
    assert stop_node(discounted, 1, 6, init_iterations=1, threshold=1.0) is None  # the former rule
    assert stop_node(discounted, 1, 6, 1, 1.0, views) == 3  # node 3 is the best of 1..3 (node 2's view not)
    assert stop_node(discounted, 1, 6, 1, 2.0, views) is None  # node 4 ties node 3: the first is the best


def test_a_fully_known_map_gives_no_gain_after_the_cutoff_and_no_proposal(looked_around):
    method, context, T = looked_around
    context.map._observed[:] = True  # every voxel known: nothing left to see
    tree = method.source.planner.grow(T)
    assert not tree.found and len(tree.xy) == method.source.planner.settings.cutoff_iterations + 1
    assert method.source.observe(T) is None


def test_the_target_is_the_best_branchs_first_node_kept_until_a_pose_reaches_it(looked_around):
    method, context, T = looked_around
    source = method.source
    target = source.observe(T)
    tree = source.tree
    branch = tree.branch(tree.best)
    assert target is not None and np.allclose(target.xy, tree.xy[branch[0]]) and target.yaw == pytest.approx(
        tree.yaw[branch[0]])
    assert target.gain_m3 == pytest.approx(tree.view_sum_m3[tree.best]) and target.gain_m3 > 1.0  # found_on: views
    np.testing.assert_allclose(tree.view_sum_m3[branch[-1]], tree.view_gain_m3[branch].sum())
    np.testing.assert_allclose(source.memory[:, :2], tree.xy[branch[1:]])  # the rest, for the next tree
    observation = source.observation(Z, T)
    np.testing.assert_allclose(observation.position, [*target.xy, Z])
    np.testing.assert_allclose(observation.direction, [np.cos(target.yaw), np.sin(target.yaw), 0.0], atol=1e-12)
    assert source.observe(T) is target and source.trees == 1  # the same target: no new tree
    at_target = pose_from_heading(target.xy[0], target.xy[1], Z, target.yaw)
    assert visited(target.xy[None], np.array([target.yaw]), np.array([[*target.xy, target.yaw]]), 0.5, 0.4)[0]
    assert source.observe(at_target) is not target and source.trees == 2  # reached: a new tree from there


@pytest.fixture(scope="module")
def nbvp_run(plan_spec, tmp_path_factory):
    """A 90-step nbvp run on the two-room plan (default seed): (metrics, trajectory)."""
    out = tmp_path_factory.mktemp("nbvp") / "run"
    metrics = run_method(plan_spec, out, "nbvp", 90, "--depth", "gt")
    return metrics, json.loads((out / "trajectory.json").read_text()), out


def test_nbvp_explores_well_beyond_its_start_turn_without_collisions(nbvp_run):
    metrics, _, _ = nbvp_run
    coverage = np.array(metrics["coverage_per_step"])
    after_turn = coverage[33]  # the 360 deg start turn: 33 increments of 11 deg
    assert metrics["method"] == "nbvp" and metrics["collisions"] == 0 and metrics["goals"] >= 3
    assert metrics["coverage"] > after_turn + 0.2 and metrics["path_length_m"] > 2.0


def test_the_same_seed_gives_the_same_nbvp_run(nbvp_run, plan_spec, tmp_path):
    metrics, trajectory, _ = nbvp_run
    again = run_method(plan_spec, tmp_path / "again", "nbvp", 90, "--depth", "gt")
    repeat = json.loads((tmp_path / "again" / "trajectory.json").read_text())
    np.testing.assert_array_equal(np.array(trajectory["T_world_cam"]), np.array(repeat["T_world_cam"]))
    assert metrics["coverage_per_step"] == again["coverage_per_step"]


def test_nbvp_stops_with_no_frontiers_left_in_a_small_closed_room(closet_spec, tmp_path):
    metrics = run_method(closet_spec, tmp_path / "closet", "nbvp", 300, "--depth", "gt")
    assert metrics["stop_reason"] == "no frontiers left" and metrics["steps"] < 300
    assert metrics["collisions"] == 0 and metrics["coverage"] > 0.6



def test_box_sampling_draws_goals_over_the_whole_map_most_of_them_outside_the_known_free_space(looked_around):
    """``nbvp.sample_region: box`` (nbvplanner's RrtTree::iterate, the default): goals uniform over the map's
    XY extent, so the tree's nearest nodes are steered towards unexplored space; ``known_free`` draws them
    in the robot's known free region only."""
    method, context, T = looked_around
    planner = method.source.planner
    space = planner.free_space(T[:2, 3], Z)
    extent = np.asarray(space.free.shape) * space.cell_m
    drawn = {}
    for region in ("box", "known_free"):
        planner.settings = dataclasses.replace(planner.settings, sample_region=region)
        drawn[region], yaws = planner.samples(space, T[:2, 3])
        assert len(drawn[region]) == planner.draws and np.all(np.abs(yaws) <= np.pi)
    cells = {region: tuple(((xy - space.origin_xy) // space.cell_m).astype(int).T) for region, xy in drawn.items()}
    assert np.all(space.free[cells["known_free"]])
    box = drawn["box"]
    assert np.all((box >= space.origin_xy) & (box < space.origin_xy + extent))
    np.testing.assert_allclose(box.mean(axis=0), space.origin_xy + extent / 2, atol=0.05 * extent.max())
    assert np.mean(space.free[cells["box"]]) == pytest.approx(space.free.mean(), abs=0.03) and space.free.mean() < 0.5

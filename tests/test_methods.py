"""Exploration methods (issue 6): every method runs in the same explorer and differs only in
where its goal candidates come from and how the goal is chosen."""

from __future__ import annotations

import contextlib
import io
import json
from types import SimpleNamespace

import numpy as np
import pytest

from conftest import explore_section
from frontiernet.cli.main import main
from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.exploration.methods import ImageSource, MapSource, Method, MethodContext, make_method, method_names
from frontiernet.frontiers import FrontierTracker
from frontiernet.planning.planner import FrontierPlanner

BASELINES = ("classic", "gain-distance", "random-frontier", "vacuum")


def run_method(spec, out, method: str, steps: int, *options: str) -> dict:
    stream = io.StringIO()
    with contextlib.redirect_stdout(stream), contextlib.redirect_stderr(stream):
        code = main(["explore", "--scene", spec, "--method", method, "--max-steps", str(steps), "--no-video",
                     "--out", str(out), *options])
    assert code == 0, stream.getvalue()
    return json.loads((out / "metrics.json").read_text())


def test_every_built_in_method_is_listed_and_built(two_room_scene, two_room_voxels):
    names = method_names()
    for name in ("frontiernet", "oracle", "df-uniform", "discontinuity-gain", "discontinuity-uniform", *BASELINES):
        assert name in names
    context = MethodContext(load_config("explore", overrides=["run.seed=4"]), load_config("sim"),
                            scene=two_room_scene, voxels=two_room_voxels)
    assert context.map.shape == two_room_voxels.shape and context.rng.random() == np.random.default_rng(4).random()
    classic, gain, random_frontier, vacuum = (make_method(name, context) for name in BASELINES)
    assert isinstance(classic.source, MapSource) and classic.goal == "nearest" and classic.fresh_frontiers
    assert classic.source.map is context.map  # the run's map, which the explorer fills
    assert gain.source.gain == "unknown_volume" and gain.goal == "utility"
    assert random_frontier.goal == "random" and vacuum.source is None and vacuum.goal == "vacuum"
    assert vacuum.moves.rng is context.rng and all(m.moves is None for m in (classic, gain, random_frontier))
    uniform = make_method("discontinuity-uniform", context)  # needs no model file
    assert isinstance(uniform.source, ImageSource) and not uniform.fresh_frontiers and uniform.goal == "utility"
    assert uniform.source.rng is context.rng and uniform.source.anchoring == context.conf.anchoring
    assert not any(method.uses_model for method in (classic, gain, random_frontier, vacuum, uniform))


def test_unknown_method_or_goal_rule_is_an_input_error_listing_the_valid_ones():
    with pytest.raises(InputError, match="valid: .*classic.*gain-distance.*vacuum"):
        make_method("no-such-method", MethodContext(load_config("explore"), load_config("sim")))
    with pytest.raises(InputError, match="goal rule"):
        Method("mine", None, "closest")
    with pytest.raises(InputError, match="no frontier source"):
        Method("mine", None, "utility")
    with pytest.raises(InputError, match="vacuum goal rule and a method's own moves"):
        Method("mine", None, "vacuum")


def test_the_vacuum_goes_straight_on_until_blocked_then_turns_90_to_270_degrees():
    from frontiernet.exploration.motion import Motion, wrap_angle, yaw_of
    from frontiernet.exploration.vacuum import VacuumMoves
    from frontiernet.geometry import pose_from_heading

    motion = Motion(explore_section("motion"), 1.2)
    moves, T = VacuumMoves(np.random.default_rng(0)), pose_from_heading(1.0, 2.0, 1.2, 0.3)
    ahead = moves.next_pose(T, motion, lambda T, target: ("ok", None))
    np.testing.assert_allclose(ahead[:2, 3], [1.0 + motion.max_translation * np.cos(0.3),
                                              2.0 + motion.max_translation * np.sin(0.3)])
    assert yaw_of(ahead) == pytest.approx(0.3)
    turned = moves.next_pose(T, motion, lambda T, target: ("look", target[:2, 3]))  # only "ok" moves on
    np.testing.assert_allclose(turned[:3, 3], T[:3, 3])  # a turn on the spot, towards the new heading
    assert np.pi / 2 <= abs(wrap_angle(moves.yaw - 0.3)) and abs(wrap_angle(moves.yaw - 0.3)) <= np.pi
    first = moves.yaw
    moves.bumped(turned)  # a collision turns it again
    assert abs(wrap_angle(moves.yaw - first)) >= np.pi / 2


def frontier(frontier_id: int, xy, gain: float):
    return SimpleNamespace(id=frontier_id, gain_m3=gain, position=np.array([*xy, 1.2]))


@pytest.mark.parametrize("goal, best", [("utility", 1), ("nearest", 0)])
def test_goal_rules_rank_by_gain_over_distance_or_by_distance_alone(goal, best):
    planner = FrontierPlanner(explore_section("planner"), goal=goal)
    near, far = frontier(0, (1, 0), 2.0), frontier(1, (4, 0), 20.0)
    scores = [planner.score(near, 1.0), planner.score(far, 4.0)]
    assert int(np.argmax(scores)) == best


def test_the_random_goal_rule_is_seeded_and_fixed_per_frontier():
    first = FrontierPlanner(explore_section("planner"), goal="random", seed=3)
    again = FrontierPlanner(explore_section("planner"), goal="random", seed=3)
    frontiers = [frontier(i, (i, 0), 5.0) for i in range(6)]
    scores = [first.score(f, 1.0 + f.id) for f in frontiers]
    assert scores == [again.score(f, 0.5) for f in frontiers]  # distance plays no part
    assert scores == [first.score(f, 9.0) for f in frontiers]  # a frontier keeps its draw
    assert len(set(scores)) == 6


def test_fresh_proposals_replace_a_frontier_instead_of_averaging():
    tracker = FrontierTracker(explore_section("tracking"))
    seen = SimpleNamespace(position=np.array([1.0, 1.0, 1.2]), direction=np.array([1.0, 0, 0]), gain_m3=10.0)
    moved = SimpleNamespace(position=np.array([1.4, 1.0, 1.2]), direction=np.array([1.0, 0, 0]), gain_m3=4.0)
    [first] = tracker.add([seen], 0, 0, average=False)
    assert tracker.add([moved], 1, 1, average=False) == [first]
    kept = tracker.get(first)
    assert kept.position.tolist() == [1.4, 1.0, 1.2] and kept.predicted_gain_m3 == 4.0 and kept.observations == 2


@pytest.mark.slow
@pytest.mark.parametrize("method", BASELINES)
def test_baselines_explore_the_two_room_plan_without_collisions(plan_spec, tmp_path, method):
    metrics = run_method(plan_spec, tmp_path / method, method, 60)
    assert metrics["method"] == method and metrics["model"] is None and metrics["collisions"] == 0
    assert metrics["coverage"] > metrics["coverage_per_step"][0] and metrics["path_length_m"] > 0.5
    # GLEAM's metrics come with every run: surface coverage grows, its AUC lies below its end value
    surface = np.array(metrics["surface_coverage_per_step"])
    assert np.all(np.diff(surface) >= 0) and 0 < surface[-1] <= 1
    assert surface[-1] == pytest.approx(metrics["surface_coverage"], abs=1e-5)
    assert 0 < metrics["surface_auc"] <= metrics["surface_coverage"]
    assert 0 < metrics["chamfer_m"] < 1.0 and 0 < metrics["completeness"] <= 1
    if method != "vacuum":
        assert metrics["goals"] >= 1 and metrics["coverage"] > 0.5  # it has looked into the second room
    else:
        assert metrics["goals"] == 0 and metrics["steps"] == 60  # no goals, it runs until the budget ends


@pytest.mark.parametrize("method, every", [("discontinuity-uniform", 4), ("classic", 4), ("discontinuity-uniform", 1)])
def test_an_image_method_observes_every_n_frames_a_map_method_every_frame(plan_spec, tmp_path, monkeypatch,
                                                                          method, every):
    calls = []
    propose = Method.propose

    def counted(self, frame, depth, stopwatch):
        calls.append(len(calls))
        return propose(self, frame, depth, stopwatch)

    monkeypatch.setattr(Method, "propose", counted)
    metrics = run_method(plan_spec, tmp_path / "run", method, 20, f"tracking.observe_every_steps={every}")
    frames = len(metrics["coverage_per_step"])  # one per sensed frame, the first included
    expected = frames if method == "classic" else -(-frames // every)
    assert len(calls) == expected and metrics["collisions"] == 0


@pytest.mark.parametrize("method, merges", [("discontinuity-uniform", True), ("classic", False)])
def test_the_cluster_merge_runs_in_the_loop_on_image_frontiers_only(plan_spec, tmp_path, monkeypatch, method,
                                                                    merges):
    """tracking.merge=clusters (the public code's merge, FrontierTracker.merge_clusters, tested in
    test_tracking) runs on an image method's frontiers every frame; a map method's frontiers are
    recomputed from the map each frame and never merged."""
    from frontiernet.frontiers import FrontierTracker

    modes = []
    merge = FrontierTracker.merge_clusters

    def recorded(self):
        modes.append(self.conf["merge"])
        return merge(self)

    monkeypatch.setattr(FrontierTracker, "merge_clusters", recorded)
    metrics = run_method(plan_spec, tmp_path / "run", method, 20, "tracking.merge=clusters")
    frames = len(metrics["coverage_per_step"])
    assert modes == (["clusters"] * frames if merges else []) and metrics["collisions"] == 0


def test_observe_every_steps_below_one_is_refused(plan_spec, tmp_path):
    stream = io.StringIO()
    with contextlib.redirect_stdout(stream), contextlib.redirect_stderr(stream):
        code = main(["explore", "--scene", plan_spec, "--method", "classic", "--max-steps", "3", "--no-video",
                     "--out", str(tmp_path / "run"), "tracking.observe_every_steps=0"])
    assert code == 2 and "tracking.observe_every_steps must be an integer >= 1, got 0" in stream.getvalue()


def make_my_planner(context):
    """docs/exploration.md's plugin example: map frontiers scored by visible unknown volume, nearest first."""
    return Method("my-planner", MapSource("unknown_volume", context.map, context.conf), goal="nearest",
                  fresh_frontiers=True)


@pytest.mark.slow
def test_a_method_registered_under_the_entry_point_group_explores_and_is_benchmarked(plan_spec, tmp_path,
                                                                                      monkeypatch):
    import importlib.metadata

    real = importlib.metadata.entry_points
    plugin = importlib.metadata.EntryPoint("my-planner", "test_methods:make_my_planner", "frontiernet.methods")
    monkeypatch.setattr(importlib.metadata, "entry_points",
                        lambda **kw: [plugin] if kw.get("group") == "frontiernet.methods" else real(**kw))
    assert "my-planner" in method_names()
    metrics = run_method(plan_spec, tmp_path / "mine", "my-planner", 50, "--start", "2,1.5,1.2,0")
    assert metrics["method"] == "my-planner" and metrics["collisions"] == 0 and metrics["goals"] >= 1
    stream = io.StringIO()
    with contextlib.redirect_stdout(stream), contextlib.redirect_stderr(stream):
        code = main(["bench", "--scenes", plan_spec, "--methods", "my-planner", "--starts", "1", "--repeats", "1",
                     "--max-steps", "20", "--out", str(tmp_path / "bench")])
    assert code == 0 and "| my-planner |" in stream.getvalue(), stream.getvalue()


def test_only_draw_free_methods_on_unseeded_depth_repeat_identically():
    from frontiernet.exploration.methods import repeats_identically

    assert repeats_identically("classic", "ground_truth") and repeats_identically("gain-distance", "ground_truth")
    assert not repeats_identically("classic", "emulated")  # seeded depth noise
    for method in ("frontiernet", "oracle", "random-frontier", "vacuum", "df-uniform"):
        assert not repeats_identically(method, "ground_truth")
    assert not repeats_identically("classic", "someone's plugin depth")


@pytest.mark.slow
def test_the_run_seed_reaches_the_explorers_draws_and_nothing_else(plan_spec, tmp_path):
    """--seed picks vacuum's turns (a repeat of a benchmark is a new draw), while a method without
    draws (classic, ground-truth depth) repeats its run exactly from the same start."""

    def path(method, seed):
        out = tmp_path / f"{method}{seed}"
        metrics = run_method(plan_spec, out, method, 90, "--seed", str(seed), "--start", "2,1.5,1.2,0")
        return metrics, np.asarray(json.loads((out / "trajectory.json").read_text())["T_world_cam"])

    (first, T_first), (second, T_second) = path("vacuum", 0), path("vacuum", 1)
    assert first["seed"] == 0 and second["seed"] == 1
    assert not np.allclose(T_first, T_second)
    (_, T_classic), (_, T_again) = path("classic", 0), path("classic", 1)
    np.testing.assert_array_equal(T_classic, T_again)


@pytest.mark.slow
def test_map_frontiers_are_the_current_maps_frontiers_only(plan_spec, tmp_path):
    metrics = run_method(plan_spec, tmp_path / "classic", "classic", 40)
    frontiers = json.loads((tmp_path / "classic" / "frontiers.json").read_text())
    assert metrics["frontiers_removed"].get("stale", 0) > 0  # frontiers that the map no longer has are gone
    assert all(f["predicted_gain_m3"] == explore_section("map_frontiers")["uniform_gain_m3"]
               for f in frontiers["frontiers"])


def test_the_methods_of_map_frontier_regions_are_those_whose_runs_read_bury_visited(two_room_scene, two_room_voxels):
    # tracking.bury_visited acts on map frontier regions (Method.map_regions); --redo-changed redoes the runs of the
    # methods frontiernet.benchmark.changes lists for it, so the two must name the same methods
    from frontiernet.benchmark.changes import REGION_METHODS
    from frontiernet.exploration.methods import MAP_METHODS

    context = MethodContext(load_config("explore"), load_config("sim"), scene=two_room_scene, voxels=two_room_voxels)
    regions = {name for name in ("classic", "gain-distance", "random-frontier", "vacuum", "nbvp", "omniscient", "seer",
                                 "mapex", "discontinuity-uniform") if make_method(name, context).map_regions}
    assert regions == set(MAP_METHODS) | REGION_METHODS == {"classic", "gain-distance", "random-frontier", "mapex"}

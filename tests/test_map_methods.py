"""The methods that explore with a map predictor (issue 56 items 3 and 4): ``seer`` (views around the
map's frontier clusters, gain through SEER's predicted 3D crop) and ``mapex`` (map frontiers by the
ensemble variance in sight of the predicted map, per metre). The predictors here are tiny and
randomly initialised: the tests check the methods' plumbing and scoring, not a predictor's quality."""

from __future__ import annotations

import contextlib
import io
import json
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from frontiernet.cli.main import main
from frontiernet.config import load_config
from frontiernet.exploration.mapex import MapexSource, visible_cells
from frontiernet.exploration.methods import method_names, uses_model
from frontiernet.exploration.seer import Crop, SeerSource
from frontiernet.frontiers.anchoring import FrontierObservation
from frontiernet.geometry import poses_from_headings
from frontiernet.mapping import OccupancyMap
from frontiernet.mapprediction import save_predictor, shipped_predictor_path
from frontiernet.mapprediction.networks import NetworkSettings, PredictorSpec

CONF = load_config("explore")
CAMERA = load_config("sim").camera


@pytest.fixture(scope="module")
def predictors(tmp_path_factory) -> dict:
    """A tiny random predictor file of each kind (SEER's 80 x 80 x 24 crop, MapEx's 3 members)."""
    folder = tmp_path_factory.mktemp("predictors")
    torch.manual_seed(0)
    specs = {"seer": PredictorSpec("seer", NetworkSettings((2, 4), (1,), 3), 1, extra={"occupied_threshold": 0.65}),
             "mapex": PredictorSpec("mapex", NetworkSettings((4, 4), (1,), 2), 3, extra={"occupied_threshold": 0.5})}
    return {kind: save_predictor(folder / f"{kind}.safetensors", spec, spec.build().state_dict())
            for kind, spec in specs.items()}


def explore(spec: str, out, method: str, steps: int, *options: str) -> tuple[int, str]:
    stream = io.StringIO()
    with contextlib.redirect_stdout(stream), contextlib.redirect_stderr(stream):
        code = main(["explore", "--scene", spec, "--method", method, "--max-steps", str(steps), "--no-video",
                     "--out", str(out), *options])
    return code, stream.getvalue()


def empty_map(size=(6.0, 4.0, 2.4)) -> OccupancyMap:
    return OccupancyMap(np.zeros(3), tuple(int(round(n / 0.1)) for n in size), CONF.map)


# --------------------------------------------------------------------------- in the loop

def test_both_are_registered_methods_that_take_a_predictor_file():
    assert {"seer", "mapex"} <= set(method_names())
    assert uses_model("seer") and uses_model("mapex")  # --model names the predictor file


@pytest.mark.parametrize("method", ["seer", "mapex"])
def test_the_method_explores_the_two_room_plan_with_its_predictor(plan_spec, predictors, tmp_path, method):
    code, log = explore(plan_spec, tmp_path / method, method, 50, "--model", str(predictors[method]))
    assert code == 0, log
    metrics = json.loads((tmp_path / method / "metrics.json").read_text())
    assert metrics["method"] == method and metrics["model"] == str(predictors[method])
    assert metrics["collisions"] == 0 and metrics["goals"] >= 1 and metrics["path_length_m"] > 0.3
    assert metrics["coverage"] > metrics["coverage_per_step"][0]
    assert metrics["timing"]["mean_ms"]["perception"] > 0  # the prediction ran (timed as perception)


def test_bench_explore_times_a_predictor_method_with_its_model_file(plan_spec, predictors, capsys):
    """``bench explore --method mapex --model P`` (or ``mapex.predictor=P``): the predictor given as to
    ``explore``; its prediction is the step's ``perception`` stage (no shipped predictor is needed)."""
    assert main(["bench", "explore", "--scene", plan_spec, "--method", "mapex", "--model", str(predictors["mapex"]),
                 "--steps", "3", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["method"] == "mapex" and result["steps"] == 3 and result["mean_ms"]["perception"] > 0
    # frontiernet-mapex's predictor is a config key (--model is its FrontierNet model), set as explore sets it
    assert main(["bench", "explore", "--scene", plan_spec, "--method", "frontiernet-mapex", "--steps", "2", "--json",
                 f"mapex.predictor={predictors['mapex']}"]) == 0
    assert json.loads(capsys.readouterr().out)["method"] == "frontiernet-mapex"


def test_the_predictor_file_comes_from_the_config_key_too(plan_spec, predictors, tmp_path):
    code, log = explore(plan_spec, tmp_path / "run", "mapex", 3, f"mapex.predictor={predictors['mapex']}")
    assert code == 0, log


@pytest.mark.parametrize("method", ["seer", "mapex"])
def test_a_missing_or_wrong_predictor_is_one_line_and_exit_2_before_the_scene_loads(predictors, tmp_path, capsys,
                                                                                    method):
    other = predictors["mapex" if method == "seer" else "seer"]
    cases = [(["--model", str(tmp_path / "none.safetensors")], "none.safetensors: predictor file not found"),
             (["--model", str(other)], f"{other}: a {'mapex' if method == 'seer' else 'seer'} predictor, expected a "
                                       f"{method} one"),
             ([f"{method}.predictor={tmp_path / 'gone.safetensors'}"], "gone.safetensors: predictor file not found")]
    if not shipped_predictor_path(method).is_file():
        cases.append(([], f"no {method} predictor is shipped yet"))
    for options, message in cases:
        # a scene that does not exist: the predictor is checked first, so the error names it, not the scene
        code = main(["explore", "--scene", "floorplan:/no/such/plan.png", "--method", method, "--no-video",
                     "--out", str(tmp_path / "out"), *options])
        err = capsys.readouterr().err.strip()
        assert code == 2 and "\n" not in err and "Traceback" not in err and message in err, err
        assert not (tmp_path / "out").exists()  # nothing written


def test_show_prediction_draws_the_predicted_map_beside_the_robots_own(plan_spec, predictors, tmp_path, capsys):
    """``explore --show-prediction``: a third panel in exploration.mp4, as wide as the map's; a predictor
    of the wrong kind, or no video to draw into, is one line and exit 2 with nothing written."""
    import cv2

    frames = {}
    for name, options in (("plain", []), ("shown", ["--show-prediction", str(predictors["mapex"])])):
        code = main(["explore", "--scene", plan_spec, "--method", "classic", "--max-steps", "3",
                     "--out", str(tmp_path / name), *options])
        assert code == 0, capsys.readouterr().err
        ok, frames[name] = cv2.VideoCapture(str(tmp_path / name / "exploration.mp4")).read()
        assert ok
    map_width = frames["plain"].shape[1] - 480
    assert frames["shown"].shape == (480, 480 + 2 * map_width, 3)
    difference = np.abs(frames["shown"][:, :480 + map_width].astype(int) - frames["plain"]).mean()
    assert difference < 3  # the same run's first two panels (the video is lossy)
    for options, message in ((["--show-prediction", str(predictors["seer"])], "a seer predictor, expected a mapex"),
                             (["--show-prediction", str(predictors["mapex"]), "--no-video"], "leave out --no-video")):
        code = main(["explore", "--scene", plan_spec, "--method", "classic", "--out", str(tmp_path / "refused"),
                     *options])
        err = capsys.readouterr().err.strip()
        assert code == 2 and "\n" not in err and message in err, err
        assert not (tmp_path / "refused").exists()


@pytest.mark.parametrize("method", ["mapex", "frontiernet-mapex"])
def test_show_prediction_alone_draws_the_methods_own_prediction_and_changes_nothing_of_the_run(
        plan_spec, predictors, tmp_path, method, capsys):
    """With a method that predicts the map itself, ``--show-prediction`` alone reads its prediction (mapex's
    from ``--model``; no second predictor is loaded, so a missing shipped one is no error): the same run."""
    chosen = ["--model", str(predictors["mapex"])] if method == "mapex" else [f"mapex.predictor={predictors['mapex']}"]
    runs = {}
    for name, options in (("plain", ["--no-video"]), ("shown", ["--show-prediction"])):
        code = main(["explore", "--scene", plan_spec, "--method", method, "--max-steps", "8",
                     "--out", str(tmp_path / name), *chosen, *options])
        assert code == 0, capsys.readouterr().err
        runs[name] = json.loads((tmp_path / name / "metrics.json").read_text())
    assert runs["shown"]["coverage_per_step"] == runs["plain"]["coverage_per_step"]
    assert (tmp_path / "shown" / "exploration.mp4").stat().st_size > 0


def test_the_predicted_panel_colours_unknown_cells_by_their_predicted_occupancy():
    from frontiernet.exploration.drawing import FREE, OCCUPIED, PREDICTED_FREE, PREDICTED_OCCUPIED, TopDown

    top = TopDown(np.zeros(2), (4, 2), 0.1, height_px=2)  # one pixel per cell
    free, occupied = np.zeros((4, 2), bool), np.zeros((4, 2), bool)
    free[0, :], occupied[1, :] = True, True
    probability = np.array([[0.0, 0.0], [1.0, 1.0], [0.0, 0.0], [1.0, 1.0]])
    image = top.prediction(free, occupied, probability)  # rows: +y up, columns: +x
    assert image.shape == (2, 4, 3)
    assert [tuple(image[0, i]) for i in range(4)] == [FREE, OCCUPIED, PREDICTED_FREE, PREDICTED_OCCUPIED]
    half = top.prediction(np.zeros((4, 2), bool), np.zeros((4, 2), bool), np.full((4, 2), 0.5))[0, 0]
    assert np.allclose(half, (np.add(PREDICTED_FREE, PREDICTED_OCCUPIED)) / 2, atol=1)


# --------------------------------------------------------------------------- MapEx's score

def test_rays_stop_before_a_cell_predicted_occupied():
    mean = np.zeros((21, 21), np.float32)
    mean[15, :] = 0.85  # a predicted wall 5 cells in +x from the centre
    def seen_mask(probability):
        rows, cols = visible_cells(probability, np.array([10, 10]), 64, 8.0, 0.8)
        assert len(set(zip(rows.tolist(), cols.tolist()))) == len(rows)  # each cell once
        mask = np.zeros(probability.shape, bool)
        mask[rows, cols] = True
        return mask

    seen = seen_mask(mean)
    assert seen[10, 10] and seen[14, 10] and not seen[15, 10] and not seen[17, 10]
    assert seen[10, 17] and seen[3, 10] and not seen[10, 19]  # the other directions reach their range, no farther
    assert seen_mask(np.where(mean > 0, 0.75, 0.0))[17, 10]  # below 0.8: seen


def test_mapex_ranks_a_frontier_with_uncertain_unknown_space_in_sight_above_one_without():
    source = MapexSource(SimpleNamespace(spec=SimpleNamespace(band_m=0.3)), empty_map(), CONF)
    mean = np.full((60, 40), 0.5, np.float32)  # unknown, predicted neither free nor occupied
    variance = np.zeros((60, 40), np.float32)
    variance[45:, 25:] = 0.2  # the members disagree in the north-east ...
    variance[12:20, :] = 0.2  # ... and on a band 1.2 m east of the west frontier ...
    walled = mean.copy()
    walled[10, :] = 0.9  # ... which a predicted wall hides from it
    west, east = (FrontierObservation(np.array([x, y, 1.2]), np.array([1.0, 0, 0]), 1.0, 10, np.full(2, np.nan),
                                      np.eye(4)) for x, y in ((0.55, 0.55), (5.55, 3.55)))
    positions = np.array([west.position[:2], east.position[:2]])
    assert source.values(positions, mean, variance)[0] > 1.0  # in sight without the wall
    values = source.values(positions, walled, variance)
    assert values[0] == 0.0 and values[1] > 10 * 0.2
    scored = source.scored([west, east], walled, variance)
    assert scored[1].gain_m3 > scored[0].gain_m3 >= CONF.tracking.min_gain_m3  # none dropped; ranked by variance
    assert scored[1].gain_m3 / scored[0].gain_m3 == pytest.approx((values[1] + 1e-6) / 1e-6)


def test_mapex_keeps_a_frontiers_value_until_the_prediction_changes_within_its_rays_range(monkeypatch):
    import frontiernet.exploration.mapex as mapex

    source = MapexSource(SimpleNamespace(spec=SimpleNamespace(band_m=0.3)), empty_map(), CONF)
    mean, variance = np.full((200, 40), 0.5, np.float32), np.full((200, 40), 0.1, np.float32)
    positions = np.array([[0.55, 0.55], [15.55, 0.55]])  # 15 m apart: each beyond the other's 3.5 m rays
    first = source.values(positions, mean, variance)
    rays = []
    monkeypatch.setattr(mapex, "visible_cells", lambda *a, **k: rays.append(a[1].tolist()) or visible_cells(*a, **k))
    assert np.array_equal(source.values(positions, mean, variance), first) and rays == []  # nothing changed
    variance[150:160, :] = 0.3  # the members now disagree near the second frontier only
    again = source.values(positions, mean, variance)
    assert rays == [[155, 5]] and again[0] == first[0] and again[1] > first[1]
    fresh = MapexSource(SimpleNamespace(spec=SimpleNamespace(band_m=0.3)), empty_map(), CONF)
    assert np.array_equal(fresh.values(positions, mean, variance), again)


@pytest.mark.parametrize("method", ["mapex", "seer"])
def test_before_a_stop_the_map_predicting_methods_propose_their_small_regions_too(method):
    """As the map methods (map_frontiers.min_cells_before_stop): mapex stopped after its start turn on a KTH plan
    with emulated depth, the door a region under its min_cells; once a run would stop, the regions down to the
    key's size are proposed, once; with the key null the run stops as before."""
    def source(**changes):
        conf = OmegaConf.merge(CONF, {"map_frontiers": changes})
        if method == "mapex":
            return MapexSource(SimpleNamespace(spec=SimpleNamespace(band_m=0.3)), empty_map(), conf)
        predictor = SimpleNamespace(occupied_threshold=0.65, spec=SimpleNamespace(crop_shape=(80, 80, 24)))
        return SeerSource(predictor, empty_map(), conf, CAMERA)

    def min_cells(of) -> int:
        return of.frontier_conf.map_frontiers.min_cells if method == "mapex" else of.min_cells

    widening = source(min_cells_before_stop=1)
    assert min_cells(widening) > 1
    assert widening.widen() and min_cells(widening) == 1 and not widening.widen()
    off = source(min_cells_before_stop=None)
    before = min_cells(off)
    assert not off.widen() and min_cells(off) == before


def test_mapex_predicts_again_only_once_the_map_has_learnt_enough():
    calls = []

    def predict(states, voxel_size):
        calls.append(states.shape)
        return np.full(states.shape, 0.3, np.float32), np.full(states.shape, 0.1, np.float32)

    predictor = SimpleNamespace(spec=SimpleNamespace(band_m=0.3), predict_topdown_states=predict)
    occupancy = empty_map((12.0, 10.0, 2.4))
    source = MapexSource(predictor, occupancy, OmegaConf.merge(CONF, {"mapex": {"repredict_new_cells": 50}}))
    states = np.zeros((120, 100), np.int8)
    states[20:25, 20:25] = 1  # 25 known cells: the window is them and the 3.5 m visibility range around
    mean, variance = source.topdown(states, predict=False)  # a reader (the video) before any prediction
    assert calls == [] and mean[22, 22] == 0.0 and mean[30, 30] == 0.5 and not variance.any()
    mean, variance = source.prediction(states)
    assert calls == [(20 + 5 + 36, 20 + 5 + 36)]
    assert mean[22, 22] == 0.0 and variance[22, 22] == 0.0 and mean[30, 30] == pytest.approx(0.3)
    assert mean[100, 90] == 0.5 and variance[100, 90] == 0.0  # out of reach of every ray: not predicted
    states[25:30, 20:25] = 1  # 25 more, below 50: the cached prediction, read with the new known cells
    mean, variance = source.prediction(states)
    assert len(calls) == 1 and mean[27, 22] == 0.0 and variance[27, 22] == 0.0
    states[30:40, 20:25] = 1  # 75 since the prediction: predicted again, by the method, not by a reader
    assert source.topdown(states, predict=False)[0][35, 22] == 0.0 and len(calls) == 1
    source.prediction(states)
    assert len(calls) == 2


def test_mapex_predicts_only_where_the_map_changed_as_a_prediction_of_the_whole_map_would(tmp_path):
    """The cached prediction is redone only around the changed cells (their box grown by the rays' range
    and the network's reach), and every cell the rays can read equals a prediction of the whole map."""
    from frontiernet.exploration.predicted import TopdownPrediction
    from frontiernet.mapprediction import load_predictor

    torch.manual_seed(1)
    spec = PredictorSpec("mapex", NetworkSettings(in_channels=2), 3)  # the shipped architecture, random weights
    predictor = load_predictor(save_predictor(tmp_path / "m.safetensors", spec, spec.build().state_dict()))
    radius = predictor.receptive_radius
    probe = np.zeros((1, 2, 128, 128), np.float32)
    poked = probe.copy()
    poked[0, 0, 64, 64] = 1.0
    moved = np.abs(predictor._run(poked) - predictor._run(probe))[:, 0].max(axis=0) > 1e-6
    rows, cols = np.nonzero(moved)  # an input cell reaches no output farther than the bound
    assert moved[64, 64] and np.abs(rows - 64).max() <= radius and np.abs(cols - 64).max() <= radius

    shapes = []
    record = predictor.predict_topdown_states
    predictor.predict_topdown_states = lambda states, cell: shapes.append(states.shape) or record(states, cell)
    topdown = TopdownPrediction(predictor, 0.1, 35.0, 1)
    states = np.zeros((300, 240), np.int8)  # unknown (0)
    states[20:60, 20:50] = 1  # a room seen, free (1), its walls occupied (2)
    states[20:60, 20] = states[20, 20:50] = 2
    topdown(states)
    states[60:80, 30:40] = 1  # the robot maps a corridor on
    mean, variance = topdown(states)
    assert shapes[1][0] < states.shape[0] and shapes[1][1] < states.shape[1]  # not the whole map
    whole_mean, whole_variance = record(states, 0.1)
    from scipy import ndimage
    in_range = ndimage.binary_dilation(states > 0, np.ones((73, 73), bool))  # within 36 cells of a known one
    assert np.allclose(mean[in_range], whole_mean[in_range], atol=1e-5)
    assert np.allclose(variance[in_range], whole_variance[in_range], atol=1e-6)


# --------------------------------------------------------------------------- SEER's gain and views

def seer_source(occupancy, **changes) -> SeerSource:
    predictor = SimpleNamespace(occupied_threshold=0.65, spec=SimpleNamespace(crop_shape=(80, 80, 24)))
    return SeerSource(predictor, occupancy, OmegaConf.merge(CONF, {"seer": changes}), CAMERA)


def test_seer_rays_stop_at_predicted_occupied_voxels_of_unknown_space():
    occupancy = empty_map()
    source = seer_source(occupancy)
    pose = poses_from_headings(np.array([[1.0, 2.0, 1.2]]), np.array([0.0]), np.radians(-5.0))
    wall = np.zeros((80, 80, 24), bool)
    wall[20, :, :] = True  # x = 2.0 m: 1 m ahead of the view
    crop = Crop(np.array([0, -20, 0]), np.array([3.0, 2.0]), wall, 0)
    open_gain, walled = source.gains(pose, None)[0], source.gains(pose, crop)[0]
    assert open_gain > 10.0 and 0 < walled < 0.1 * open_gain  # a 1 m deep frustum, not a 3.5 m one
    behind = np.zeros_like(wall)
    behind[5, :, :] = True  # x = 0.5 m, behind the view
    behind_crop = Crop(np.array([0, -20, 0]), np.array([3.0, 2.0]), behind, 0)
    assert source.gains(pose, behind_crop)[0] == pytest.approx(open_gain)


def test_seer_proposes_one_view_per_cluster_on_its_circles_away_from_the_robot():
    occupancy = empty_map()
    K = np.array([[40.0, 0, 31.5], [0, 40.0, 31.5], [0, 0, 1]])
    T = np.eye(4)
    T[:3, :3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]  # level, looking along +x
    T[:3, 3] = [0.5, 2.0, 1.2]
    occupancy.integrate(np.full((64, 64), np.nan, np.float32), K, T)  # nothing within range: free up to 3.5 m
    source = seer_source(occupancy)
    clusters = source.clusters(1.2)
    assert clusters
    views = source.views(clusters, [None] * len(clusters), poses_from_headings(np.array([[0.5, 2.0, 1.2]]),
                                                                               np.array([0.0]), 0.0)[0])
    assert views and all(v.gain_m3 >= CONF.tracking.min_gain_m3 for v in views)
    centres = [c.mean(axis=0) for c in clusters]
    for view in views:
        assert np.hypot(*(view.position[:2] - [0.5, 2.0])) >= 0.75
        assert any(0.5 - 1e-6 <= np.hypot(*(view.position[:2] - c)) <= 1.2 + 1e-6 for c in centres)
    # the views' gains are kept while the map does not change near them: the next frame integrates none
    T_robot = poses_from_headings(np.array([[0.5, 2.0, 1.2]]), np.array([0.0]), 0.0)[0]
    integrated = []
    source.gains = lambda poses, crop, gains=source.gains: integrated.append(len(poses)) or gains(poses, crop)
    again = source.views(source.clusters(1.2), [None] * len(clusters), T_robot)
    assert [(v.position.tolist(), v.gain_m3) for v in again] == [(v.position.tolist(), v.gain_m3) for v in views]
    assert integrated == []
    T[:3, 3] = [1.0, 2.0, 1.2]
    occupancy.integrate(np.full((64, 64), 2.0, np.float32), K, T)  # a wall mapped 2 m ahead: gains change
    again = source.views(source.clusters(1.2), [None] * len(source.clusters(1.2)), T_robot)
    assert integrated and again  # integrated afresh, not read from before the change
    fresh = seer_source(occupancy).views(source.clusters(1.2), [None] * len(source.clusters(1.2)), T_robot)
    assert [(v.position.tolist(), v.gain_m3) for v in again] == [(v.position.tolist(), v.gain_m3) for v in fresh]


def test_seer_scores_at_most_its_budget_of_clusters_a_step_and_keeps_the_others_last_views():
    """``seer.max_scored_clusters_per_step``: a step's views cost at most that many clusters' rings (issue 55:
    the step cost of a large floor), nearest first; a cluster beyond the budget keeps its last view."""
    occupancy = empty_map()
    K = np.array([[40.0, 0, 31.5], [0, 40.0, 31.5], [0, 0, 1]])
    T = np.eye(4)
    T[:3, :3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]  # level, looking along +x
    T[:3, 3] = [0.5, 2.0, 1.2]
    occupancy.integrate(np.full((64, 64), np.nan, np.float32), K, T)
    T_robot = poses_from_headings(np.array([[0.5, 2.0, 1.2]]), np.array([0.0]), 0.0)[0]
    every = seer_source(occupancy)
    clusters = every.clusters(1.2)
    assert len(clusters) >= 3
    unlimited = every.views(clusters, [None] * len(clusters), T_robot)

    source = seer_source(occupancy, max_scored_clusters_per_step=1)
    scored = []
    source.best_view = lambda cells, *args, best=source.best_view: scored.append(len(cells)) or best(cells, *args)
    for frame in range(len(clusters)):  # one cluster more a frame, nearest first, until every one has a view
        views = source.views(clusters, [None] * len(clusters), T_robot)
        assert len(views) == min(frame + 1, len(unlimited))
    distances = [np.hypot(*(c.mean(axis=0) - [0.5, 2.0])) for c in clusters]
    assert scored[0] == len(clusters[int(np.argmin(distances))])
    assert sorted((tuple(v.position), v.gain_m3) for v in views) == \
        sorted((tuple(v.position), v.gain_m3) for v in unlimited)  # the same views once all are scored
    T[:3, 3] = [1.0, 2.0, 1.2]
    occupancy.integrate(np.full((64, 64), 2.0, np.float32), K, T)  # a wall mapped: every ring's gains are stale
    scored.clear()
    again = source.views(source.clusters(1.2), [None] * len(source.clusters(1.2)), T_robot)
    assert len(scored) == 1 and len(again) > 1  # one scored anew, the others proposed from their last views


@pytest.mark.parametrize("method", ["seer", "mapex"])
def test_an_exploration_never_calls_back_into_a_library_file_it_came_from(plan_spec, predictors, tmp_path, method):
    from test_walks import returns_during  # docs/design.md, "Walk (a)" and "Walk (b)"

    def run() -> None:
        code, log = explore(plan_spec, tmp_path / "run", method, 4, "--model", str(predictors[method]))
        assert code == 0, log

    returns = returns_during(run)
    assert returns == {}, "\n".join(f"{where}: {chain}" for where, chain in returns.items())


# --------------------------------------------------------------------------- frontiernet-mapex

def test_frontiernet_mapex_with_no_weight_is_frontiernet_step_for_step(plan_spec, predictors, tmp_path):
    """``frontiernet-mapex`` is FrontierNet with the predicted space blended into its gains: at
    ``frontiernet_mapex.weight=0`` the same run as ``frontiernet``; at the default it explores too."""
    runs = {}
    for name, method, options in (("plain", "frontiernet", []),
                                  ("w0", "frontiernet-mapex", ["frontiernet_mapex.weight=0"]),
                                  ("blend", "frontiernet-mapex", [])):
        code, log = explore(plan_spec, tmp_path / name, method, 12, f"mapex.predictor={predictors['mapex']}", *options)
        assert code == 0, log
        runs[name] = json.loads((tmp_path / name / "metrics.json").read_text())
    assert runs["w0"]["coverage_per_step"] == runs["plain"]["coverage_per_step"]
    assert runs["blend"]["method"] == "frontiernet-mapex" and runs["blend"]["collisions"] == 0
    assert runs["blend"]["coverage"] > runs["blend"]["coverage_per_step"][0]


def test_the_predicted_space_counts_free_unknown_cells_in_view_up_to_a_predicted_wall():
    from frontiernet.exploration.predicted_space import PredictedSpaceGain
    from frontiernet.mapping.occupancy import FREE, UNKNOWN

    occupancy = empty_map((6.0, 4.0, 2.4))
    prediction = SimpleNamespace(range_cells=35.0)
    source = PredictedSpaceGain(None, prediction, occupancy, CONF, np.radians(90.0))
    states = np.full((60, 40), UNKNOWN, np.int8)
    states[:10] = FREE  # the robot knows the first metre
    mean = np.where(states == FREE, 0.0, 0.2).astype(np.float32)  # the rest: predicted free (p = 0.2)
    east, west = np.array([[1.0, 0.0]]), np.array([[-1.0, 0.0]])
    at = np.array([[0.95, 2.05]])
    ahead = source.predicted_volume(at, east, mean, states)[0]
    cell_m3 = 0.1 * 0.1 * float(CONF.frontiernet_mapex.column_height_m)
    i, j = np.meshgrid(np.arange(60) + 0.5 - 9.5, np.arange(40) + 0.5 - 20.5, indexing="ij")  # from the start cell
    wedge = (np.hypot(i, j) <= 35) & (np.abs(np.arctan2(j, i)) <= np.radians(45)) & (states == UNKNOWN)
    assert ahead == pytest.approx(wedge.sum() * 0.8 * cell_m3, rel=0.1)  # the 90 deg wedge of 3.5 m, unknown part...
    assert source.predicted_volume(at, west, mean, states)[0] == 0.0  # ... and behind it only known cells
    walled = mean.copy()
    walled[15, :] = 0.9  # a predicted wall 0.5 m ahead
    assert source.predicted_volume(at, east, walled, states)[0] < 0.1 * ahead


def test_frontiernet_mapex_without_its_predictor_is_one_line_and_exit_2_before_the_scene_loads(tmp_path, capsys):
    code = main(["explore", "--scene", "floorplan:/no/such/plan.png", "--method", "frontiernet-mapex", "--no-video",
                 "--out", str(tmp_path / "out"), f"mapex.predictor={tmp_path / 'gone.safetensors'}"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err and "gone.safetensors: predictor file not found" in err, err
    assert not (tmp_path / "out").exists()

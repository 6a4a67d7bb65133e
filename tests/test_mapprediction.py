"""Map prediction (issue 56, items 1 and 2; docs/mapprediction.md): tiny data through ``mapgen``, a few
training steps of each predictor, predictions from an OccupancyMap, the held-out evaluation, the
encodings, the simple predictions on hand-made maps, resume, and bad input."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from omegaconf import OmegaConf

from datagen.mapgen import generate_maps, load_mapgen_config
from datagen.mapshards import open_map_dataset
from frontiernet.cli.main import main as cli
from frontiernet.errors import InputError
from frontiernet.mapping import FREE, OCCUPIED, UNKNOWN, OccupancyMap
from frontiernet.mapprediction import (band_layers, confusion, crop_input, crop_states, load_predictor,
                                       map_states, map_topdown_states, near_frontier, predict_free, predict_wall,
                                       save_predictor, scores, take_crop, topdown_input, topdown_probability,
                                       topdown_states)
from frontiernet.mapprediction.encodings import decode_crop_input, probability_states
from frontiernet.mapprediction.networks import NetworkSettings, PredictorSpec
from train.mapeval import evaluate_maps
from train.mapprediction import load_map_train_config, main as train_main

SMALL = "floors=1&footprint_min=8&footprint_max=10&rooms_min=3&rooms_max=4"
SCENES = [f"procedural:5?{SMALL}", f"procedural:6?{SMALL}"]
HELD_OUT = [f"procedural:7?{SMALL}"]
SET = ["sim.camera.width=96", "sim.camera.height=96", "sim.camera.focal_px=60", "mapgen.max_steps=20",
       "mapgen.snapshot_every_steps=6", "mapgen.first_snapshot_step=6", "mapgen.runs=[{method: classic, depth: gt}]"]
TINY = {"seer": {"predictor": {"kind": "seer", "crop_shape": [16, 16, 8], "network": {"widths": [4, 8, 8], "dilations": [1]}}},
        "mapex": {"predictor": {"kind": "mapex", "network": {"widths": [4, 8, 8], "dilations": [1]}},
                  "data": {"topdown_size": 32}}}


@pytest.fixture(scope="module")
def conf():
    return load_mapgen_config(overrides=SET)


@pytest.fixture(scope="module")
def map_data(tmp_path_factory, conf):
    out = tmp_path_factory.mktemp("maps") / "train"
    summary = generate_maps(SCENES, out, conf, seed=1, progress=False)
    return out, summary


@pytest.fixture(scope="module")
def held_out(tmp_path_factory, conf):
    out = tmp_path_factory.mktemp("maps") / "held_out"
    generate_maps(HELD_OUT, out, conf, seed=2, progress=False)
    return out


def tiny_config(tmp_path: Path, kind: str, dataset: Path, **sections):
    user = OmegaConf.merge(TINY[kind], {"name": kind, "out": str(tmp_path), "data": {"batch_size": 2, "val_fraction": 0.5},
                                        "trainer": {"max_epochs": 1, "max_steps": 3, "max_time": None,
                                                    "val_check_interval": 1.0, "log_every_n_steps": 1},
                                        "optim": {"horizon": "steps", "warmup_steps": 1}}, sections)
    path = tmp_path / f"{kind}.yaml"
    path.write_text(OmegaConf.to_yaml(user))
    return path, load_map_train_config(path, [f"data.path={dataset}"])


@pytest.fixture(scope="module")
def trained(tmp_path_factory, map_data):
    """A tiny predictor of each kind, trained a few steps: {kind: its run folder}."""
    runs = {}
    for kind in ("seer", "mapex"):
        folder = tmp_path_factory.mktemp(f"run_{kind}")
        runs[kind] = train_main(tiny_config(folder, kind, map_data[0])[1], progress=False)
    return runs


def a_map(voxel_size: float = 0.1) -> OccupancyMap:
    """A 4 x 4 x 2.4 m map that saw a wall 2 m ahead of a level camera at 1.2 m."""
    conf = OmegaConf.merge(load_mapgen_config().map, {"voxel_size": voxel_size})
    occupancy = OccupancyMap(np.zeros(3), tuple(int(round(n / voxel_size)) for n in (4.0, 4.0, 2.4)), conf)
    K = np.array([[40.0, 0, 31.5], [0, 40.0, 31.5], [0, 0, 1]])
    T = np.eye(4)
    T[:3, :3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]  # camera z (optical axis) along world +x, level
    T[:3, 3] = [0.5, 2.0, 1.2]
    occupancy.integrate(np.full((64, 64), 2.0, np.float32), K, T)
    return occupancy


# --------------------------------------------------------------------------- data

def test_mapgen_writes_runs_of_snapshots_with_the_true_occupancy(map_data):
    out, summary = map_data
    assert summary["failed_runs"] == 0 and summary["runs"] == len(SCENES) and summary["snapshots"] >= 2 * len(SCENES)
    info = json.loads((out / "dataset.json").read_text())
    assert info["format"] == "frontiernet-map-dataset" and info["voxel_size"] == 0.1
    assert info["runs"] == [{"method": "classic", "depth": "ground_truth"}]
    dataset = open_map_dataset(out)
    assert dataset.scenes == SCENES and len(dataset) == summary["snapshots"]
    shard, record = dataset.snapshots[0]
    assert record["step"] >= 6 and record["frontiers"] and len(record["frontiers"][0]) == 3
    assert record["floor_z"] == pytest.approx(record["position"][2] - 1.2)
    observed, occupied = dataset.masks(0)
    truth_occupied, explorable = dataset.truth(shard)
    assert observed.shape == tuple(dataset.metas[shard]["shape"]) == truth_occupied.shape and observed.dtype == bool
    assert not (occupied & ~observed).any() and not (truth_occupied & explorable).any()
    later = dataset.masks(1)[0]
    assert later.sum() >= observed.sum()  # the map grows along the run


def test_resume_makes_only_the_missing_runs_and_refuses_another_config(map_data, conf, tmp_path):
    out, _ = map_data
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    shards = sorted((copy / "shards").glob("*.zip"))
    reference = shards[1].read_bytes()
    shards[1].unlink()  # the run that was under way when the generation was killed ...
    (copy / "shards" / f"{shards[1].name}.tmp-999").write_bytes(b"half a shard")  # ... and its temporary
    with pytest.raises(InputError, match="pass --resume"):
        generate_maps(SCENES, copy, conf, seed=1, progress=False)
    summary = generate_maps(SCENES, copy, conf, seed=1, resume=True, progress=False)
    assert summary["runs_done_before"] == 1 and summary["runs_this_session"] == 1
    assert shards[1].read_bytes() == reference  # the same seed gives the same bytes
    assert not list((copy / "shards").glob("*.tmp-*"))
    other = OmegaConf.merge(conf, {"mapgen": {"max_steps": 30}})
    with pytest.raises(InputError, match=r"copy: cannot resume, the dataset was made with other settings "
                                         r"\(mapgen.max_steps: \d+ in the dataset, 30 now\); use another --out"):
        generate_maps(SCENES, copy, other, seed=1, resume=True, progress=False)  # (seventh probe, D22: the hashes)
    nbvp_changed = OmegaConf.merge(conf, {"nbvp": {"attempts_per_node": 7}})  # a method no run of it uses
    summary = generate_maps(SCENES, copy, nbvp_changed, seed=1, resume=True, progress=False)
    assert summary["runs_done_before"] == 2 and summary["runs_this_session"] == 0


# --------------------------------------------------------------------------- encodings

def test_crop_and_topdown_encodings_round_trip_and_match_the_map():
    occupancy = a_map()
    states = map_states(occupancy)
    assert states.dtype == np.int8 and set(np.unique(states)) == {UNKNOWN, FREE, OCCUPIED}
    crop, corner = crop_states(occupancy, (2.0, 2.0, 1.2), (16, 16, 8), floor_z=0.4)
    assert crop.shape == (16, 16, 8) and corner.tolist() == [12, 12, 4]
    assert np.array_equal(crop, take_crop(states, corner, (16, 16, 8), np.int8(UNKNOWN)))
    one_hot = crop_input(crop)
    assert one_hot.shape == (3, 16, 16, 8) and one_hot.dtype == np.float32 and np.all(one_hot.sum(axis=0) == 1)
    assert np.array_equal(decode_crop_input(one_hot), crop)
    edge, _ = crop_states(occupancy, (0.0, 0.0), (16, 16, 8))  # half off the map: unknown there
    assert np.all(edge[:8, :8] == UNKNOWN)
    k0, k1 = band_layers(occupancy.origin[2], occupancy.voxel_size, occupancy.shape[2], 1.2, 0.3)
    top = topdown_states(states, k0, k1)
    assert np.array_equal(top, map_topdown_states(occupancy, 1.2, 0.3))
    probability = topdown_probability(top)
    assert set(np.unique(probability)) == {0.0, 0.5, 1.0} and np.array_equal(probability_states(probability), top)
    assert topdown_input(probability).shape == (2,) + top.shape


# --------------------------------------------------------------------------- simple predictions, scores

def test_the_simple_predictions_and_scores_on_a_hand_made_map():
    s = np.full((14, 9), FREE, np.int8)  # cells (x, y) of 0.1 m
    s[8:] = UNKNOWN  # x >= 8 unseen
    s[:8, 4] = OCCUPIED  # a wall along x, seen end-on at x = 7: it runs into the unknown
    wall = predict_wall(s, 0.1, reach_m=0.4, run_cells=5)
    assert wall[8:12, 4].all() and not wall[12:, 4].any()  # continued up to `reach` (4 cells) past its end
    assert wall.sum() == (s == OCCUPIED).sum() + 4  # nothing else: known cells keep their state
    assert not predict_wall(s, 0.1, reach_m=0.4, run_cells=9)[8:].any()  # a wall shorter than the run: not a wall
    assert not predict_free(s)[s == UNKNOWN].any() and predict_free(s)[s == OCCUPIED].all()
    face = np.where(np.arange(14)[:, None] < 8, FREE, UNKNOWN).astype(np.int8) + np.zeros((1, 9), np.int8)
    face[7] = OCCUPIED  # a wall across, seen face-on: one cell deep, not continued through the unknown
    assert not predict_wall(face, 0.1, 0.4, 5)[8:].any()
    face[3:8] = OCCUPIED  # a block 5 cells deep is a wall run: continued
    assert predict_wall(face, 0.1, 0.4, 5)[8:12].all()
    layers = np.stack([s, face], axis=2)  # 3D: the rule per horizontal layer
    assert np.array_equal(predict_wall(layers, 0.1, 0.4, 5), np.stack([wall, predict_wall(face, 0.1, 0.4, 5)], axis=2))

    # scored: unknown cells within 0.2 m of a frontier cell (free beside unknown: x = 7, y != 4)
    near = near_frontier(s, 0.1, radius_m=0.2)
    assert near[8].all() and near[9, [0, 1, 2, 3, 5, 6, 7, 8]].all() and near.sum() == 17  # (9, 4) is 0.22 m off
    labels = np.zeros(s.shape, np.uint8)
    labels[:, 4] = 1  # the truth: the wall goes on
    assert confusion(wall, labels, near).tolist() == [1, 0, 0, 16]  # (8, 4) continued: TP; the rest free: TN
    assert confusion(predict_free(s), labels, near).tolist() == [0, 0, 1, 16]
    labels[10, 0] = 255  # ignored cells are not scored
    assert near_frontier(s, 0.1, 0.3, labels).sum() == near_frontier(s, 0.1, 0.3).sum() - 1
    result = scores([2, 1, 1, 16])
    assert result["accuracy"] == pytest.approx(18 / 20) and result["iou_occupied"] == pytest.approx(0.5)
    assert result["iou_free"] == pytest.approx(16 / 18) and result["miou"] == pytest.approx((0.5 + 16 / 18) / 2)
    assert result["cells"] == 20 and np.isnan(scores([0, 0, 0, 0])["accuracy"])


# --------------------------------------------------------------------------- train, predict, evaluate

def test_training_writes_a_predictor_of_each_kind_that_predicts_from_a_map(trained):
    occupancy = a_map()
    seer = load_predictor(trained["seer"] / "predictor.safetensors", kind="seer")
    summary = json.loads((trained["seer"] / "summary.json").read_text())
    assert summary["steps"] == 3 and summary["parameters"] == sum(p.numel() for p in seer.net.parameters())
    assert seer.info["train_scenes"] and set(seer.info["train_scenes"] + seer.info["val_scenes"]) == set(SCENES)
    crop = seer.predict_crop(occupancy, (2.0, 2.0), floor_z=0.4)
    assert crop.probability.shape == (16, 16, 8) and crop.probability.dtype == np.float32
    assert np.all((crop.probability >= 0) & (crop.probability <= 1))
    assert np.all(crop.probability[crop.states == OCCUPIED] == 1) and np.all(crop.probability[crop.states == FREE] == 0)
    mapex = load_predictor(trained["mapex"] / "predictor.safetensors")
    assert mapex.kind == "mapex" and mapex.spec.members == 3 and mapex.occupied_threshold == 0.5
    mean, variance = mapex.predict_topdown(occupancy, 1.2)
    assert mean.shape == variance.shape == occupancy.shape[:2] and mean.dtype == variance.dtype == np.float32
    unknown = map_topdown_states(occupancy, 1.2, 0.3) == UNKNOWN
    assert np.all(variance[~unknown] == 0) and np.all(variance >= 0) and variance[unknown].max() > 0
    last = load_predictor(trained["mapex"] / "checkpoints" / "last.ckpt")  # a checkpoint loads as a predictor
    assert last.spec == mapex.spec and last.info["train_scenes"] == mapex.info["train_scenes"]


def test_training_resumes_from_its_last_checkpoint(trained, map_data):
    run = trained["seer"]
    path, conf = tiny_config(run.parent, "seer", map_data[0], trainer={"max_steps": 4, "max_epochs": 5})
    with pytest.raises(InputError, match="pass --resume"):
        train_main(conf, progress=False)
    train_main(conf, resume="last", progress=False)
    assert json.loads((run / "summary.json").read_text())["steps"] == 4 and (run / "metrics-part1.csv").is_file()


def test_mapeval_scores_held_out_scenes_beside_the_simple_predictions(trained, held_out, map_data, tmp_path, capsys):
    result = evaluate_maps(trained["seer"] / "predictor.safetensors", held_out, crops_per_snapshot=2)
    assert result["scenes"] == HELD_OUT and set(result["scores"]) == {"procedural", "all"} and result["crops"] > 0
    row = result["scores"]["procedural"]
    assert set(row) == {"predictor", "unknown=free", "continue wall"}
    assert row["unknown=free"]["iou_occupied"] == 0 and row["predictor"]["cells"] == row["unknown=free"]["cells"] > 0
    report = tmp_path / "mapex.json"
    assert cli(["mapeval", str(trained["mapex"] / "predictor.safetensors"), "--data", str(held_out),
                "--json", str(report)]) == 0
    assert "continue wall" in capsys.readouterr().out
    scores_json = json.loads(report.read_text())
    assert scores_json["kind"] == "mapex" and set(scores_json["variance"]["procedural"]) == {"where_right", "where_wrong"}
    with pytest.raises(InputError, match="every scene of the dataset was seen in training"):
        evaluate_maps(trained["mapex"] / "predictor.safetensors", map_data[0])


# --------------------------------------------------------------------------- bad input

def test_bad_predictor_files_and_map_resolutions_are_refused(trained, held_out, tmp_path, capsys):
    seer_path = trained["seer"] / "predictor.safetensors"
    seer = load_predictor(seer_path)
    other = tmp_path / "wrong_shape.safetensors"  # weights of another architecture than the file declares
    spec = PredictorSpec("seer", NetworkSettings((4, 16, 8), (1,), 3), crop_shape=(16, 16, 8))
    save_predictor(other, spec, seer.net.state_dict())
    shipped = Path(__file__).resolve().parents[1] / "frontiernet" / "weights" / "frontiernet_rgbd_resnet18.safetensors"
    report = tmp_path / "scores.json"
    for bad, message in ((other, "weights do not fit the seer predictor"), (shipped, "not a map predictor file"),
                         (tmp_path / "missing.safetensors", "predictor file not found")):
        if bad == shipped and not shipped.is_file():
            continue
        assert cli(["mapeval", str(bad), "--data", str(held_out), "--json", str(report)]) == 2
        err = capsys.readouterr().err
        assert message in err and str(bad) in err and len(err.strip().splitlines()) == 1
    with pytest.raises(InputError, match="a seer predictor, expected a mapex one"):
        load_predictor(seer_path, kind="mapex")
    with pytest.raises(InputError, match="not a mapex one"):
        seer.predict_topdown(a_map(), 1.2)
    with pytest.raises(InputError, match="trained on 0.1 m voxels, given a map of 0.05 m voxels"):
        seer.predict_crop(a_map(0.05), (2.0, 2.0))
    with pytest.raises(InputError, match=r"takes crops of \[16, 16, 8\] voxels"):
        seer.predict_crop_states(np.zeros((80, 80, 24), np.int8), 0.1)

    coarse = tmp_path / "coarse"  # a dataset made with another map resolution
    shutil.copytree(held_out, coarse)
    info = json.loads((coarse / "dataset.json").read_text())
    (coarse / "dataset.json").write_text(json.dumps(dict(info, voxel_size=0.05)))
    assert cli(["mapeval", str(seer_path), "--data", str(coarse), "--json", str(report)]) == 2
    err = capsys.readouterr().err
    assert "dataset.json: voxel_size 0.05 m" in err and len(err.strip().splitlines()) == 1
    assert not report.exists()  # nothing written
    path, _ = tiny_config(tmp_path, "seer", coarse)
    assert cli(["train", "--config", str(path), f"data.path={coarse}"]) == 2
    assert "differs from predictor.voxel_size 0.1 m" in capsys.readouterr().err
    assert not (tmp_path / "seer").exists()


def test_training_refuses_test_scenes_and_foreign_datasets(held_out, map_data, tmp_path, capsys):
    path, conf = tiny_config(tmp_path, "mapex", held_out, data={"refuse_scenes": ["procedural:7-8"]})
    with pytest.raises(InputError, match="procedural:7.*data.refuse_scenes"):
        train_main(conf, progress=False)
    frontier_dataset = tmp_path / "frontiernet_dataset"
    frontier_dataset.mkdir()
    (frontier_dataset / "dataset.json").write_text(json.dumps({"format": "frontiernet-dataset", "format_version": 1}))
    assert cli(["train", "--config", str(path), f"data.path={frontier_dataset}"]) == 2
    assert "not a map dataset (format 'frontiernet-dataset'" in capsys.readouterr().err
    out = tmp_path / "never"
    assert cli(["mapgen", "--scenes", SCENES[0], "--out", str(out), "--set", "mapgen.runs=[{method: nope, depth: gt}]"]) == 2
    assert "mapgen.runs[0].method: unknown exploration method 'nope'" in capsys.readouterr().err and not out.exists()
    assert cli(["mapgen", "--scenes", "procedural:5?nonsense=3", "--out", str(out), "--no-progress"]) == 2
    assert "unknown procedural option 'nonsense'" in capsys.readouterr().err and not out.exists()  # every run failed
    shard = next((map_data[0] / "shards").glob("*.zip"))
    broken = tmp_path / "broken"
    shutil.copytree(map_data[0], broken)
    (broken / "shards" / shard.name).write_bytes(b"not a zip")
    with pytest.raises(InputError, match=f"{shard.name}: corrupt map shard"):
        open_map_dataset(broken)

"""Bad input of the ninth probe of issue 55 to training, evaluation, export and the datasets (docs/bad_input.md):
one line naming the file, key or value and what is wrong, exit code 2, no traceback, refused before the trainer's
setup, and nothing written over or left behind."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
import torch

from frontiernet.cli.main import main
from frontiernet.errors import InputError
from frontiernet.io import claim_output_folder

REPO_ROOT = Path(__file__).resolve().parents[1]
TINY = ["trainer.max_steps=1", "data.image_size=64", "data.batch_size=2", "augment.crop_size=null",
        "data.num_workers=0", "data.cache=false", "data.max_val_samples=2", "trainer.accelerator=cpu",
        "trainer.threads=1"]
"""Overrides of a FrontierNet training of one step on 64 px views (as tests/test_bad_input_training.py)."""
SMALL_PREDICTOR = {"widths": [4, 8, 8], "dilations": [1]}


@pytest.fixture
def no_trainer(monkeypatch):
    """Makes Lightning's Trainer an internal error (exit 1): a refusal that exits 2 came before the trainer's setup
    (and its lines on stderr)."""
    import train.main

    def refuse(*args, **kwargs):
        raise RuntimeError("the trainer was set up")

    monkeypatch.setattr(train.main.L, "Trainer", refuse)


def train_args(data, out, *extra) -> list[str]:
    return ["train", "--no-progress", f"data.path={data}", f"out={out}", *TINY, *extra]


def map_train_args(kind: str, out, *extra) -> list[str]:
    return ["train", "--no-progress", "--config", str(REPO_ROOT / "configs" / f"train_{kind}.yaml"),
            "data.path=nowhere", f"out={out}", *extra]


def checkpoint(path: Path, hyper: dict, weights: dict) -> Path:
    """A checkpoint as ``frontiernet train`` writes one (Lightning's keys), of hyperparameters `hyper`."""
    torch.save({"pytorch-lightning_version": "2.4.0", "epoch": 0, "global_step": 1, "loops": {},
                "optimizer_states": [], "lr_schedulers": [],
                "state_dict": {f"net.{name}": tensor for name, tensor in weights.items()},
                "hyper_parameters": hyper}, path)
    return path


def predictor_checkpoint(path: Path, kind: str, network: dict | None = None) -> Path:
    """A map predictor's checkpoint of `kind` (the shipped config's architecture, or `network`)."""
    from frontiernet.config import load_config
    from train.mapprediction import predictor_spec

    conf = load_config(f"train_{kind}")
    if network:
        conf.predictor.network.update(network)
    spec = predictor_spec(conf)
    return checkpoint(path, {"predictor": spec.to_dict(), "train": {}}, spec.build().state_dict())


def frontiernet_checkpoint(path: Path) -> Path:
    """The shipped FrontierNet as a training checkpoint."""
    from frontiernet.model import load_model

    model, conf = load_model()
    return checkpoint(path, {"model": {key: conf[key] for key in ("network", "input", "labels", "inference")},
                             "train": {}}, model.state_dict())


# ----------------------------------------------------------------------------- E3: a checkpoint of another kind

def test_resuming_from_a_checkpoint_of_another_kind_or_architecture_is_refused_naming_it(tmp_path, one_line_error):
    # ninth probe (E3): Lightning's setup, then exit 1, "Error(s) in loading state_dict for FrontierNetModule"
    mapex = predictor_checkpoint(tmp_path / "mapex.ckpt", "mapex")
    runs = tmp_path / "runs"
    assert main(train_args(tmp_path / "nowhere", runs, "--resume", str(mapex))) == 2
    assert one_line_error().endswith(f"error: {mapex}: the checkpoint of a mapex map predictor; this run trains a "
                                     "FrontierNet model: resume from one of its own checkpoints, or start afresh "
                                     "without --resume")
    frontiernet = frontiernet_checkpoint(tmp_path / "frontiernet.ckpt")
    assert main(map_train_args("mapex", runs, "--resume", str(frontiernet))) == 2
    assert (f"{frontiernet}: the checkpoint of a FrontierNet model; this run trains a mapex map predictor"
            in one_line_error())
    assert main(map_train_args("seer", runs, "--resume", str(mapex))) == 2
    assert f"{mapex}: the checkpoint of a mapex map predictor; this run trains a seer map predictor" in one_line_error()
    small = predictor_checkpoint(tmp_path / "small.ckpt", "seer", SMALL_PREDICTOR)
    assert main(map_train_args("seer", runs, "--resume", str(small))) == 2
    assert (f"{small}: a seer map predictor's checkpoint of another architecture (predictor.network.widths: "
            "[4, 8, 8] there, [8, 16, 36] in this run)") in one_line_error()
    assert not runs.exists()


# ----------------------------------------------------------------------------- E4: preview of a corrupt shard

def test_a_preview_that_fails_on_a_corrupt_shard_leaves_no_folder_and_no_sheet(two_scenes, tmp_path, one_line_error):
    # ninth probe (E4): the one line, and an empty pv4/ left behind (a sheet written before it: a partial one)
    broken = tmp_path / "broken"
    shutil.copytree(two_scenes, broken, ignore=shutil.ignore_patterns("cache"))
    shard = sorted((broken / "shards").glob("*.zip"))[-1]  # the second of the two sheets reads it
    with zipfile.ZipFile(shard) as source:
        members = {name: source.read(name) for name in source.namelist() if not name.endswith("/gain.npy")}
    with zipfile.ZipFile(shard, "w") as target:
        for name, data in members.items():
            target.writestr(name, data)
    out = tmp_path / "previews" / "pv4"
    assert main(["datagen", "preview", str(broken), "--n", "2", "--out", str(out)]) == 2
    assert f"{shard}: corrupt shard (member " in one_line_error()
    assert not (tmp_path / "previews").exists()
    out.mkdir(parents=True)  # a folder that was there keeps what it held, and gets no sheet
    (out / "notes.txt").write_text("mine")
    assert main(["datagen", "preview", str(broken), "--n", "2", "--out", str(out)]) == 2
    assert "corrupt shard" in one_line_error()
    assert sorted(path.name for path in out.iterdir()) == ["notes.txt"]


# ----------------------------------------------------------------------------- E6: more loader workers than cores

def test_evaluate_with_more_workers_than_cores_says_so_in_one_line(two_scenes, monkeypatch, caplog):
    # ninth probe (E6): torch's four-line DataLoader warning ("Our suggested max number of worker ..."), twice
    import warnings

    from frontiernet.model import default_model_path

    monkeypatch.setattr("os.sched_getaffinity", lambda pid: {0})  # one core, as torch and evaluate count them
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert main(["evaluate", str(default_model_path()), "--data", str(two_scenes), "--all", "--max-samples", "1",
                     "--size", "64", "--workers", "2"]) == 0
    assert not [warning for warning in caught if "worker processes" in str(warning.message)]
    assert [record.getMessage() for record in caplog.records if "--workers" in record.getMessage()] == [
        "--workers 2: more loader processes than the 1 CPU cores this process may use; they share them"]


# ----------------------------------------------------------------------------- E7: a data.cache folder

def test_a_cache_folder_that_is_no_cache_is_refused_before_the_trainer(two_scenes, tmp_path, no_trainer,
                                                                      one_line_error):
    # ninth probe (E7): "cache.json: not found (... is not a training cache)" after 10 Lightning lines
    from omegaconf import OmegaConf

    from frontiernet.config import load_config
    from train.cache import ensure_cache

    runs, other = tmp_path / "runs", tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    assert main(train_args(two_scenes, runs, f"data.cache={other}")) == 2
    assert one_line_error().endswith(f"error: data.cache={other}: {other} holds files but no cache.json, so it is not "
                                     "a training cache; give a new or an empty folder (the cache is built there), or "
                                     "data.cache=auto")
    # an empty folder is where the cache is built (it was refused as not a cache)
    labels = OmegaConf.merge(load_config("model").labels, {"gain_definition": None})
    empty = tmp_path / "empty"
    empty.mkdir()
    cache = ensure_cache(two_scenes, str(empty), 64, labels)
    assert cache.path == empty and (empty / "cache.json").is_file() and len(cache) == 4
    # a cache of another size: refused before the trainer too (it was opened after its setup)
    assert main(train_args(two_scenes, runs, f"data.cache={empty}", "data.image_size=32")) == 2
    assert f"{empty / 'cache.json'}: built for size 64, the config asks for 32" in one_line_error()
    assert not runs.exists() and (other / "notes.txt").read_text() == "mine"


# ----------------------------------------------------------------------------- E11, E12: the run folder

def test_a_fresh_run_into_an_earlier_runs_folder_is_refused_and_replaces_nothing(tmp_path, one_line_error):
    # ninth probe (E11): its model.safetensors, metrics.csv and summary.json replaced without --resume or a word
    run = tmp_path / "runs" / "tiny"
    run.mkdir(parents=True)
    for name in ("model.safetensors", "metrics.csv", "summary.json"):
        (run / name).write_text(f"earlier {name}")
    args = train_args(tmp_path / "nowhere", tmp_path / "runs", "name=tiny")
    assert main(args) == 2
    assert one_line_error().endswith(f"error: {run}: holds an earlier training run's files (model.safetensors, "
                                     "summary.json, metrics.csv), which a new run would replace; it has no checkpoint "
                                     "to resume from: choose another out= or name=, or move them away")
    (run / "checkpoints").mkdir()
    (run / "checkpoints" / "best.ckpt").write_text("a checkpoint")
    assert main(args) == 2
    assert f"pass --resume {run / 'checkpoints' / 'best.ckpt'} to continue it, or choose another out= or name=" \
        in one_line_error()
    assert main(map_train_args("seer", tmp_path / "runs", "name=tiny")) == 2  # a map predictor's training too
    assert f"{run}: holds an earlier training run's files" in one_line_error()
    assert all((run / name).read_text() == f"earlier {name}" for name in ("model.safetensors", "metrics.csv",
                                                                           "summary.json"))


def test_a_second_training_on_a_run_folder_in_use_is_refused(two_scenes, tmp_path, no_trainer, one_line_error):
    # ninth probe (E12): two runs on one folder at once both exited 0, each writing over the other's files
    run = tmp_path / "runs" / "tiny"
    with claim_output_folder(run, force=True):  # another process's run holds it
        assert main(train_args(two_scenes, tmp_path / "runs", "name=tiny")) == 2
        assert f"{run}: another run (process " in one_line_error()
    assert not (run / ".frontiernet.lock").exists()
    # what a run in progress in another process wrote is not taken for an earlier run's files (the second run is
    # told so), and a lock file left by a run that ended (its lock gone with its process) is no run in progress
    holder = subprocess.Popen([sys.executable, "-c", HOLD_THE_FOLDER, str(run)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        assert main(train_args(two_scenes, tmp_path / "runs", "name=tiny")) == 2
        assert one_line_error().endswith(f"error: {run}: another run (process {holder.pid}) is writing there; wait for "
                                         "it to end, or choose another out= or name=")
    finally:
        holder.kill()
        holder.wait()
    assert (run / ".frontiernet.lock").read_text().strip() == str(holder.pid)  # (killed: its file was left)
    assert main(train_args(two_scenes, tmp_path / "runs", "name=tiny")) == 2
    assert f"{run}: holds an earlier training run's files" in one_line_error()


HOLD_THE_FOLDER = """import sys, time
from frontiernet.io import claim_output_folder
with claim_output_folder(sys.argv[1], force=True) as run:
    (run / "metrics.csv").write_text("rows of the run in progress")
    print("held", flush=True)
    time.sleep(120)
"""


def test_claimed_run_folder_takes_the_lock_and_removes_what_it_made(tmp_path):
    from train.resume import claimed_run_folder

    run = tmp_path / "runs" / "tiny"
    with pytest.raises(InputError, match="another run"):
        with claimed_run_folder(run, None) as made:
            assert made == tmp_path / "runs" and (run / ".frontiernet.lock").is_file()
            with claimed_run_folder(run, None):
                pass
    assert not (tmp_path / "runs").exists()


# ----------------------------------------------------------------------------- E13: export's frontier threshold

@pytest.mark.parametrize("threshold", ["0.05", "0.1", "1e-300"])
def test_export_refuses_a_frontier_threshold_at_or_below_the_models_smallest_distance(threshold, tmp_path,
                                                                                      one_line_error):
    # ninth probe (E13): 0.05 px marked 1 frontier pixel of an image (2,913 at the model's own), 1e-300 none
    from frontiernet.model import default_model_path

    out = tmp_path / "m.safetensors"
    assert main(["export", str(default_model_path()), "--format", "safetensors", "--out", str(out),
                 "--frontier-threshold", threshold]) == 2
    message = one_line_error()
    assert "--frontier-threshold must be in (0.1, 10) pixels, got " in message
    assert "labels.min_distance_px = 0.1 px, so a threshold there or below marks (almost) no pixel" in message
    assert not out.exists()


# ----------------------------------------------------------------------------- E16: keys of the other predictor

@pytest.mark.parametrize("kind, key", [("mapex", "data.crops_per_snapshot=1000000000"), ("mapex", "data.jitter_m=1e30"),
                                       ("mapex", "predictor.crop_shape=[16,16,8]"), ("seer", "data.topdown_size=64"),
                                       ("seer", "data.anywhere_fraction=0.5"), ("seer", "predictor.band_m=1")])
def test_a_key_the_predictors_kind_does_not_read_is_refused(kind, key, tmp_path, one_line_error):
    # ninth probe (E16): data.crops_per_snapshot / data.jitter_m in a mapex training, ignored without a word
    other = "seer" if kind == "mapex" else "mapex"
    assert main(map_train_args(kind, tmp_path / "runs", key)) == 2
    assert f"error: {key.split('=')[0]}: a {kind} training does not read it ({other} only: " in one_line_error()
    assert not (tmp_path / "runs").exists()


def test_the_shipped_predictor_configs_and_their_own_keys_are_taken():
    from train.mapprediction import load_map_train_config

    for kind, key in (("seer", "data.crops_per_snapshot=2"), ("mapex", "data.topdown_size=64")):
        conf = load_map_train_config(REPO_ROOT / "configs" / f"train_{kind}.yaml", ["data.path=d", key])
        assert conf.predictor.kind == kind


# ----------------------------------------------------------------------------- E17, E18: evaluate's options

def test_evaluate_checks_a_monocular_depth_sources_files_as_explore_does(two_scenes, tmp_path, one_line_error):
    # ninth probe (E17): "depth.depth_anything_v2: expected a mapping of options, got tuple", whatever was installed
    from frontiernet.config import load_config
    from frontiernet.depth import check_depth_files
    from frontiernet.model import default_model_path

    for name in ("depth_anything_v2", "metric3d_v2"):
        try:
            check_depth_files(name, load_config("depth"))  # what explore --depth checks
        except InputError as error:
            expected = str(error)
        else:
            continue  # its files are installed here: nothing to refuse
        assert "expected a mapping" not in expected
        with pytest.raises(InputError) as without_conf:  # the shipped options when no config is given
            check_depth_files(name)
        assert str(without_conf.value) == expected
        assert main(["evaluate", str(default_model_path()), "--data", str(two_scenes), "--all", "--max-samples", "1",
                     "--depth", name]) == 2
        assert one_line_error() == f"frontiernet evaluate: error: {expected}"


def test_evaluate_takes_seed_ranges_and_patterns_of_the_datasets_scenes(two_scenes, capsys, one_line_error):
    # ninth probe (E18): "scene(s) not in the dataset: procedural:3-4" (and 'procedural:*'), both scenes there
    from frontiernet.model import default_model_path

    args = ["evaluate", str(default_model_path()), "--data", str(two_scenes), "--max-samples", "2", "--size", "64",
            "--scenes"]
    for scenes in (["procedural:3-4"], ["procedural:*"], ["procedural:[34]", "procedural:3"]):
        assert main(args + scenes) == 0
        assert "on 2 views of 2 given scene(s)" in capsys.readouterr().out
    assert main(args + ["mesh:*.glb"]) == 2
    assert one_line_error().endswith(f"error: {two_scenes}: --scenes 'mesh:*.glb': the pattern matches none of the "
                                     "dataset's scenes (procedural:3, procedural:4)")
    assert main(args + ["procedural:3-9"]) == 2
    assert one_line_error().endswith(f"error: {two_scenes}: scene(s) not in the dataset: procedural:5, procedural:6, "
                                     "procedural:7, procedural:8, procedural:9 (it holds procedural:3, procedural:4)")
    assert main(args + ["procedural:4-3"]) == 2  # a malformed range: refused as datagen refuses it
    assert "procedural:4-3" in one_line_error()


# ----------------------------------------------------------------------------- E21: a dataset of the other command

@pytest.mark.parametrize("resume", [[], ["--resume"]])
def test_a_dataset_of_the_other_command_is_named_as_such(resume, tmp_path, one_line_error):
    # ninth probe (E21): mapgen --out <a datagen dataset> advised --resume, then refused it as "not a map dataset"
    from datagen.shards import DATASET_FORMAT, DATASET_FORMAT_VERSION

    frontier = tmp_path / "ds"
    frontier.mkdir()
    description = json.dumps({"format": DATASET_FORMAT, "format_version": DATASET_FORMAT_VERSION})
    (frontier / "dataset.json").write_text(description)
    assert main(["mapgen", "--scenes", "procedural:3", "--no-progress", "--out", str(frontier), *resume]) == 2
    assert one_line_error().endswith(f"error: {frontier}: holds a FrontierNet dataset (frontiernet datagen), not a "
                                     "map dataset: mapgen cannot add to it or resume it; choose another --out")
    maps = tmp_path / "maps"
    maps.mkdir()
    (maps / "dataset.json").write_text(json.dumps({"format": "frontiernet-map-dataset", "format_version": 1}))
    assert main(["datagen", "--scenes", "procedural:3", "--views-per-scene", "1", "--no-progress", "--out", str(maps),
                 *resume]) == 2
    assert one_line_error().endswith(f"error: {maps}: holds a map dataset (frontiernet mapgen), not a FrontierNet "
                                     "dataset: datagen cannot add to it or resume it; choose another --out")
    assert (frontier / "dataset.json").read_text() == description and sorted(p.name for p in maps.iterdir()) == [
        "dataset.json"]

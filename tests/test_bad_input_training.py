"""Bad input to training and to model files (the third probe of docs/bad_input.md): one line naming the
file, key or value and what is wrong, exit code 2, no traceback, and nothing written (no run folder,
no training cache, no export)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import torch

from frontiernet.cli.main import main
from frontiernet.errors import InputError

TINY = ["trainer.max_steps=1", "data.image_size=64", "data.batch_size=2", "augment.crop_size=null",
        "data.num_workers=0", "data.cache=false", "data.max_val_samples=2", "trainer.accelerator=cpu",
        "trainer.threads=1"]


FIRST = "stem.0.weight"
"""The weight of the shipped model that :func:`model_with` changes."""


def model_with(tmp_path: Path, value: float, suffix: str = ".safetensors") -> Path:
    """The shipped model with one weight set to `value`, as a model file or (suffix .ckpt) a checkpoint
    as ``frontiernet train`` writes one (Lightning's keys included)."""
    from frontiernet.model import load_model, save_model

    model, conf = load_model()
    with torch.no_grad():
        dict(model.named_parameters())[FIRST].view(-1)[3] = value
    path = tmp_path / f"model{suffix}"
    if suffix == ".safetensors":
        return save_model(path, model, conf)
    model_conf = {key: conf[key] for key in ("network", "input", "labels", "inference")}
    torch.save({"pytorch-lightning_version": "2.4.0", "epoch": 0, "global_step": 1, "loops": {},
                "optimizer_states": [], "lr_schedulers": [],
                "state_dict": {f"net.{name}": tensor for name, tensor in model.state_dict().items()},
                "hyper_parameters": {"model": model_conf, "train": {}}}, path)
    return path


@pytest.mark.parametrize("overrides, message", [
    # augment.crop_size larger than the views trained in silence, uncropped
    (["data.image_size=64", "augment.crop_size=128"],
     "augment.crop_size: 128 px is larger than the 64 px views it crops (data.image_size); give at most 64, "
     "or null for no crop"),
    # no loss term weighed: trained on a loss of 0
    (["loss.distance_weight=0", "loss.ce_weight=0", "loss.dice_weight=0"],
     "loss.distance_weight, loss.ce_weight, loss.dice_weight: all 0, so the loss is 0 and nothing trains"),
    (["loss.ce_weight=-1"], "loss.ce_weight must be a number >= 0, got -1"),
    # a learning-rate fraction of 2 ended the cosine at twice the rate
    (["optim.final_lr_fraction=2"], "optim.final_lr_fraction must be a number in [0, 1], got 2"),
    (["optim.final_lr_fraction=-0.1"], "optim.final_lr_fraction must be a number in [0, 1], got -0.1"),
    # one scene as text was read as its characters: "'3' is not a scene of the dataset"
    (["data.val_scenes=procedural:3"], "data.val_scenes: takes a list of scene specs (or null), got "
                                       "'procedural:3'; write one scene as a one-element list, e.g. "
                                       "'data.val_scenes=[procedural:3]'"),
    # numbers float32 cannot hold: an internal error (torch's overflow) or a whole run trained on NaN
    (["optim.lr=1e300"], "optim.lr must be a number in (0, 1e+30], got 1e+300: beyond the 32-bit floats it is computed in"),
    (["model.input.rgb_std=[0.1,0.1,1e-300]"], "model.input.rgb_std must be a list of 3 numbers > 0, got "
                                              "[0.1, 0.1, 1e-300]: beyond the 32-bit floats"),
    (["model.labels.truncation_px=1e300"], "model.labels.truncation_px must be a number > 0, got 1e+300: beyond"),
    # Lightning refused it only after its INFO lines on stderr
    (["trainer.limit_val_batches=1.5"], "trainer.limit_val_batches: a fraction of the validation batches is in "
                                        "[0, 1] (or give a whole number of batches, e.g. 1), got 1.5"),
    # eighth probe (E19): "got 60", a value never typed (YAML 1.1 reads 1:00 as a base-60 number); since the fifteenth
    # (Q12) an override's base-60 number is the text typed, for every key (1:00:00:00 is then one day, as typed)
    (["trainer.max_time=1:00"], "trainer.max_time: a wall-clock limit is DD:HH:MM:SS (e.g. 00:01:00:00), or null "
                                "for none; got '1:00'"),
    # eighth probe (E27): the advice was the bare key name, "...: init_inputs"
    (["init_weights=default", "model.network.inputs=depth"],
     "model.network.inputs: depth, but the run starts from init_weights's rgbd (its network replaces model.network): "
     "give init_inputs=depth (the started network's first layer then takes depth)"),
    # eighth probe (E25): "... or train on a dataset made with bogus", after the data load, the valid ones unnamed
    (["model.labels.gain_definition=bogus"], "model.labels.gain_definition must be one of unobserved/blend, "
                                             "unobserved/region, occluded/blend, occluded/region (or null), got 'bogus'"),
])
def test_training_settings_judged_without_data_are_refused_before_anything(tmp_path, overrides, message,
                                                                            one_line_error):
    runs = tmp_path / "runs"
    assert main(["train", "--no-progress", f"data.path={tmp_path / 'no_data'}", f"out={runs}", "name=tiny", *TINY,
                 *overrides]) == 2
    assert message in one_line_error()
    assert not runs.exists()


def test_an_override_is_judged_by_the_shipped_kind_of_its_key_not_a_config_files(tmp_path, one_line_error):
    # eighth probe (E32): with train_tiny.yaml's `cache_workers: 0`, data.cache_workers=abc "takes a number (default
    # 0)": the key also takes auto, which configs/train.yaml ships
    from conftest import REPO_ROOT

    runs = tmp_path / "runs"
    assert main(["train", "--no-progress", "--config", str(REPO_ROOT / "configs" / "train_tiny.yaml"),
                 f"data.path={tmp_path / 'no_data'}", f"out={runs}", "data.cache_workers=abc"]) == 2
    from frontiernet.errors import PER_CORE

    most = PER_CORE * (os.cpu_count() or 1)
    assert one_line_error().endswith(f"error: data.cache_workers must be an integer in [0, {most}], got 'abc' (at "
                                     f"most {PER_CORE} per core of this machine); or auto")
    assert not runs.exists()


def test_a_list_of_validation_scenes_is_still_taken():
    from train.config import load_train_config

    conf = load_train_config(overrides=["data.path=d", "data.val_scenes=[procedural:3]", "loss.ce_weight=0",
                                        "loss.dice_weight=0"])  # one loss term is enough
    assert list(conf.data.val_scenes) == ["procedural:3"]


def test_a_crop_larger_than_the_datasets_own_views_is_refused_before_the_cache(two_scenes, tmp_path,
                                                                              one_line_error):
    # data.image_size: null keeps the dataset's 64 px views: a crop of 128 is judged once the dataset is open,
    # before its training cache is built
    runs = tmp_path / "runs"
    assert main(["train", "--no-progress", f"data.path={two_scenes}", f"out={runs}", *TINY, "data.image_size=null",
                 "data.cache=auto", "augment.crop_size=128"]) == 2
    assert ("augment.crop_size: 128 px is larger than the 64 px views it crops (data.image_size: null keeps the "
            "dataset's size)") in one_line_error()
    assert not runs.exists() and not (two_scenes / "cache").exists()


def test_gain_classes_other_than_the_datasets_are_refused_before_the_trainer(two_scenes, tmp_path, one_line_error):
    # eighth probe (E3): Lightning's INFO lines, then an internal error at the first validation step (RuntimeError:
    # shape '[2, 2]' is invalid for input of size 23): the dataset's views hold 11 gain classes
    runs = tmp_path / "runs"
    assert main(["train", "--no-progress", f"data.path={two_scenes}", f"out={runs}", *TINY,
                 "model.labels.bin_edges=[1,50]", "model.labels.num_classes=2"]) == 2
    assert one_line_error() == (
        "frontiernet train: error: model.labels.bin_edges: gain classes of bin edges [1, 50] x 0.01 m^3, the "
        "dataset's [1, 50, 150, 300, 450, 750, 1000, 1500, 2000, 2500, 3500] x 0.01 m^3 (datagen ground_truth.gain); "
        "give the dataset's (model.labels.num_classes: as many), or train on a dataset made with yours")
    assert not runs.exists()
    import json
    import shutil

    other = tmp_path / "other"  # the shipped model on a dataset of other classes: its gain Dice compares other ones
    shutil.copytree(two_scenes, other, ignore=shutil.ignore_patterns("cache"))
    info = json.loads((other / "dataset.json").read_text())
    info["config"]["ground_truth"]["gain"]["bin_unit_m3"] = 0.02
    (other / "dataset.json").write_text(json.dumps(info))
    model = model_with(tmp_path, 0.0)
    assert main(["evaluate", str(model), "--data", str(other), "--all"]) == 2
    assert f"{other}: the model ({model}) has gain classes of bin edges [1, 50, " in one_line_error()


def test_a_dataset_missing_a_shard_it_lists_is_refused_naming_it(two_scenes, tmp_path, one_line_error):
    # eighth probe (E5): trained and evaluated on the other scenes without a word
    import json
    import shutil

    from train.data import open_training_data

    partial = tmp_path / "partial"
    shutil.copytree(two_scenes, partial, ignore=shutil.ignore_patterns("cache"))
    (partial / "shards" / "00001-procedural-4-0000.zip").unlink()
    message = (f"{partial}: shard 00001-procedural-4-0000.zip of scene procedural:4 is missing from {partial / 'shards'} "
               "(1 of the shards its dataset.json plans: deleted, or a run that did not finish); make them with the "
               "dataset's `frontiernet datagen` command and --resume")
    runs = tmp_path / "runs"
    assert main(["train", "--no-progress", f"data.path={partial}", f"out={runs}", *TINY]) == 2
    assert one_line_error() == f"frontiernet train: error: {message}"
    assert not runs.exists()
    assert main(["evaluate", str(model_with(tmp_path, 0.0)), "--data", str(partial), "--all"]) == 2
    assert one_line_error() == f"frontiernet evaluate: error: {message}"
    # a scene its run reported failed (summary.json) made no shard, and the run said so: the rest is the dataset
    summary = json.loads((partial / "summary.json").read_text())
    summary["failed_scenes"] = [{"scene": "procedural:4", "error": "no view", "bad_input": True}]
    (partial / "summary.json").write_text(json.dumps(summary))
    assert open_training_data(partial).scenes == ["procedural:3"]


def test_evaluate_scenes_named_twice_count_once_and_an_empty_one_is_refused(two_scenes, tmp_path, capsys,
                                                                          one_line_error):
    # eighth probe: a scene named twice was counted twice, "on 1 views of 2 given scene(s)" (E14); '' was refused
    # after the data load, "scene(s) not in the dataset: " naming nothing (E31)
    model = str(model_with(tmp_path, 0.0))
    assert main(["evaluate", model, "--data", str(two_scenes), "--scenes", "", "--max-samples", "1"]) == 2
    assert one_line_error().endswith("error: --scenes: an empty scene spec (item 1 of the 1 given); give the dataset's "
                                     "scene specs as separate words, e.g. --scenes procedural:3 procedural:4")
    assert main(["evaluate", model, "--data", str(two_scenes), "--scenes", "procedural:3", "procedural:3",
                 "--max-samples", "1", "--size", "64"]) == 0
    assert "on 1 views of 1 given scene(s)" in capsys.readouterr().out


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs /proc, a folder no file can be made in")
def test_a_training_cache_where_nothing_can_be_written_is_refused_not_waited_on(two_scenes, tmp_path,
                                                                              one_line_error):
    # issue 55's fourth probe: data.cache=/proc/c waited forever for the lock beside it (a hang)
    runs = tmp_path / "runs"
    assert main(["train", "--no-progress", f"data.path={two_scenes}", f"out={runs}", *TINY,
                 "data.cache=/proc/frontiernet-probe-cache"]) == 2
    assert "data.cache: cannot write in /proc" in one_line_error()
    assert not runs.exists()


def test_resuming_from_a_checkpoint_that_cannot_resume_is_refused_before_anything(two_scenes, tmp_path,
                                                                                 one_line_error):
    # {"state_dict": {}} passed the check, then Lightning failed (KeyError 'pytorch-lightning_version', an
    # internal error, exit 1) and left an empty runs/ folder behind
    empty = tmp_path / "emptystate.ckpt"
    torch.save({"state_dict": {}}, empty)
    runs = tmp_path / "runs"
    args = ["train", "--no-progress", f"data.path={two_scenes}", f"out={runs}", *TINY, "--resume"]
    assert main(args + [str(empty)]) == 2
    assert (f"{empty}: not a training checkpoint (no pytorch-lightning_version, optimizer_states, lr_schedulers, "
            "loops, hyper_parameters: nothing to resume from)") in one_line_error()
    # all of Lightning's keys, but weights of no network, or not finite ones
    no_weights = tmp_path / "noweights.ckpt"
    state = torch.load(model_with(tmp_path, float("nan"), ".ckpt"), weights_only=True)
    torch.save({**state, "state_dict": {}}, no_weights)
    assert main(args + [str(no_weights)]) == 2
    assert f"{no_weights}: weights do not fit a resnet18/rgbd FrontierNet" in one_line_error()
    assert main(args + [str(tmp_path / "model.ckpt")]) == 2
    assert f"{tmp_path / 'model.ckpt'}: weights are not all finite" in one_line_error()
    assert not runs.exists()


@pytest.mark.parametrize("argv, flag, what", [
    (["train", "--no-progress", "data.path=d", "out=o", "--resume"], "--resume", "checkpoint"),
    (["explore", "--scene", "procedural:3", "--out", "o", "--show-prediction"], "--show-prediction", "predictor file"),
])
def test_an_override_after_an_option_of_an_optional_file_is_named_as_one(argv, flag, what, tmp_path, monkeypatch,
                                                                         one_line_error):
    # eighth probe (E18): "optim.lr=0.1: checkpoint to resume from not found", the override taken for the file
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as stop:  # (argparse's usage error)
        main([*argv, "optim.lr=0.1"])
    assert stop.value.code == 2
    assert one_line_error().endswith(f"error: argument {flag}: took the config override optim.lr=0.1 for its {what}; "
                                     f"give the overrides before {flag} (or a {what} after it)")
    assert list(tmp_path.iterdir()) == []


def test_a_run_that_fails_before_its_first_step_leaves_no_folder_it_made(two_scenes, tmp_path, monkeypatch):
    # the run folder was removed, but not the folders above it that the run made (out=runs/deep)
    import lightning as L

    from train.config import load_train_config
    from train.main import main as train

    def fail(*args, **kwargs):
        raise RuntimeError("boom")

    monkeypatch.setattr(L.Trainer, "fit", fail)
    (tmp_path / "kept").mkdir()
    for out in (tmp_path / "runs" / "deep", tmp_path / "kept"):
        conf = load_train_config(overrides=[f"data.path={two_scenes}", f"out={out}", *TINY])
        with pytest.raises(RuntimeError, match="boom"):
            train(conf, progress=False)
    assert not (tmp_path / "runs").exists()
    assert list((tmp_path / "kept").iterdir()) == []  # a folder that was there stays


@pytest.mark.parametrize("overrides", [["optim.lr=1e30"], ["model.input.rgb_std=[1e-30,1e-30,1e-30]"]],
                         ids=["the loss", "a BatchNorm variance"])
def test_a_run_that_stops_being_finite_ends_at_once_in_one_line_and_saves_no_diverged_weights(two_scenes, tmp_path,
                                                                                              overrides, capsys,
                                                                                              monkeypatch):
    # it trained to its end on NaN and failed only when writing the weights, in 19 lines, leaving runs/tiny
    import logging
    import sys

    loggers = [logging.getLogger(), *(logger for logger in logging.Logger.manager.loggerDict.values()
                                      if isinstance(logger, logging.Logger))]
    for handler in (handler for logger in loggers for handler in logger.handlers):  # made on an earlier test's
        if type(handler) is logging.StreamHandler:  # captured stderr (Lightning's, at import), since closed
            monkeypatch.setattr(handler, "stream", sys.stderr)  # (setStream would flush the closed one; put back
            # after the test, whose capture closes with it)
    runs = tmp_path / "runs"
    assert main(["train", "--no-progress", f"data.path={two_scenes}", f"out={runs}", "name=tiny",
                 *[item for item in TINY if item != "trainer.max_steps=1"], "trainer.max_steps=6",
                 "trainer.checkpoint_every_n_epochs=100", "model.network.pretrained=false", *overrides]) == 2
    err = capsys.readouterr().err  # Lightning's INFO lines as the run started, then the run's end in one line
    message = err.strip().splitlines()[-1]
    assert "Traceback" not in err and message.startswith("frontiernet train: error: ")
    assert sum(not line.startswith("INFO: ") for line in err.strip().splitlines()) == 1
    assert " became " in message and "the settings make training diverge" in message  # (the loss or a weight)
    assert overrides[0].split("=")[0] in message  # the key that usually causes it, with its value
    step = int(message.split(" at step ")[1].split()[0])
    kept = sorted(runs.rglob("*.ckpt"))
    if not kept:
        assert not runs.exists()  # no checkpoint to resume from: nothing left behind
    for path in kept:  # the checkpoints of before (its first epoch's best), never the diverged weights
        state = torch.load(path, map_location="cpu", weights_only=True)
        assert state["global_step"] < step and path.name != "last.ckpt"
        assert all(torch.isfinite(value).all() for value in state["state_dict"].values() if value.is_floating_point())


def test_bench_train_refuses_a_worker_count_given_twice(tmp_path, one_line_error):
    # --workers 0 0 timed the same loader twice (--encoders of bench inference refuses a repeated name)
    assert main(["bench", "train", f"data.path={tmp_path / 'no_data'}", "--workers", "0", "0", "--batches", "1",
                 "--steps", "1", "--no-baseline"]) == 2
    assert "--workers must list distinct worker counts, got 0 0" in one_line_error()


@pytest.mark.parametrize("value", [float("nan"), float("inf")])
def test_a_model_file_with_weights_that_are_not_finite_is_refused_when_read(tmp_path, value, one_line_error):
    # a model of NaN weights exported, and predicted 0 frontier pixels with a numpy RuntimeWarning
    path = model_with(tmp_path, value)
    out = tmp_path / "m.onnx"
    assert main(["export", str(path), "--format", "onnx", "--out", str(out)]) == 2
    message = one_line_error()
    assert message == (f"frontiernet export: error: {path}: weights are not all finite ({FIRST} holds NaN or "
                       "infinity); the model file is damaged or its training diverged")
    assert not out.exists()
    from frontiernet.model import load_model

    with pytest.raises(InputError, match="weights are not all finite"):  # a checkpoint alike
        load_model(model_with(tmp_path, value, ".ckpt"))

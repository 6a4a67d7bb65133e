"""Training: labels at the training resolution, augmentations that keep labels consistent, the
loss and Table II metrics, a scene-held-out split, and `frontiernet train` / `evaluate` end to end
(the loss falls, Ctrl-C leaves a resumable checkpoint, bad input exits 2 with one line)."""

from __future__ import annotations

import csv
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from conftest import REPO_ROOT
from datagen import open_dataset
from datagen.labels import distance_field
from frontiernet.cli.main import main
from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.model import encode_distance, load_model
from train.data import split_scenes
from train.losses import dice_loss, frontier_loss
from train.metrics import DistanceError, FrontierCurves, GainDice, depth_jump_score
from train.packed import pack_sample, unpack_distance
from train.transforms import resample_mask, training_item, training_sample

LABELS = OmegaConf.to_container(load_config("model").labels)
TRAIN_LOSS = OmegaConf.to_container(load_config("train").loss)


def frontier_sample(dataset):
    """The first sample of the dataset with frontier pixels."""
    for index in range(len(dataset)):
        sample = dataset[index]
        if sample["frontier_mask"].sum() > 20:
            return sample
    pytest.fail("the tiny dataset has no view with frontier pixels")


def test_native_size_labels_are_the_datasets(tiny_dataset):
    sample = frontier_sample(open_dataset(tiny_dataset))
    ts = training_sample(sample, None, LABELS)
    assert np.array_equal(ts["frontier"], sample["frontier_mask"])
    assert np.array_equal(ts["gain_class"], sample["gain_class"])
    assert np.allclose(ts["distance"], sample["distance_field"])
    assert np.isnan(sample["depth"]).any() == (ts["depth"] == 0).any() and np.isfinite(ts["depth"]).all()


def test_resampled_labels_are_recomputed_in_pixels_of_the_new_size(tiny_dataset):
    sample = frontier_sample(open_dataset(tiny_dataset))
    ts = training_sample(sample, 64, LABELS)
    assert ts["rgb"].shape == (64, 64, 3) and ts["distance"].shape == (64, 64)
    assert ts["frontier"].any()
    # D is the exact distance to the resampled F, truncated at r pixels of the new image
    assert np.allclose(ts["distance"], distance_field(ts["frontier"], LABELS["truncation_px"]))
    # the gain band is where D < r, and carries the classes present at full size
    band = ts["gain_class"] > 0
    assert (ts["distance"][band] < LABELS["truncation_px"]).all()
    assert set(np.unique(ts["gain_class"][band])) <= set(np.unique(sample["gain_class"][sample["gain_class"] > 0]))
    # every full-size frontier pixel has a resampled pixel where its centre falls
    v, u = np.nonzero(sample["frontier_mask"])
    assert ts["frontier"][((v + 0.5) * 64 / 96).astype(int), ((u + 0.5) * 64 / 96).astype(int)].all()


def test_flip_and_crop_keep_labels_consistent(tiny_dataset):
    ts = training_sample(frontier_sample(open_dataset(tiny_dataset)), None, LABELS)
    view = pack_sample(ts, LABELS["truncation_px"])
    augment = {**OmegaConf.to_container(load_config("train").augment), "crop_size": 48, "hflip": 1.0}
    item = training_item(view, augment, np.random.default_rng(1))
    rng = np.random.default_rng(1)
    top, left = int(rng.integers(0, 96 - 48 + 1)), int(rng.integers(0, 96 - 48 + 1))
    window = (slice(top, top + 48), slice(left, left + 48))
    distance = unpack_distance(item["distance_sq"].numpy(), LABELS["truncation_px"])
    # a crop keeps pixel scale: its distances are the full image's (F outside the crop still counts),
    # and a flip mirrors image and labels together
    assert np.allclose(distance, ts["distance"][window][:, ::-1])
    assert np.array_equal(item["gain_class"].numpy(), ts["gain_class"][window][:, ::-1])
    assert np.array_equal(item["rgb"].numpy().transpose(1, 2, 0), ts["rgb"][window][:, ::-1])
    assert np.allclose(item["depth"].numpy(), ts["depth"][window][:, ::-1], atol=5e-4)
    frontier = (item["masks"].numpy() & 1) > 0
    assert np.array_equal(frontier, ts["frontier"][window][:, ::-1])
    # without augmentation the item is the whole view, unflipped, with neutral jitter
    plain = training_item(view)
    assert np.array_equal(plain["gain_class"].numpy(), ts["gain_class"]) and (plain["jitter"] == 1).all()


def test_emulated_depth_in_training_sees_the_far_depth_as_the_explorer_does(tiny_dataset):
    """A monocular source in training gets the surfaces beyond the sensor's range (datagen's
    far_depth), as the explorer gives it Frame.hit_depth: far pixels come out near their true
    depth, not at the fill depth of a range-clipped ground truth."""
    from frontiernet.config import load_config
    from frontiernet.depth import make_depth_source

    dataset = open_dataset(tiny_dataset)
    sample = next(dataset[i] for i in range(len(dataset))
                  if dataset[i]["far_depth"] is not None and np.isfinite(dataset[i]["far_depth"]).mean() > 0.05)
    ts = training_sample(sample, None, LABELS)
    far = ts["far_depth"] > 0
    assert far.any() and not (far & (ts["depth"] > 0)).any()
    conf = load_config("depth")
    conf.emulated.update(scale_sigma=0.0, noise_sigma=0.0, noise_sigma_per_m=0.0, edge_band_px=0, blur_sigma_px=0.0)
    source = make_depth_source("emulated", conf)
    assert source.sees_past_range
    view = pack_sample(ts, LABELS["truncation_px"])
    source.reset(0)
    estimate = training_item(view, depth_source=source)["depth"].numpy()
    assert np.allclose(estimate[far], ts["far_depth"][far], atol=2e-3)
    source.reset(0)
    clipped = training_item({**view, "far_depth_mm": np.zeros_like(view["far_depth_mm"])}, depth_source=source)
    assert np.allclose(clipped["depth"].numpy()[far], float(conf.emulated.fill_depth))


def test_resample_mask_sets_the_pixel_each_centre_falls_in():
    mask = np.zeros((6, 6), bool)
    mask[0, 0] = mask[5, 5] = mask[2, 3] = True
    small = resample_mask(mask, (3, 3))
    assert small.sum() == 3 and small[0, 0] and small[2, 2] and small[1, 1]


def test_split_is_by_scene_and_checks_names():
    scenes = [f"procedural:{i}" for i in range(20)]
    train, val = split_scenes(scenes, None, 0.1, seed=0)
    assert len(val) == 2 and not set(train) & set(val) and len(train) + len(val) == 20
    assert split_scenes(scenes, None, 0.1, seed=0) == (train, val)
    assert split_scenes(scenes, ["procedural:3"], 0.1, 0)[1] == ["procedural:3"]
    with pytest.raises(InputError, match="'house' is not a scene of the dataset"):
        split_scenes(scenes, ["house"], 0.1, 0)
    with pytest.raises(InputError, match="needs two or more"):
        split_scenes(scenes[:1], None, 0.1, 0)


def test_loss_is_lowest_for_the_right_answer():
    torch.manual_seed(0)
    distance_px = torch.full((2, 16, 16), 10.0)
    distance_px[:, 8, :] = 0.0
    distance_px[:, 7, :] = distance_px[:, 9, :] = 1.0
    gain_class = torch.zeros(2, 16, 16, dtype=torch.long)
    gain_class[:, 6:11] = 4
    batch = {"distance": distance_px, "gain_class": gain_class}
    perfect_y = encode_distance(distance_px, LABELS)[:, None]
    perfect_logits = torch.nn.functional.one_hot(gain_class, 11).permute(0, 3, 1, 2).float() * 20
    best = frontier_loss(perfect_y, perfect_logits, batch, TRAIN_LOSS, LABELS)
    noisy = frontier_loss(perfect_y + 0.5 * torch.rand_like(perfect_y), torch.randn(2, 11, 16, 16), batch,
                          TRAIN_LOSS, LABELS)
    assert best["distance"] < 1e-6 and best["dice"] < 0.01 and best["loss"] < noisy["loss"]
    assert dice_loss(perfect_logits, gain_class) < dice_loss(torch.zeros_like(perfect_logits), gain_class)


def test_metrics_of_a_perfect_and_a_shifted_prediction():
    frontier = torch.zeros(1, 32, 32, dtype=torch.bool)
    frontier[0, 10:20, 16] = True
    distance = torch.from_numpy(distance_field(frontier[0].numpy(), 10.0))[None]
    depth = torch.full((1, 32, 32), 2.0)
    depth[0, :, 17:] = 4.0  # a depth jump along the frontier ...
    depth[0, 25, :] = 1.0   # ... and a thin object that is no frontier
    error, curves = DistanceError(10.0), FrontierCurves()
    error.update(distance, distance)
    curves.update(distance, frontier, depth)
    result = {**error.compute(), **curves.compute()}
    assert result["df_error_px"] == 0
    assert result["frontier_precision"] == 1 and result["frontier_recall"] == 1
    assert result["fd_recall"] == 1 and result["fd_precision"] < 1  # F_d also fires on the thin object
    shifted = DistanceError(10.0)
    shifted.update(torch.roll(distance, 3, dims=2), distance)
    assert shifted.compute()["df_error_px"] > 0.5
    dice = GainDice(11)
    labels = torch.zeros(1, 8, 8, dtype=torch.long)
    labels[0, :4] = 3
    dice.update(labels, labels)
    assert dice.compute()["gain_dice"] == 1
    wrong = GainDice(11)
    wrong.update(torch.where(labels > 0, 5, 0), labels)
    assert wrong.compute()["gain_dice"] == 0
    assert depth_jump_score(depth)[0, 10, 16] > 0.1 > depth_jump_score(depth)[0, 5, 5]


def test_channels_last_changes_the_memory_order_not_the_numbers():
    from train.main import channels_last_wanted
    from train.module import FrontierNetModule

    model = OmegaConf.to_container(load_config("model"))
    model["network"]["pretrained"] = None
    optim = OmegaConf.to_container(load_config("train").optim)
    module = FrontierNetModule(model=model, train={"loss": TRAIN_LOSS, "optim": optim})
    module.eval()
    image = torch.randn(2, 4, 64, 64, generator=torch.Generator().manual_seed(0))
    with torch.no_grad():
        reference = module.net(image)
        module.use_channels_last(True)
        weight = next(p for p in module.net.parameters() if p.dim() == 4)
        assert weight.is_contiguous(memory_format=torch.channels_last) and not weight.is_contiguous()
        nhwc = module.net(image.contiguous(memory_format=torch.channels_last))
    for a, b in zip(reference, nhwc):
        assert torch.allclose(a, b, atol=1e-4, rtol=1e-4)
    assert channels_last_wanted(OmegaConf.create({"channels_last": "auto", "accelerator": "cpu"})) is False
    assert channels_last_wanted(OmegaConf.create({"channels_last": True, "accelerator": "cpu"})) is True
    with pytest.raises(InputError, match="trainer.channels_last: must be true, false or auto, got 'maybe'"):
        channels_last_wanted(OmegaConf.create({"channels_last": "maybe", "accelerator": "cpu"}))


def test_a_ctrl_c_during_the_batch_transform_stays_a_keyboard_interrupt(tiny_dataset, monkeypatch):
    """Ctrl-C lands between two Python bytecodes. Inside omegaconf's ``__getitem__``, called by
    ``torch.tensor`` on a config list, it came out as torch's ValueError and the run died without
    its interrupt checkpoint: the per-batch transform must run no config code at all."""
    from types import SimpleNamespace

    from omegaconf import DictConfig, ListConfig

    from train.config import load_train_config
    from train.data import FrontierDataModule

    conf = load_train_config(REPO_ROOT / "configs" / "train_tiny.yaml", [f"data.path={tiny_dataset}"])
    datamodule = FrontierDataModule(conf, progress=False)
    datamodule.setup()
    batch = next(iter(datamodule.train_dataloader()))

    def ctrl_c(*args, **kwargs):
        raise KeyboardInterrupt

    for node in (DictConfig, ListConfig):
        monkeypatch.setattr(node, "__getitem__", ctrl_c)
        monkeypatch.setattr(node, "__getattr__", ctrl_c)
    datamodule.trainer = SimpleNamespace(training=True)  # the augmented path too
    training = datamodule.on_after_batch_transfer(dict(batch), 0)
    datamodule.trainer = None
    validation = datamodule.on_after_batch_transfer(dict(batch), 0)
    for network_input in (training["image"], validation["image"]):
        assert network_input.shape[:2] == (len(batch["rgb"]), 4) and torch.isfinite(network_input).all()


def train_losses(run: Path) -> list[float]:
    with open(run / "metrics.csv") as handle:
        return [float(row["train/loss"]) for row in csv.DictReader(handle) if row.get("train/loss")]


@pytest.mark.slow
def test_train_tiny_config_loss_falls_then_evaluate_and_resume(tiny_dataset, tmp_path, capsys, one_line_error):
    args = ["train", "--config", str(REPO_ROOT / "configs" / "train_tiny.yaml"), "--no-progress",
            f"data.path={tiny_dataset}", f"out={tmp_path}", "name=tiny", "trainer.max_epochs=6"]
    assert main(args) == 0
    run = tmp_path / "tiny"
    losses = train_losses(run)
    assert len(losses) >= 8
    assert np.mean(losses[-3:]) < 0.8 * np.mean(losses[:3]), losses
    for name in ("checkpoints/last.ckpt", "checkpoints/best.ckpt", "model.safetensors", "summary.json",
                 "config.yaml"):
        assert (run / name).is_file(), name
    model, conf = load_model(run / "model.safetensors")
    assert conf["info"]["val_scenes"] and conf["info"]["train_scenes"] == 2
    assert conf["labels"]["gain_definition"] == "unobserved/blend"  # the dataset's, recorded
    # the final weights are validated too (epoch 6 is not a validation epoch of the tiny config)
    with open(run / "metrics.csv") as handle:
        validated = [int(row["step"]) for row in csv.DictReader(handle) if row.get("val/loss")]
    assert len(validated) == 2 and validated[-1] >= conf["info"]["steps"] - 1, validated
    capsys.readouterr()
    # evaluate picks the held-out scene recorded in the model file
    assert main(["evaluate", str(run / "model.safetensors"), "--data", str(tiny_dataset),
                 "--json", str(tmp_path / "eval.json")]) == 0
    report = capsys.readouterr().out
    assert "held-out scene" in report and "DF error (px)" in report and "gain Dice" in report
    # the same run is refused without --resume, and continued with it
    assert main(args) == 2
    assert "--resume" in one_line_error()
    steps = load_model(run / "checkpoints" / "last.ckpt")[1]["info"]["steps"]
    assert main(args[:-1] + ["trainer.max_epochs=7", "--resume"]) == 0
    assert load_model(run / "checkpoints" / "last.ckpt")[1]["info"]["steps"] > steps
    with open(run / "metrics-part1.csv") as handle:  # the first session's rows survive the resume
        assert len([row for row in csv.DictReader(handle) if row.get("train/loss")]) == len(losses)
    # fine-tuning: a new run starts from the model file's weights and architecture, not from scratch;
    # a network asked for on the command line that the file does not have is refused, not dropped
    fine_args = args[:-1] + ["name=fine", "trainer.max_epochs=1", f"init_weights={run / 'model.safetensors'}"]
    capsys.readouterr()
    assert main(fine_args + ["model.network.encoder=resnet34"]) == 2
    assert "model.network.encoder: resnet34, but the run starts from init_weights's resnet18" in capsys.readouterr().err
    assert main(fine_args) == 0
    fine = train_losses(tmp_path / "fine")
    assert fine[0] < 0.8 * np.mean(losses[:3]), (fine[:3], losses[:3])
    fine_model, fine_conf = load_model(tmp_path / "fine" / "model.safetensors")
    assert fine_conf["network"]["encoder"] == "resnet18"
    assert fine_conf["info"]["init_weights"] == str(run / "model.safetensors")


@pytest.mark.slow
def test_time_horizon_ends_the_cosine_at_max_time(tiny_dataset, tmp_path, monkeypatch):
    # a wall-clock budget (a lent GPU's 10 minutes) ends with a decayed rate, not cut mid-cosine
    import lightning.pytorch.callbacks.timer as timer_module

    class Clock:  # the trainer's Timer reads this clock: each reading is 0.5 s later, so the 20 s
        now = 0.0  # budget lasts a dozen steps or so on any machine, however loaded (no timing in tests)

        @classmethod
        def monotonic(cls) -> float:
            cls.now += 0.5
            return cls.now

    monkeypatch.setattr(timer_module, "time", Clock)
    args = ["train", "--config", str(REPO_ROOT / "configs" / "train_tiny.yaml"), "--no-progress",
            f"data.path={tiny_dataset}", f"out={tmp_path}", "trainer.max_epochs=100000",
            "trainer.max_time=00:00:00:20", "optim.warmup_steps=1"]  # warm-up done at once: few steps suffice
    for horizon in ("time", "steps"):
        assert main(args + [f"name={horizon}", f"optim.horizon={horizon}"]) == 0
        with open(tmp_path / horizon / "metrics.csv") as handle:
            rates = [float(row["lr-AdamW"]) for row in csv.DictReader(handle) if row.get("lr-AdamW")]
        assert len(rates) >= 3
        peak = max(rates)  # 3e-3 after warm-up, the tiny config's lr
        # the last rate logged is that of the last step begun before the budget ran out, near the
        # end of the cosine with the time horizon, near its start with the steps one
        assert rates[-1] < 0.5 * peak if horizon == "time" else rates[-1] > 0.9 * peak, (horizon, rates[-5:])
    # the time horizon needs the time
    assert main([a for a in args if not a.startswith("trainer.max_time")] + ["name=none", "optim.horizon=time"]) == 2


@pytest.mark.slow
def test_ctrl_c_leaves_a_resumable_checkpoint(tiny_dataset, tmp_path):
    arguments = ["train", "--config", str(REPO_ROOT / "configs" / "train_tiny.yaml"), "--no-progress",
                 f"data.path={tiny_dataset}", f"out={tmp_path}", "name=stop", "trainer.max_epochs=1000"]
    # The run as a terminal starts it, Ctrl-C raising KeyboardInterrupt. A suite started in the
    # background (`nohup make test &`) has SIGINT ignored, children inherit that, and Python then
    # installs no Ctrl-C handler: the run rightly ignored the SIGINT and the test hung
    foreground = ("import signal, sys; from frontiernet.cli.main import main; "
                  "signal.signal(signal.SIGINT, signal.default_int_handler); sys.exit(main(sys.argv[1:]))")
    command = [sys.executable, "-c", foreground, *arguments]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    metrics = tmp_path / "stop" / "metrics.csv"
    deadline = time.time() + 600  # Ctrl-C *during training*: wait until it logs losses

    def training() -> bool:
        return metrics.is_file() and len(train_losses(tmp_path / "stop")) >= 3

    while time.time() < deadline and process.poll() is None and not training():
        time.sleep(0.5)
    if not training():
        process.kill()
        pytest.fail(f"training logged no losses (exit code {process.wait()}): {process.stderr.read()[-2000:]}")
    process.send_signal(signal.SIGINT)
    try:
        _, err = process.communicate(timeout=300)  # a hang guard: a loaded machine may take a while
    except subprocess.TimeoutExpired:
        # say which hang it was
        state = ("still running" if process.poll() is None else
                 f"exited ({process.returncode}) but something kept its output pipes open")
        process.kill()
        try:
            _, err = process.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            err = "(output pipes still open)"
        pytest.fail(f"training did not stop within 300 s of SIGINT: {state}; stderr: {err[-2000:]}")
    finally:
        if process.poll() is None:  # never leave a training run behind
            process.kill()
            process.wait()
    assert process.returncode == 130, err[-2000:]
    assert "interrupted" in err
    last = tmp_path / "stop" / "checkpoints" / "last.ckpt"
    assert last.is_file()
    steps = load_model(last)[1]["info"]["steps"]
    assert steps > 0
    resumed = subprocess.run(command[:-1] + [f"trainer.max_steps={steps + 4}", "--resume"], capture_output=True,
                             text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    assert load_model(last)[1]["info"]["steps"] == steps + 4


def test_bad_training_input_is_one_line_exit_2(tmp_path, capsys, one_line_error):
    assert main(["train", f"out={tmp_path}"]) == 2
    assert "data.path is not set" in one_line_error()
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["train", f"data.path={empty}", f"out={tmp_path}"]) == 2
    assert str(empty) in one_line_error()
    assert main(["train", f"data.path={tmp_path / 'missing'}", f"out={tmp_path}"]) == 2
    assert "dataset folder not found" in one_line_error()
    assert main(["evaluate", str(tmp_path / "none.ckpt"), "--data", str(empty)]) == 2
    assert "none.ckpt: model file not found" in one_line_error()
    assert main(["train", "--config", str(tmp_path / "nope.yaml"), f"data.path={empty}"]) == 2
    assert "nope.yaml: config file not found" in one_line_error()


@pytest.mark.slow
def test_a_model_and_a_dataset_of_other_gain_definitions_are_refused(tiny_dataset, tmp_path, one_line_error):
    import json
    import shutil

    other = tmp_path / "occluded"  # the same views, labelled (say) with datagen's occluded gain volume
    shutil.copytree(tiny_dataset, other, ignore=shutil.ignore_patterns("cache"))
    info = json.loads((other / "dataset.json").read_text())
    info["config"]["ground_truth"]["gain"]["volume"] = "occluded"
    (other / "dataset.json").write_text(json.dumps(info))
    args = ["train", "--config", str(REPO_ROOT / "configs" / "train_tiny.yaml"), "--no-progress", f"data.path={other}",
            f"out={tmp_path}", "trainer.max_epochs=1"]
    assert main(args + ["name=a", "model.labels.gain_definition=unobserved/blend"]) == 2
    assert "model.labels.gain_definition: unobserved/blend" in one_line_error()
    assert main(args + ["name=b", "init_weights=default"]) == 2  # the shipped model: made before, unobserved/blend
    assert "init_weights: default was trained on gain definition unobserved/blend" in one_line_error()
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists() and not (other / "cache").exists()
    from frontiernet.model import default_model_path

    assert main(["evaluate", str(default_model_path()), "--data", str(other), "--all", "--max-samples", "2"]) == 2
    assert "holds gain labels of definition occluded/blend" in one_line_error()

"""Bad input of the tenth probe of issue 55 (docs/bad_input.md), its N10-N14, N17, N18 and a data.image_size within
the encoder's stride: each refusal one line, exit code 2, nothing left; each test failed before its fix."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys

import pytest

from conftest import REPO_ROOT
from frontiernet.cli.main import main

TINY = str(REPO_ROOT / "configs/train_tiny.yaml")


def train_args(data, out, *overrides):
    return ["train", "--no-progress", "--config", TINY, f"data.path={data}", f"out={out}", *overrides]


@pytest.mark.parametrize("key", ["scale_sigma", "noise_sigma", "noise_sigma_per_m"])
def test_emulated_depth_noise_larger_than_the_depth_is_refused(key, tmp_path, one_line_error):
    # N11: 3e38 printed numpy's overflow warnings and mapped inf / NaN depth (exit 0)
    assert main(["explore", "--scene", "procedural:3", "--max-steps", "4", "--no-video", "--depth", "emulated",
                 "--out", str(tmp_path / "o"), f"depth.emulated.{key}=3e38"]) == 2
    assert f"depth.emulated.{key} must be a number in [0, 1], got 3e+38" in one_line_error()
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("key", ["nbvp.gain_range_m", "tracking.gain_view.max_depth_m"])
def test_a_gain_view_reaching_past_any_camera_is_refused(key, tmp_path, one_line_error):
    # N12: 3e38 m gave invalid-cast warnings (the map's int64 voxel indices), exit 0
    assert main(["explore", "--scene", "procedural:3", "--max-steps", "4", "--no-video", "--method", "nbvp",
                 "--out", str(tmp_path / "o"), f"{key}=3e38"]) == 2
    assert f"{key} must be a number in (0, 100], got 3e+38" in one_line_error()
    assert not (tmp_path / "o").exists()


def test_scene_sizes_past_float32_are_refused_without_numpy_warnings(tmp_path, one_line_error):
    # N13: a texture repeat of 1.2e-38 m (exit 0) and a mesh scale of 3e38 printed numpy's cast warnings
    import trimesh

    assert main(["scene", "info", "procedural:3?texture_size_m=1.2e-38"]) == 2
    assert "procedural option texture_size_m must be a number in [0.01, 100], got 1.2e-38" in one_line_error()
    trimesh.creation.box(extents=(6.0, 4.0, 3.0)).export(tmp_path / "box.glb")
    (tmp_path / "c.yaml").write_text("scenes:\n  mesh:\n    scale: 3.0e38\n")
    assert main(["scene", "info", str(tmp_path / "box.glb"), "--config", str(tmp_path / "c.yaml")]) == 2
    assert "scenes.mesh.scale must be a number in (0, 1000000], got 3e+38" in one_line_error()
    trimesh.creation.box(extents=(6e33, 4e33, 3e33)).export(tmp_path / "huge.glb")  # in range, past float32 scaled
    assert main(["scene", "info", f"mesh:{tmp_path / 'huge.glb'}?scale=1e6"]) == 2
    assert "8 vertices are NaN or infinite" in one_line_error()


def test_a_dataset_description_that_is_a_folder_is_refused(two_scenes, tmp_path, one_line_error):
    # N14: taken for no dataset.json (the shards' metas stood in) and trained on, while a 0-byte one is refused
    data = tmp_path / "data"
    shutil.copytree(two_scenes, data)
    (data / "dataset.json").unlink()
    (data / "dataset.json").mkdir()
    assert main(train_args(data, tmp_path / "runs", "data.batch_size=1")) == 2
    assert f"{data / 'dataset.json'}: is a folder, expected a file (dataset description)" in one_line_error()
    assert not (tmp_path / "runs").exists()


def test_a_shard_that_is_no_regular_file_is_named_so_not_missing(two_scenes, tmp_path, one_line_error):
    # N17: a FIFO shard or a link to /dev/zero was left out of the list, then reported missing
    from frontiernet.model import default_model_path

    data = tmp_path / "data"
    shutil.copytree(two_scenes, data)
    shard = sorted((data / "shards").glob("*.zip"))[0]
    shard.unlink()
    os.mkfifo(shard)
    assert main(train_args(data, tmp_path / "runs")) == 2
    assert f"{shard}: not a regular file, expected a file (dataset shard)" in one_line_error()
    shard.unlink()
    shard.symlink_to("/dev/zero")
    assert main(["evaluate", str(default_model_path()), "--data", str(data), "--all", "--size", "64"]) == 2
    assert f"{shard}: not a regular file, expected a file (dataset shard)" in one_line_error()
    assert not (tmp_path / "runs").exists()


def test_an_empty_or_truncated_checkpoint_to_resume_from_says_so(tmp_path, one_line_error):
    # N18: both were "not a training checkpoint (RuntimeError)"; other inputs say "empty file (0 bytes)"
    import torch

    (tmp_path / "empty.ckpt").write_bytes(b"")
    torch.save({"state_dict": {"net.w": torch.zeros(1000)}}, tmp_path / "full.ckpt")
    data = (tmp_path / "full.ckpt").read_bytes()
    for cut in (len(data) // 2, len(data) - 10):  # (torch: a RuntimeError, then an OSError of mmap)
        (tmp_path / "cut.ckpt").write_bytes(data[:cut])
        assert main(train_args(tmp_path / "none", tmp_path / "runs", "--resume", str(tmp_path / "cut.ckpt"))) == 2
        assert "cut.ckpt: not a training checkpoint (not a PyTorch zip archive, the format frontiernet train " \
               "writes: truncated, or another kind of file)" in one_line_error()
    assert main(train_args(tmp_path / "none", tmp_path / "runs", "--resume", str(tmp_path / "empty.ckpt"))) == 2
    assert "empty.ckpt: empty file (0 bytes), expected a checkpoint to resume from" in one_line_error()
    assert not (tmp_path / "runs").exists()


def test_views_within_the_encoders_stride_in_a_batch_of_one_are_refused_before_the_trainer(tmp_path, one_line_error):
    # data.image_size=32 with batch 1: BatchNorm's "Expected more than 1 value per channel" after the trainer's setup
    # (an internal error), as augment.crop_size was (commit f1ba402); 32 px in a batch of 2 still trains (tests)
    from datagen.config import load_datagen_config
    from datagen.generate import generate

    runs, none = tmp_path / "runs", tmp_path / "none"
    assert main(train_args(none, runs, "augment.crop_size=null", "data.image_size=32", "data.batch_size=1")) == 2
    assert ("data.image_size + 32 * data.batch_size + model.network.pad_multiple > 96 must hold (the encoder's last "
            "stage") in one_line_error()
    for allowed in (["data.batch_size=2"], ["data.batch_size=1", "model.network.pad_multiple=64"]):
        assert main(train_args(none, runs, "augment.crop_size=null", "data.image_size=32", *allowed)) == 2
        assert "dataset folder not found" in one_line_error()  # (past the ranges: refused at the data)
    conf = load_datagen_config(overrides=["camera.width=32", "camera.height=32", "camera.focal_px=20"])
    generate(["procedural:3"], 2, tmp_path / "d32", conf, seed=0, workers=1, progress=False)
    assert main(train_args(tmp_path / "d32", runs, "augment.crop_size=null", "data.batch_size=1")) == 2
    assert "data.image_size: null keeps the dataset's 32 px views, within the encoder's 32 px" in one_line_error()
    assert not runs.exists()


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_during_the_interpreters_teardown_neither_prints_nor_changes_the_exit_code(signum, tmp_path):
    # N10: a Ctrl-C after main() returned raised KeyboardInterrupt in an atexit callback ("Exception ignored in
    # atexit callback" and a traceback; seen in torch's); a SIGTERM there killed the process (exit -15). Sent here
    # from an atexit callback itself: deterministic, no timing
    code = ("import atexit, os, sys, time; from frontiernet.cli.main import main; "
            f"atexit.register(lambda: (os.kill(os.getpid(), {int(signum)}), time.sleep(0.5))); "
            f"sys.argv = ['frontiernet', 'scene', 'info', {str(tmp_path / 'no.glb')!r}]; sys.exit(main())")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert (result.returncode, result.stderr.strip()) == (2, f"frontiernet scene: error: {tmp_path / 'no.glb'}: mesh "
                                                             "file not found")


def test_a_caller_of_main_keeps_its_signal_handlers(tmp_path, capsys):
    # the late signals are ignored only for the process's own command line (argv None), not for main([...])
    handlers = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    assert main(["scene", "info", str(tmp_path / "no.glb")]) == 2
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == handlers

"""Bad input of the tenth probe of issue 55 (docs/bad_input.md): each refusal one line, exit code 2, no
internal error; each test failed before its fix."""

from __future__ import annotations

import io
import shutil
import zipfile

import numpy as np
import pytest

from frontiernet.cli.main import main


def npy_bomb(path, shape=(100_000, 100_000)):
    """A .npy file whose header claims `shape` float32 over 64 bytes of data (37 GiB for the default)."""
    buffer = io.BytesIO()
    np.lib.format.write_array_header_1_0(buffer, {"descr": "<f4", "fortran_order": False, "shape": shape})
    path.write_bytes(buffer.getvalue() + b"\0" * 64)
    return path


def test_an_npy_header_claiming_more_than_the_file_holds_is_refused_before_numpy_allocates(tmp_path, one_line_error):
    import cv2

    cv2.imwrite(str(tmp_path / "rgb.png"), np.full((48, 64, 3), 128, np.uint8))
    bomb = npy_bomb(tmp_path / "depth.npy")
    assert main(["predict", "--image", str(tmp_path / "rgb.png"), "--depth", str(bomb), "--out", str(tmp_path / "o")]) == 2
    assert ("depth.npy: not a readable .npy array (its header claims a 100000x100000 float32 array of "
            "40,000,000,000 bytes, the file holds 64: truncated or corrupt)") in one_line_error()
    assert not (tmp_path / "o").exists()
    assert main(["scene", "info", f"floorplan:{bomb}?resolution=0.05"]) == 2
    assert "its header claims a 100000x100000 float32 array" in one_line_error()


def test_a_whole_npy_file_still_reads(tmp_path):
    from frontiernet.array_files import npy_overclaim, read_npy

    np.save(tmp_path / "a.npy", np.arange(12, dtype=np.float32).reshape(3, 4))
    assert read_npy(tmp_path / "a.npy").sum() == 66
    data = (tmp_path / "a.npy").read_bytes()
    assert npy_overclaim(io.BytesIO(data), len(data)) is None
    assert "of 48 bytes, the file holds 47" in npy_overclaim(io.BytesIO(data[:-1]), len(data) - 1)


def test_a_dataset_shard_holding_such_a_header_is_refused_as_corrupt(two_scenes, tmp_path, one_line_error):
    from frontiernet.model import default_model_path

    data = tmp_path / "data"
    shutil.copytree(two_scenes, data)
    shard = sorted((data / "shards").glob("*.zip"))[0]
    with zipfile.ZipFile(shard) as archive:
        members = {name: archive.read(name) for name in archive.namelist()}
    target = next(name for name in members if name.endswith(".npy"))
    members[target] = npy_bomb(tmp_path / "bomb.npy").read_bytes()
    with zipfile.ZipFile(shard, "w") as archive:
        for name, content in members.items():
            archive.writestr(name, content)
    assert main(["evaluate", str(default_model_path()), "--data", str(data), "--all", "--size", "64"]) == 2
    line = one_line_error()
    assert "its header claims a 100000x100000 float32 array" in line and shard.name in line


def test_output_names_too_long_for_the_system_are_refused_in_one_line(tmp_path, one_line_error):
    """A 300-byte name (datagen, mapgen asked the system about it first: ENAMETOOLONG, an internal error) and a
    path of 5,000 bytes made of legal 200-byte names (explore)."""
    long_name = str(tmp_path / ("L" * 300))
    for argv in (["datagen", "--scenes", "procedural:3", "--views-per-scene", "1", "--no-progress", "--out", long_name],
                 ["mapgen", "--scenes", "procedural:3", "--no-progress", "--out", long_name]):
        assert main(argv) == 2
        assert "a name of 300 bytes in the output path; file systems take at most 255" in one_line_error()
    deep = str(tmp_path.joinpath(*["d" * 200] * 25))
    assert main(["explore", "--scene", "procedural:3", "--max-steps", "4", "--no-video", "--out", deep]) == 2
    assert "bytes; the system takes at most 4,095" in one_line_error()
    assert sorted(tmp_path.iterdir()) == []


@pytest.mark.parametrize("option", ["wall_thickness", "exterior_wall_thickness", "door_clearance", "furniture_gap"])
def test_procedural_lengths_past_any_building_are_refused(option, one_line_error):
    # 3e38 m overflowed the plan's int64 cells (an internal error); every length now has footprint_max's bound
    assert main(["scene", "info", f"procedural:3?{option}=3e38"]) == 2
    assert f"procedural option {option} must be a number in (0, 100], got 3e+38" in one_line_error()


@pytest.mark.parametrize("config, override, message", [
    ("configs/train_tiny.yaml", "optim.lr=3e38", "optim.lr must be a number in (0, 1e+30], got 3e+38"),
    ("configs/train_tiny.yaml", "optim.weight_decay=1e30", "optim.weight_decay must be a number in [0, 100], got 1e+30"),
    ("configs/train_seer.yaml", "optim.lr=1e38", "optim.lr must be a number in (0, 1e+30], got 1e+38"),
])
def test_training_rates_that_overflow_are_refused_before_the_trainer(config, override, message, tmp_path,
                                                                      one_line_error):
    # 3e38 overflowed torch's Adam after the trainer's setup; 1e30 decay diverged, blamed on optim.lr
    from conftest import REPO_ROOT

    assert main(["train", "--no-progress", "--config", str(REPO_ROOT / config), f"data.path={tmp_path / 'none'}",
                 f"out={tmp_path / 'runs'}", override]) == 2
    assert message in one_line_error()
    assert not (tmp_path / "runs").exists()


def test_nbvp_draws_past_memory_are_refused_before_the_scene(tmp_path, one_line_error):
    # each key at its maximum, the product asked for 54 GiB (an internal error); the default draws 201,000
    assert main(["explore", "--scene", "procedural:3", "--max-steps", "4", "--no-video", "--method", "nbvp",
                 "--out", str(tmp_path / "o"), "nbvp.attempts_per_node=10000", "nbvp.cutoff_iterations=2000",
                 "nbvp.init_iterations=2000", "nbvp.yaw_samples=360"]) == 2
    assert "nbvp.yaw_samples <= 50000000 must hold (a planning call draws" in one_line_error()
    assert not (tmp_path / "o").exists()


def test_a_seer_crop_of_too_many_voxels_is_refused_before_training(tmp_path, one_line_error):
    # 512 x 512 x 512 (each side in range) trained for minutes before its first step: a hang to the user
    from conftest import REPO_ROOT

    assert main(["train", "--no-progress", "--config", str(REPO_ROOT / "configs/train_seer.yaml"),
                 f"data.path={tmp_path / 'none'}", f"out={tmp_path / 'runs'}", "predictor.crop_shape=[512,512,512]"]) == 2
    assert "predictor.crop_shape[2] <= 2000000 must hold" in one_line_error()


def test_a_crop_within_the_encoders_stride_is_refused_before_the_trainer(tmp_path, one_line_error):
    # 8 and 16 px crops of batch 1 left one value a channel for BatchNorm: a ValueError after the trainer's setup
    from conftest import REPO_ROOT

    assert main(["train", "--no-progress", "--config", str(REPO_ROOT / "configs/train_tiny.yaml"),
                 f"data.path={tmp_path / 'none'}", f"out={tmp_path / 'runs'}", "data.batch_size=1",
                 "augment.crop_size=16"]) == 2
    assert "augment.crop_size must be an integer in [33, 2048] (or null), got 16" in one_line_error()

"""Bad input to every command (issue 28's probe list, docs/bad_input.md): one line naming the file,
key or value and what is wrong, exit code 2, no traceback, nothing already written lost."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from conftest import check_sigterm_ends_workers
from frontiernet.cli.main import build_parser, main


@pytest.mark.parametrize("argv, dest, value", [
    (["render", "procedural:3", "--pose", "-4.5,-0.5,1.2,0", "--out", "o"], "pose", "-4.5,-0.5,1.2,0"),
    (["render", "procedural:3", "--pose", "-.5,2,1.2,-90", "--out", "o"], "pose", "-.5,2,1.2,-90"),
    (["explore", "--scene", "s", "--start", "-1,2,1.2,-90", "--out", "o"], "start", "-1,2,1.2,-90"),
    (["explore", "--scene", "s", "--seed", "-1", "--out", "o"], "seed", -1),
    (["scene", "topdown", "s", "--cut-height", "-5", "--out", "o.png"], "cut_height", -5.0),
    (["sequence", "--input", "i", "--intrinsics", "-525,525,319.5,239.5", "--out", "o"], "intrinsics",
     "-525,525,319.5,239.5"),
    (["predict", "--image", "i.png", "--intrinsics", "-1,1,1,1", "--out", "o"], "intrinsics", "-1,1,1,1"),
    (["export", "m", "--format", "onnx", "--out", "o", "--frontier-threshold", "-1"], "frontier_threshold", -1.0),
    (["bench", "--scenes", "s", "--seed", "-3", "--out", "o"], "seed", -3),
])
def test_negative_numbers_and_lists_are_option_values_as_written(argv, dest, value):
    # argparse took '-4.5,-0.5,1.2,0' for an unknown option ("expected one argument"); the value is
    # now read and left to the command to judge (a bad one is refused in one line, below)
    assert getattr(build_parser().parse_args(argv), dest) == value


def test_an_unknown_option_is_still_refused_in_one_line(capsys, one_line_error):
    with pytest.raises(SystemExit) as stop:
        build_parser().parse_args(["render", "procedural:3", "--pose", "1,1,1,0", "--out", "o", "--bogus"])
    assert stop.value.code == 2 and "--bogus" in one_line_error()


def test_malformed_yaml_config_names_the_file_and_line(tmp_path, one_line_error):
    config = tmp_path / "bad.yaml"
    config.write_text("camera:\n  width: [1,\n b: }\n")
    for argv in (["scene", "info", "procedural:3", "--config", str(config)],
                 ["explore", "--scene", "procedural:3", "--config", str(config), "--out", str(tmp_path / "e")]):
        assert main(argv) == 2
        assert "bad.yaml: not valid YAML at line 3" in one_line_error()
    assert not (tmp_path / "e").exists()


def test_an_empty_npy_floor_plan_is_one_line(tmp_path, one_line_error):
    (tmp_path / "plan.npy").write_bytes(b"")
    assert main(["scene", "info", f"floorplan:{tmp_path / 'plan.npy'}?resolution=0.05"]) == 2
    assert "plan.npy: not a readable .npy array" in one_line_error()


SMALL_DATAGEN = ["--views-per-scene", "2", "--no-progress", "--set", "camera.width=64", "camera.height=64",
                 "camera.focal_px=40", "writer.shard_size=2"]


@pytest.mark.parametrize("argv, message", [
    (["explore", "--scene", "procedural:3", "--seed=-1", "--max-steps", "1", "--no-video"], "--seed, run.seed"),
    (["explore", "--scene", "procedural:3", "run.seed=-3", "--max-steps", "1", "--no-video"], "got -3"),
    (["bench", "--scenes", "procedural:3", "--seed", "-1", "--max-steps", "4"], "--seed, run.seed"),
    (["bench", "--scenes", "procedural:3", "--depth", "sonar", "--max-steps", "4"], "depth source 'sonar'"),
    (["bench", "--scenes", "procedural:3", "--workers", "0", "--max-steps", "4"], "--workers must be"),
    (["bench", "--scenes", "procedural:3", "--backend", "spark", "--max-steps", "4"], "--backend must be"),
    (["datagen", "--scenes", "procedural:3", *SMALL_DATAGEN, "--workers", "0"], "--workers must be"),
])
def test_bad_run_settings_are_refused_before_anything_is_written(argv, message, tmp_path, one_line_error):
    out = tmp_path / "out"
    assert main([*argv, "--out", str(out)]) == 2
    assert message in one_line_error()
    assert not out.exists()  # a refused run leaves nothing that blocks the next one


def test_datagen_on_ray_without_ray_leaves_nothing(tmp_path, one_line_error):
    import importlib.util

    if importlib.util.find_spec("ray") is not None:
        pytest.skip("Ray is installed here")
    out = tmp_path / "ds"
    assert main(["datagen", "--scenes", "procedural:3", *SMALL_DATAGEN, "--backend", "ray", "--out", str(out)]) == 2
    assert "needs Ray" in one_line_error()
    assert not out.exists()
    assert main(["datagen", "--scenes", "procedural:3", *SMALL_DATAGEN, "--out", str(out)]) == 0  # not blocked


def test_datagen_of_only_bad_scenes_leaves_no_empty_dataset(tmp_path, capsys):
    np.save(tmp_path / "plan.npy", np.zeros((0, 0), np.uint8))
    out = tmp_path / "ds"
    assert main(["datagen", "--scenes", f"floorplan:{tmp_path / 'plan.npy'}?resolution=0.05", *SMALL_DATAGEN,
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "at least 3x3 pixels" in err[-1] and "no view was made" in err[-1] and "Traceback" not in "".join(err)
    assert not out.exists()  # was an empty dataset that refused the next run ("already holds a dataset")


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads worker processes from Linux's /proc")
def test_sigterm_to_datagen_ends_its_workers(tmp_path):
    # 3: the two workers and the manager process of their progress queue
    check_sigterm_ends_workers(["datagen", "--scenes", "procedural:1", "procedural:2", "--views-per-scene", "64",
                                "--out", str(tmp_path / "ds"), "--workers", "2", "--no-progress"], workers=3)

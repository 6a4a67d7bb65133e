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


@pytest.mark.parametrize("option, message", [
    (["--pixel-size", "0"], "pixel size (--pixel-size) must be a positive number"),
    (["--pixel-size", "-0.05"], "got -0.05"),
    (["--pixel-size", "nan"], "got nan"),
    (["--pixel-size", "0.0001"], "give a larger pixel size"),
    (["--cut-height", "-5"], "cut height (--cut-height) must be a positive number"),
])
def test_bad_top_view_settings_are_one_line(plan_spec, tmp_path, one_line_error, option, message):
    assert main(["scene", "topdown", plan_spec, "--out", str(tmp_path / "top.png"), *option]) == 2
    assert message in one_line_error()
    assert not (tmp_path / "top.png").exists()


def test_outputs_are_replaced_only_with_force(plan_spec, tmp_path, capsys, one_line_error):
    view, top = tmp_path / "view", tmp_path / "top.png"
    render = ["render", plan_spec, "--pose", "2.0,1.5,1.2,0", "--out", str(view)]
    topdown = ["scene", "topdown", plan_spec, "--out", str(top)]
    assert main(render) == 0 and main(topdown) == 0
    before = {path: path.read_bytes() for path in [*view.iterdir(), top]}
    (view / "mine.txt").write_text("a file of the user's")
    for argv, name in ((render, "view"), (topdown, "top.png"),
                       (["explore", "--scene", plan_spec, "--out", str(view)], "view"),
                       (["export", "model.safetensors", "--format", "onnx", "--out", str(top)], "top.png")):
        capsys.readouterr()
        assert main(argv) == 2, argv
        error = one_line_error()
        assert name in error and "--force" in error
    assert all(path.read_bytes() == data for path, data in before.items())  # nothing written over
    assert main([*render[:2], "--pose", "2.0,1.5,1.2,90", "--out", str(view), "--force"]) == 0
    assert main([*topdown, "--force", "--pixel-size", "0.1"]) == 0
    assert (view / "depth.npy").read_bytes() != before[view / "depth.npy"] and top.read_bytes() != before[top]
    assert (view / "mine.txt").is_file()


@pytest.mark.parametrize("argv, message", [
    (["export", "{model}", "--format", "onnx", "--out", "{tmp}"], "is a folder; give the output's file name"),
    (["export", "{model}", "--format", "onnx", "--half", "--out", "{tmp}/m.onnx"], "--half writes float16 safetensors"),
    (["predict", "--image", "{tmp}/rgb.png", "--depth", "{tmp}/depth.npy", "--threads=-2", "--out", "{tmp}/p"],
     "--threads must be an integer >= 1, got -2"),
    (["predict", "--image", "{tmp}/rgb.png", "--depth", "{tmp}/depth.npy", "--threads", "0", "--out", "{tmp}/p"],
     "got 0"),
    (["evaluate", "{model}", "--data", "{tmp}", "--size=-64"], "--size must be an integer >= 8, got -64"),
    (["evaluate", "{model}", "--data", "{tmp}", "--json", "{tmp}"], "is a folder"),
    (["evaluate", "{model}", "--data", "{tmp}", "--all", "--scenes", "procedural:1"], "--all and --scenes exclude"),
    (["bench", "render", "--scene", "procedural:0", "--repeats=-1"], "--repeats must be an integer >= 1, got -1"),
    (["bench", "render", "--scene", "procedural:0", "--batch", "0"], "--batch must be an integer >= 1, got 0"),
    (["bench", "inference", "--model", "{tmp}/model.onnx"], "model.onnx: bench inference times a torch model"),
    (["bench", "inference", "--encoders", "resnet18,vgg16"], "--encoders must list distinct names of resnet18"),
    (["sequence", "--input", "{tmp}", "--intrinsics", "nan,525,320,240", "--out", "{tmp}/s"], "finite pixels"),
])
def test_bad_options_are_one_line_before_any_work(argv, message, tmp_path, one_line_error):
    from frontiernet.model import default_model_path

    argv = [word.format(model=default_model_path(), tmp=tmp_path) for word in argv]
    assert main(argv) == 2
    assert message in one_line_error()
    assert sorted(path.name for path in tmp_path.iterdir()) == []  # nothing written


def test_a_nonsense_motion_step_is_refused(plan_spec, tmp_path, one_line_error):
    assert main(["explore", "--scene", plan_spec, "--method", "classic", "--max-steps", "1", "--no-video",
                 "--out", str(tmp_path / "e"), "motion.translation_m=-0.11"]) == 2
    assert "motion.translation_m must be a positive number of metres, got -0.11" in one_line_error()


def test_predict_reads_nan_as_invalid_depth_as_render_writes_it(tmp_path, capsys):
    import cv2

    rgb = np.random.default_rng(0).integers(0, 255, (64, 80, 3), np.uint8)
    cv2.imwrite(str(tmp_path / "rgb.png"), rgb)
    depth = np.full((64, 80), 2.0, np.float32)
    depth[:, :30] = np.nan  # nothing hit within range: render's depth.npy
    np.save(tmp_path / "depth.npy", depth)
    assert main(["predict", "--image", str(tmp_path / "rgb.png"), "--depth", str(tmp_path / "depth.npy"),
                 "--size", "64", "--out", str(tmp_path / "p")]) == 0, capsys.readouterr().err
    inputs = np.load(tmp_path / "p" / "outputs.npz")["depth"]
    assert np.all(inputs[:, :20] == 0) and np.all(inputs[:, -20:] > 1.9)  # NaN went in as invalid (0)


def test_the_sequence_cache_is_redone_when_the_intrinsics_change():
    from types import SimpleNamespace

    from frontiernet.sequences.perceive import cache_key

    conf = {"size": 320, "crop": True, "fill_invalid_depth": False}
    frame = SimpleNamespace(name="0001.png", camera=SimpleNamespace(K=np.array([[525.0, 0, 320], [0, 525, 240],
                                                                                 [0, 0, 1]])))
    other = SimpleNamespace(name="0001.png", camera=SimpleNamespace(K=np.array([[600.0, 0, 320], [0, 600, 240],
                                                                                 [0, 0, 1]])))
    assert cache_key(frame, "m", "sensor", conf) == cache_key(frame, "m", "sensor", conf)
    assert cache_key(frame, "m", "sensor", conf) != cache_key(other, "m", "sensor", conf)


def test_a_validation_fraction_outside_0_1_is_refused():
    from frontiernet.errors import InputError
    from train.data import split_scenes

    assert len(split_scenes(["a", "b", "c"], None, 0.3, 0)[1]) == 1
    with pytest.raises(InputError, match="data.val_fraction must lie strictly between 0 and 1, got 1.5"):
        split_scenes(["a", "b"], None, 1.5, 0)


def test_an_internal_error_is_one_line_naming_the_log_with_its_traceback(monkeypatch, capsys, one_line_error):
    import frontiernet.cli.render as render

    def fault(args):
        raise ZeroDivisionError("a bug\nsecond line")

    monkeypatch.setattr(render, "run", fault)
    argv = ["render", "procedural:3", "--pose", "1,1,1.2,0", "--out", "o"]
    assert main(argv) == 1
    error = one_line_error()
    assert "internal error (ZeroDivisionError: a bug)" in error
    log = Path(error.split("the traceback is in ")[1].split(" (-v")[0])
    text = log.read_text()
    assert "frontiernet render procedural:3 --pose 1,1,1.2,0" in text and "Traceback" in text and "in fault" in text
    log.unlink()
    with pytest.raises(ZeroDivisionError):  # -v: the traceback on the terminal
        main(["-v", *argv])

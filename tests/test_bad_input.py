"""Bad input to every command (issue 28's probe list, docs/bad_input.md): one line naming the file,
key or value and what is wrong, exit code 2, no traceback, nothing already written lost."""

from __future__ import annotations

import sys
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


def test_a_range_where_one_scene_is_taken_says_so(one_line_error):
    # issue 55's second probe: "procedural seed must be an integer" for procedural:5-2
    assert main(["scene", "info", "procedural:2-5"]) == 2
    assert "a range of seeds names several scenes, and this takes one (e.g. procedural:2)" in one_line_error()
    # seventh probe (D23): an inverted range names no scene, not several
    assert main(["scene", "info", "procedural:5-2"]) == 2
    assert one_line_error() == ("frontiernet scene: error: scene spec 'procedural:5-2': seed range must satisfy "
                                "0 <= FIRST <= LAST")


def test_a_scene_option_in_exponent_notation_is_a_number():
    from frontiernet.scenes.spec import parse_spec

    assert parse_spec("floorplan:plan.png?resolution=5e-2&up=y").options == {"resolution": 0.05, "up": "y"}


def test_an_empty_npy_floor_plan_is_one_line(tmp_path, one_line_error):
    (tmp_path / "plan.npy").write_bytes(b"")
    assert main(["scene", "info", f"floorplan:{tmp_path / 'plan.npy'}?resolution=0.05"]) == 2
    assert "plan.npy: not a readable .npy array" in one_line_error()


SMALL_DATAGEN = ["--views-per-scene", "2", "--no-progress", "--set", "camera.width=64", "camera.height=64",
                 "camera.focal_px=40", "writer.shard_size=2"]


@pytest.mark.parametrize("argv, message", [
    (["explore", "--scene", "procedural:3", "--seed=-1", "--max-steps", "1", "--no-video"], "--seed, run.seed"),
    (["explore", "--scene", "procedural:3", "run.seed=-3", "--max-steps", "1", "--no-video"], "got -3"),
    (["explore", "--scene", "procedural:3", "--depth", "", "--max-steps", "1", "--no-video"],  # ran on the default
     "depth source ''"),
    (["bench", "--scenes", "procedural:3", "--seed", "-1", "--max-steps", "4"], "--seed, run.seed"),
    (["bench", "--scenes", "procedural:3", "--depth", "sonar", "--max-steps", "4"], "depth source 'sonar'"),
    (["bench", "--scenes", "procedural:3", "--workers", "0", "--max-steps", "4"], "--workers must be"),
    (["bench", "--scenes", "procedural:3", "--backend", "spark", "--max-steps", "4"], "--backend must be"),
    # issue 55: nonsense that ran (a method twice, a model no method runs, starts without end)
    (["bench", "--scenes", "procedural:3", "--methods", "classic,classic", "--max-steps", "4"],
     "--methods names classic twice"),
    # issue 55's fourth probe: 'classic,' ran as 'classic' (while --depth 'gt,' is refused)
    (["bench", "--scenes", "procedural:3", "--methods", "classic,", "--max-steps", "4"],
     "--methods 'classic,': an empty method name"),
    (["bench", "--scenes", "procedural:3", "--methods", "classic", "--model", "m.safetensors", "--max-steps", "4"],
     "none of the methods classic runs a FrontierNet model"),
    (["bench", "--scenes", "procedural:3", "--starts", "100000000", "--max-steps", "4"],
     "--starts must be an integer in [1, 1000], got 100000000"),
    (["bench", "--scenes", "procedural:3", "--workers", "99999", "--max-steps", "4"],
     "--workers must be an integer in"),
    (["explore", "--scene", "procedural:3", "--method", "oracle", "--model", "m.safetensors", "--max-steps", "1"],
     "--model m.safetensors: method oracle runs no model, so --model would be ignored"),
    (["datagen", "--scenes", "procedural:0-99999999", "--views-per-scene", "2"],
     "a seed range of 100,000,000 scenes; at most 100,000"),
    (["datagen", "--scenes", "procedural:3", "--views-per-scene", "1000000000"],
     "--views-per-scene must be an integer in [1, 10000000]"),
    (["datagen", "--scenes", "procedural:3", *SMALL_DATAGEN, "--workers", "0"], "--workers must be"),
])
def test_bad_run_settings_are_refused_before_anything_is_written(argv, message, tmp_path, one_line_error):
    out = tmp_path / "out"
    assert main([*argv, "--out", str(out)]) == 2
    assert message in one_line_error()
    assert not out.exists()  # a refused run leaves nothing that blocks the next one


def test_datagen_on_ray_without_ray_leaves_nothing(tmp_path, one_line_error, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` fails as where it is not installed
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
    (["--pixel-size", "1000"], "give a smaller pixel size"),  # a 1 px picture was an internal error (OpenCV)
    (["--cut-height", "-5"], "cut height (--cut-height) must be a positive number"),
    (["--cut-height", "1000"], "the cut height (--cut-height) 1000 m lies above"),  # drew the roof (second probe)
])
def test_bad_top_view_settings_are_one_line(plan_spec, tmp_path, one_line_error, option, message):
    assert main(["scene", "topdown", plan_spec, "--out", str(tmp_path / "new" / "top.png"), *option]) == 2
    assert message in one_line_error()
    assert not (tmp_path / "new").exists()  # issue 55: the folder of --out was made before the refusal


def test_outputs_are_replaced_only_with_force(plan_spec, tmp_path, capsys, one_line_error):
    view, top = tmp_path / "view", tmp_path / "top.png"
    render = ["render", plan_spec, "--pose", "2.0,1.5,1.2,0", "--out", str(view)]
    topdown = ["scene", "topdown", plan_spec, "--out", str(top)]
    assert main(render) == 0 and main(topdown) == 0
    before = {path: path.read_bytes() for path in [*view.iterdir(), top]}
    (view / "mine.txt").write_text("a file of the user's")
    for argv, name in ((render, "view"), (topdown, "top.png"),
                       (["explore", "--scene", plan_spec, "--out", str(view)], "view"),
                       # issue 55's second probe: predict wrote over earlier outputs without a word
                       (["predict", "--image", str(view / "rgb.png"), "--depth", str(view / "depth.npy"),
                         "--out", str(view)], "view"),
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
    (["export", "{model}", "--format", "onnx", "--out", "{tmp}/m.txt"],  # was written, and could not be read back
     "--out m.txt: onnx files are read back by their suffix; name it *.onnx"),
    (["export", "{model}", "--format", "torchscript", "--out", "{tmp}/m.onnx"], "name it *.pt or *.ts or *.torchscript"),
    (["predict", "--image", "{tmp}/rgb.png", "--depth", "{tmp}/depth.npy", "--threads=-2", "--out", "{tmp}/p"],
     "--threads must be an integer in [1, "),
    (["predict", "--image", "{tmp}/rgb.png", "--depth", "{tmp}/depth.npy", "--threads", "0", "--out", "{tmp}/p"],
     "got 0"),
    (["evaluate", "{model}", "--data", "{tmp}", "--size=-64"], "--size must be an integer in [8, 2048], got -64"),
    # issue 55: a size, a thread or worker count past what the machine can hold was an internal error
    # (MemoryError, "Overflow when unpacking long") or a segfault (exit 139, torch with 99999 threads)
    (["evaluate", "{model}", "--data", "{tmp}", "--size", "100000"],
     "--size must be an integer in [8, 2048], got 100000"),
    (["evaluate", "{model}", "--data", "{tmp}", "--workers", "99999"], "--workers must be an integer in [0, "),
    (["predict", "--image", "{tmp}/rgb.png", "--depth", "{tmp}/depth.npy", "--threads", "99999", "--out", "{tmp}/p"],
     "--threads must be an integer in [1, "),
    (["predict", "--image", "{tmp}/rgb.png", "--depth", "{tmp}/depth.npy", "--threads", "100000000000", "--out",
      "{tmp}/p"], "got 100000000000 (at most 4 per core of this machine)"),
    (["predict", "--image", "{tmp}/rgb.png", "--size", "100000", "--out", "{tmp}/p"], "--size (or 0: the image's own "
                                                                                      "size) must be an integer in [8"),
    (["bench", "inference", "--sizes", "320", "100000"], "--sizes must be an integer in [8, 2048], got 100000"),
    (["bench", "inference", "--sizes", "64", "64"], "--sizes 64 64: a size given twice"),  # timed twice, a 90 s wait
    (["evaluate", "{tmp}", "--data", "{tmp}"], "is a folder, expected a file (model file)"),
    (["datagen", "consistency", "--scenes", "procedural:12", "--views-per-scene", "1", "--json", "{tmp}"],
     "is a folder; give the output's file name"),  # was after the labelling
    (["evaluate", "{model}", "--data", "{tmp}", "--json", "{tmp}"], "is a folder"),
    (["evaluate", "{model}", "--data", "{tmp}", "--all", "--scenes", "procedural:1"], "--all and --scenes exclude"),
    (["bench", "render", "--scene", "procedural:0", "--repeats=-1"], "--repeats must be an integer in [1, 10000], got -1"),
    (["bench", "render", "--scene", "procedural:0", "--batch", "0"], "--batch must be an integer in [1, 1024], got 0"),
    # issue 55's second probe: budgets and counts without an upper bound ran until killed
    (["explore", "--scene", "procedural:3", "--max-steps", "1000000000000", "--no-video", "--out", "{tmp}/e"],
     "the step budget (--max-steps, run.max_steps) must be an integer in [1, 100000]"),
    (["explore", "--scene", "procedural:3", "--no-video", "--out", "{tmp}/e", "run.max_steps=1e9"],
     "must be an integer in [1, 100000], got 1000000000.0"),
    (["bench", "--scenes", "procedural:3", "--max-steps", "1000000000000", "--methods", "classic", "--out", "{tmp}/b"],
     "--max-steps must be an integer in [1, 100000]"),
    (["explore", "--scene", "procedural:3", "--no-video", "--out", "{tmp}/e", "run.max_steps="],
     "override 'run.max_steps=' has no value (write run.max_steps=null for none)"),  # was taken as ''
    # eighth probe (E12): the section set to a number was dropped for the key set inside it after
    (["explore", "--scene", "procedural:3", "--no-video", "--out", "{tmp}/e", "sim.camera=5", "sim.camera.width=64"],
     "override 'sim.camera=5' sets sim.camera to a value, but 'sim.camera.width=64' after it sets a key inside it (a "
     "section): give one of them"),
    (["bench", "render", "--scene", "procedural:0", "--repeats", "1000000000"], "--repeats must be an integer in [1, 10000]"),
    (["bench", "explore", "--scene", "procedural:0", "--steps", "1000000000"], "--steps must be an integer in [1, 100000]"),
    (["bench", "inference", "--model", "{tmp}/model.onnx"], "model.onnx: bench inference times a torch model"),
    (["bench", "inference", "--repeats", "100001"], "--repeats must be an integer in [1, 10000]"),  # ran until killed
    # issue 55's third probe: options a command would have ignored
    (["bench", "--report", "--out", "{tmp}/b", "--methods", "oracle"],
     "--report reads the benchmark folder (--out) alone, so --methods would be ignored"),
    (["bench", "--pack", "--out", "{tmp}/b", "--scenes", "procedural:9"], "--pack reads the benchmark folder"),
    (["bench", "--scenes", "procedural:3", "--methods", "classic", "--out", "{tmp}/b", "--set", "run.max_steps=3"],
     "run.max_steps=3: the benchmark gives each scene its budget"),
    (["datagen", "bench", "--scene", "procedural:3", "--views", "100000"], "--views must be an integer in [1, 10000]"),
    (["bench", "train", "--steps", "100000000", "data.path={tmp}"], "--steps must be an integer in [1, 10000]"),
    (["mapgen", "--scenes", "procedural:3", "--out", "{tmp}/m", "--set", "mapgen.max_steps=100001"],
     "mapgen.max_steps must be an integer in [1, 100000]"),
    (["bench", "inference", "--encoders", "resnet18,vgg16"], "--encoders must list distinct names of resnet18"),
    (["sequence", "--input", "{tmp}", "--intrinsics", "nan,525,320,240", "--out", "{tmp}/s"], "finite pixels"),
    # issue 55's second probe: a yaw of 1e30 degrees rendered some heading
    (["render", "procedural:3", "--pose", "3,3,1.2,1e30", "--out", "{tmp}/r"], "yaw must lie between -360 and 360"),
    (["bench", "--scenes", "procedural:3", "--methods", "classic,nbvp", "--max-steps", "60", "--out", "{tmp}/b",
      "--set", "planner.mode=map_free"], "method classic takes its frontiers from the robot's map"),
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
    assert "motion.translation_m must be a number >= 0.01, got -0.11" in one_line_error()


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


# --------------------------------------------------------------------------- issue 55's probe

def test_a_camera_too_large_to_render_is_refused_before_the_scene_loads(tmp_path, one_line_error):
    # was: internal error (MemoryError: Unable to allocate 7.28 TiB ...)
    config = tmp_path / "big.yaml"
    config.write_text("camera:\n  width: 1000000\n  height: 1000000\n")
    assert main(["render", "procedural:3", "--pose", "3,3,1.2,0", "--config", str(config),
                 "--out", str(tmp_path / "view")]) == 2
    assert "camera.width must be an integer in [1, 4096], got 1000000" in one_line_error()
    assert not (tmp_path / "view").exists()


@pytest.mark.parametrize("overrides, message", [
    (["trainer.max_epochs=-1"], "trainer.max_epochs (-1: no limit, with trainer.max_steps > 0) must be an integer"),
    (["augment.crop_size=0"], "augment.crop_size must be an integer in [33, 2048] (or null), got 0"),
    (["augment.hflip=1.5"], "augment.hflip must be a number in [0, 1], got 1.5"),
    (["trainer.threads=99999"], "trainer.threads must be an integer in [1, 1024] (or null), got 99999"),
    (["seed=-1"], "seed must be an integer in [0, 4294967295], got -1"),  # issue 55's second probe: an internal error
    (["name=../../escape"], "name: the run's folder name inside out= (no / or ..), got '../../escape'"),
])
def test_nonsense_training_settings_are_refused_before_anything_is_written(tmp_path, overrides, message,
                                                                             one_line_error):
    # trainer.max_epochs=-1 was an internal error (OverflowError) after the run folder was made, and
    # augment.crop_size=0 trained without crops
    runs = tmp_path / "runs"
    assert main(["train", f"data.path={tmp_path / 'no_data'}", f"out={runs}", "name=tiny", *overrides]) == 2
    assert message in one_line_error()
    assert not runs.exists()  # no runs/tiny left behind


def test_a_training_run_folder_under_a_file_is_refused_at_once(tmp_path, one_line_error):
    # was: internal error (NotADirectoryError) after the data was read
    (tmp_path / "afile").write_text("")
    assert main(["train", f"data.path={tmp_path / 'no_data'}", f"out={tmp_path / 'afile'}", "name=tiny"]) == 2
    assert f"{tmp_path / 'afile' / 'tiny'}: cannot create the output folder: {tmp_path / 'afile'} is a file" \
        in one_line_error()


def test_a_second_config_file_is_refused_not_dropped(one_line_error, capsys):
    # argparse kept the last --config and dropped the first without a word
    for argv in (["explore", "--scene", "s", "--config", "a.yaml", "--config", "b.yaml", "--out", "o"],
                 ["train", "--config", "a.yaml", "--config", "b.yaml"]):
        with pytest.raises(SystemExit) as stop:
            build_parser().parse_args(argv)
        assert stop.value.code == 2
        assert "--config given twice (a.yaml, then b.yaml): give one" in one_line_error()


def test_demo_takes_the_config_keys_of_explore(tmp_path, one_line_error):
    # docs/usage.md said demo takes sim.*, depth.*, scenes.* keys; it took none ("unrecognized arguments")
    args = build_parser().parse_args(["demo", "sim.camera.max_depth=5", "depth.emulated.fill_depth=20"])
    assert args.overrides == ["sim.camera.max_depth=5", "depth.emulated.fill_depth=20"]
    assert main(["demo", "--out", str(tmp_path / "demo"), "tracking.min_gain=2"]) == 2
    assert "unknown config key 'tracking.min_gain'" in one_line_error()
    assert not (tmp_path / "demo").exists()


@pytest.fixture
def no_setup(monkeypatch):
    """Fails a command that loads its scene: what it refuses must be refused before its setup."""
    import frontiernet.simulator.world as world

    def build_world(*args, **kwargs):
        raise AssertionError("the scene was loaded before the bad input was refused")

    monkeypatch.setattr(world, "build_world", build_world)


def test_demo_refuses_a_file_as_out_before_its_setup(tmp_path, no_setup, one_line_error):
    (tmp_path / "afile").write_text("mine")
    assert main(["demo", "--out", str(tmp_path / "afile")]) == 2  # was refused after 22 s of setup
    assert "afile: output path exists and is not a folder" in one_line_error()
    assert (tmp_path / "afile").read_text() == "mine"


@pytest.mark.parametrize("argv, message", [
    (["--start", "50,50,1.2,0"], "start pose outside the scene's free space"),  # known once the scene has loaded
    (["planner.clearance_m=0.01"], "planner.clearance_m = 0.01 is too small for the agent radius"),
    (["--depth", "sonar"], "depth source 'sonar' (--depth, run.depth) is unknown"),
])
def test_a_refused_exploration_leaves_no_out_folder(plan_spec, tmp_path, argv, message, one_line_error):
    out = tmp_path / "a" / "e"
    assert main(["explore", "--scene", plan_spec, "--method", "classic", "--max-steps", "1", "--no-video",
                 "--out", str(out), *argv]) == 2
    assert message in one_line_error()
    assert not (tmp_path / "a").exists()  # nor the parent it made


@pytest.mark.parametrize("argv, message", [
    (["--rerun"], "--rerun needs the rerun-sdk package"),  # was after 11 s of setup
    (["planner.clearance_m=0.01"], "planner.clearance_m = 0.01 is too small for the agent radius"),
    (["--model", "m.safetensors"], "m.safetensors: model file not found"),
    # issue 55's second probe: map-free mode with a map method ran as if in map mode
    (["--method", "nbvp", "--map-free"], "--map-free (planner.mode=map_free): method nbvp grows its tree"),
    (["--method", "vacuum", "--map-free"], "method vacuum plans no route"),
    # issue 55's fourth probe: a ZeroDivisionError after the run (the video's clock), exit 1
    (["run.video_fps=0"], "run.video_fps must be a number in [0.01, 1000], got 0"),
])
def test_explore_refuses_bad_settings_before_its_setup(plan_spec, tmp_path, no_setup, argv, message,
                                                       one_line_error, monkeypatch):
    monkeypatch.setitem(sys.modules, "rerun", None)  # `import rerun` fails as where it is not installed
    assert main(["explore", "--scene", plan_spec, "--out", str(tmp_path / "e"), *argv]) == 2
    assert message in one_line_error()
    assert not (tmp_path / "e").exists()


def test_a_second_run_on_the_same_out_is_refused_while_the_first_writes(plan_spec, tmp_path, one_line_error):
    # two explore runs 0.3 s apart both passed the check, and one died on the other's partial video
    import os

    from frontiernet.errors import InputError
    from frontiernet.io import LOCK_NAME, claim_output_folder

    out = tmp_path / "e"
    with claim_output_folder(out) as claimed:  # a first run, writing
        assert (claimed / LOCK_NAME).read_text().strip() == str(os.getpid())
        for argv in (["explore", "--scene", plan_spec, "--max-steps", "1", "--no-video", "--force"],
                     ["render", plan_spec, "--pose", "2.0,1.5,1.2,0", "--force"],
                     # eighth probe (E9): two datagen runs on one --out both made the same shards
                     ["datagen", "--scenes", plan_spec, "--views-per-scene", "1", "--no-progress", "--resume"],
                     ["mapgen", "--scenes", plan_spec, "--no-progress", "--resume"]):
            assert main([*argv, "--out", str(out)]) == 2
            assert f"{out}: another run (process " in one_line_error()
        (claimed / "metrics.json").write_text("{}")
    assert sorted(path.name for path in out.iterdir()) == ["metrics.json"]  # the lock goes with the run
    with pytest.raises(InputError, match="already holds files"):  # a later run without --force
        with claim_output_folder(out):
            pass
    assert (out / "metrics.json").is_file()


def test_a_datagen_run_with_one_bad_scene_writes_the_others_and_says_so_in_one_line(tmp_path, capsys):
    # was: exit 1, "FAILED", no error line
    np.save(tmp_path / "zero.npy", np.zeros((0, 0), np.uint8))
    out = tmp_path / "ds"
    bad = f"floorplan:{tmp_path / 'zero.npy'}?resolution=0.05"
    assert main(["datagen", "--scenes", "procedural:3", bad, *SMALL_DATAGEN, "--out", str(out)]) == 2
    printed = capsys.readouterr()
    [line] = printed.err.strip().splitlines()
    assert line.startswith(f"frontiernet datagen: error: {bad}: ") and "at least 3x3 pixels" in line
    assert "the other scenes' views are in" in line and "rerun with --resume" in line
    assert f"failed: {bad}" in printed.out  # in the report too
    assert len(list((out / "shards").glob("*.zip"))) == 1  # the good scene's views are kept


def test_bench_refuses_a_folder_of_other_files(tmp_path, one_line_error):
    # issue 55's second probe: a datagen dataset given as --out got the benchmark's plan and runs in it
    (tmp_path / "dataset.json").write_text("{}")
    assert main(["bench", "--scenes", "procedural:3", "--max-steps", "40", "--methods", "classic",
                 "--out", str(tmp_path)]) == 2
    assert "holds files but no benchmark (no plan.json)" in one_line_error()
    assert sorted(path.name for path in tmp_path.iterdir()) == ["dataset.json"]


@pytest.mark.parametrize("argv", [
    ["bench", "--scenes", "procedural:3", "--max-steps", "40", "--depth", "gt,depth_anything_v2", "--methods",
     "classic", "--out", "{tmp}/b"],
    ["explore", "--scene", "procedural:3", "--depth", "depth_anything_v2", "--max-steps", "3", "--no-video",
     "--out", "{tmp}/e"],
])
def test_missing_depth_weights_are_refused_before_the_setup(argv, tmp_path, monkeypatch, one_line_error):
    # issue 55's second probe: bench ran every run to fail and said so with exit 0; explore refused only
    # after 16 s of setup
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "hf"))
    assert main([word.format(tmp=tmp_path) for word in argv]) == 2
    assert "is not in the Hugging Face cache" in one_line_error()
    assert sorted(path.name for path in tmp_path.iterdir()) == []


def test_evaluate_checks_its_json_folder_before_the_evaluation(tmp_path, one_line_error):
    # issue 55's second probe: an unwritable --json was refused only after the whole evaluation
    from frontiernet.model import default_model_path

    (tmp_path / "afile").write_text("")
    assert main(["evaluate", str(default_model_path()), "--data", str(tmp_path), "--all",
                 "--json", str(tmp_path / "afile" / "x.json")]) == 2
    message = one_line_error()
    assert "--json" in message and "cannot write in" in message


def test_intrinsics_of_another_image_size_are_named_as_given(tmp_path, one_line_error):
    # issue 55's second probe: the principal point was reported scaled to the network's size, after the
    # prediction had written its pictures
    import cv2

    cv2.imwrite(str(tmp_path / "rgb.png"), np.full((48, 64, 3), 128, np.uint8))
    np.save(tmp_path / "depth.npy", np.full((48, 64), 2.0, np.float32))
    assert main(["predict", "--image", str(tmp_path / "rgb.png"), "--depth", str(tmp_path / "depth.npy"),
                 "--intrinsics", "30,30,5000,5000", "--out", str(tmp_path / "p")]) == 2
    assert "--intrinsics: the principal point (5000, 5000) lies outside the 64 x 48 image" in one_line_error()
    assert not (tmp_path / "p").exists()

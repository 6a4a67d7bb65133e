"""Bad input of the sixth probe of issue 55 (docs/bad_input.md): one line naming the file, key or option and
what is wrong, exit code 2, no traceback, refused before the setup (the scene, the model, the data) and before
any folder is made. Each test failed before its fix (a hang, an internal error, a stack trace, another
message, or the refusal after the work). Where the message was right but late, the test gives a second
fault that the work would meet first (a missing scene, model or dataset): the old code named that one."""

from __future__ import annotations

import os
import re
import struct
import subprocess
import sys
import zlib

import cv2
import numpy as np
import pytest

from frontiernet.cli.main import main
from frontiernet.errors import InputError

MISSING = "/nonexistent-probe6/none.glb"  # a scene the old code loaded (and refused) before the value tested


def huge_png(path) -> str:
    """A 69-byte PNG whose header claims 100,000 x 100,000 pixels."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", 100_000, 100_000, 8, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(b"\0" * 101))
                     + chunk(b"IEND", b""))
    return str(path)


def refused(argv, message, one_line_error, out=None) -> str:
    """Run ``frontiernet ARGV``: exit 2, one line holding `message`, `out` (if given) not made."""
    assert main([str(word) for word in argv]) == 2
    line = one_line_error()
    assert message in line, line
    assert out is None or not os.path.lexists(out)
    return line


# ----------------------------------------------------------------------------- hangs (item 1)

def test_a_building_past_100_m_is_refused_before_it_is_drawn(monkeypatch, one_line_error):
    # sixth probe: procedural:0?footprint_max=200 drew 760 rooms a storey, each over the whole plan: minutes
    import frontiernet.scenes.procedural as procedural

    def drawn(*args, **kwargs):
        raise AssertionError("the building was drawn")

    monkeypatch.setattr(procedural, "generate_procedural_scene", drawn)
    refused(["scene", "info", "procedural:0?footprint_max=200"], "procedural option footprint_max must be a number "
            "in (0, 100], got 200", one_line_error)


def test_a_room_is_meshed_from_its_own_box_of_the_plan():
    # the rectangles of a crop at its origin are the whole plan's, in the same order (a 200 m plan was
    # scanned whole once per room and surface: hundreds of rooms x millions of pixels)
    from frontiernet.scenes.builder import mask_rectangles

    plan = np.zeros((60, 80), bool)
    plan[10:20, 30:45] = plan[12:30, 50:52] = plan[25:28, 31:33] = True
    window = (slice(8, 35), slice(28, 60))
    assert mask_rectangles(plan[window], (8, 28)).tolist() == mask_rectangles(plan).tolist()


@pytest.fixture
def no_cluster(monkeypatch):
    from train.main import CLUSTER_VARIABLES

    for name in CLUSTER_VARIABLES:
        monkeypatch.delenv(name, raising=False)


@pytest.mark.parametrize("overrides, message", [
    # waited for 999 other nodes for ever
    (["trainer.num_nodes=1000"], "trainer.num_nodes=1000: no multi-node launch here"),
    # an internal error at the first step (float32 views, float64 weights)
    (["trainer.precision=64-true"], "trainer.precision=64-true: not one this training takes"),
    (["trainer.precision=bf16-true"], "trainer.precision=bf16-true: not one this training takes"),
    # two CPU processes that shared one loader and wrote no results (an internal error at the end)
    (["trainer.strategy=ddp", "trainer.devices=2"], "trainer.devices=2: training runs on the CPU here"),
    # eighth probe (E4): exit 0, the spawned process trained and this one wrote its untrained weights as the model
    (["trainer.strategy=ddp_spawn"], "trainer.strategy=ddp_spawn: not one this training takes; valid: auto, ddp, "
                                     "ddp_find_unused_parameters_false, ddp_find_unused_parameters_true, "
                                     "single_device (the weights this process holds are written as the model: it "
                                     "must train them itself)"),
    (["trainer.strategy=deepspeed"], "trainer.strategy=deepspeed: not one this training takes"),
    # Lightning's INFO lines on stderr before the error line
    (["model.network.pretrained=bogus"], "bogus: ImageNet weights file, network.pretrained not found"),
])
def test_trainer_settings_that_cannot_run_here_are_refused_before_the_data(overrides, message, tmp_path, no_cluster,
                                                                             one_line_error):
    runs = tmp_path / "runs"  # (no dataset: the old code got past these settings to refuse the data)
    refused(["train", "--no-progress", f"data.path={tmp_path / 'no_data'}", f"out={runs}", "trainer.accelerator=cpu",
             *overrides], message, one_line_error, runs)


def test_a_gpu_asked_for_where_there_is_none_names_the_key(tmp_path, no_cluster, one_line_error):
    # eighth probe (E26): "trainer: No supported gpu backend found!" (Lightning's words, after its setup began)
    import torch

    if torch.cuda.is_available():
        pytest.skip("a CUDA GPU is here: trainer.accelerator=gpu is taken")
    runs = tmp_path / "runs"
    refused(["train", "--no-progress", f"data.path={tmp_path / 'no_data'}", f"out={runs}", "trainer.accelerator=gpu"],
            "trainer.accelerator=gpu: no CUDA GPU here (torch finds none); give trainer.accelerator=cpu, or auto (a "
            "GPU where there is one)", one_line_error, runs)


# ----------------------------------------------------------------------------- internal errors (item 2)

def test_an_image_whose_header_claims_10_gigapixels_is_refused_naming_it(tmp_path, one_line_error):
    # sixth probe: OpenCV's CV_IO_MAX_IMAGE_PIXELS assertion, an internal error (floor plan, predict --image)
    image = huge_png(tmp_path / "huge.png")
    claim = f"{image}: its header claims more than 1,073,741,824 pixels"
    refused(["scene", "info", f"floorplan:{image}?resolution=0.05"], claim, one_line_error)
    np.save(tmp_path / "depth.npy", np.ones((48, 64), np.float32))
    refused(["predict", "--image", image, "--depth", tmp_path / "depth.npy", "--out", tmp_path / "p"], claim,
            one_line_error, tmp_path / "p")
    from frontiernet.sequences.readers import image_size

    with pytest.raises(InputError, match="not an image this reads"):  # (PIL's bomb error for sequence's sizes)
        image_size(tmp_path / "huge.png")


@pytest.mark.parametrize("plan, wrong", [("[1, 2]", "a JSON list, not an object"), ('{"runs": []}', "no 'settings'"),
                                         ('{"settings": {"conf": {}, "budget": 5}, "start_poses": {}, "runs": [3]}',
                                          "run 0 is not an object")])
def test_a_benchmark_plan_of_the_wrong_shape_is_named(plan, wrong, tmp_path, one_line_error):
    # sixth probe: --report, --pack and a resume ended in a KeyError or TypeError (internal errors)
    out = tmp_path / "b"
    out.mkdir()
    (out / "plan.json").write_text(plan)
    for argv in (["--report"], ["--pack"], ["--scenes", "procedural:3", "--methods", "classic"]):
        refused(["bench", *argv, "--out", out], f"{out / 'plan.json'}: not a benchmark plan ({wrong}", one_line_error)
    assert sorted(path.name for path in out.iterdir()) == ["plan.json"]


def test_a_plan_without_its_settings_is_not_resumed(tmp_path, one_line_error):
    out = tmp_path / "b"  # (a report needs no settings; a resume compares them: a KeyError before)
    out.mkdir()
    (out / "plan.json").write_text('{"settings": {}, "start_poses": {}, "runs": []}')
    refused(["bench", "--scenes", "procedural:3", "--methods", "classic", "--out", out], "plan.json: not a benchmark "
            "plan (its 'settings' lack 'conf' or 'budget')", one_line_error)


# ----------------------------------------------------------------------------- signals (item 3)

def _interrupted(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)


def test_sigterm_to_any_command_is_an_interruption():
    # sixth probe: datagen and bench with --workers 1 (no pool) ended silently with 143
    done = _interrupted("import os, signal, sys, time\nimport frontiernet.cli.scene as scene\n"
                        "def stopped(args):\n    os.kill(os.getpid(), signal.SIGTERM)\n    time.sleep(30)\n"
                        "scene.run_info = stopped\nfrom frontiernet.cli.main import main\n"
                        "sys.exit(main(['scene', 'info', 'procedural:3']))\n")
    assert done.returncode == 130 and done.stderr.strip() == "frontiernet scene: interrupted", done.stderr[-2000:]


def test_sigterm_after_pycolmap_is_imported_is_no_native_stack_trace():
    # sixth probe: pycolmap's import installed glog's handler: SIGTERM to sequence printed a native stack trace
    done = _interrupted("import os, signal, time\nfrom frontiernet.workers import sigterm_as_interrupt\n"
                        "with sigterm_as_interrupt():\n    import frontiernet.sequences.sfm\n    try:\n"
                        "        os.kill(os.getpid(), signal.SIGTERM)\n        time.sleep(30)\n"
                        "    except KeyboardInterrupt:\n        print('interrupted')\n")
    assert done.returncode == 0 and done.stdout.strip() == "interrupted" and "stack trace" not in done.stderr, \
        done.stderr[-2000:]


def test_an_interrupted_colmap_call_is_waited_for():
    # Python 3.11's Thread.join interrupted by Ctrl-C marks a running thread ended: the command exited while
    # COLMAP still ran in it ("terminate called without an active exception", a native stack trace). In a process
    # of its own: Ctrl-C reaches a process's main thread, which under pytest-xdist is not the test's.
    import subprocess
    import sys

    script = """
import _thread, signal, time
from frontiernet.sequences.sfm import _cancellable
signal.signal(signal.SIGINT, signal.default_int_handler)  # (a background job starts with Ctrl-C ignored)
finished = []
def colmap_call(cancellation_token):
    time.sleep(0.2)  # (Thread.start has returned: the caller waits on the call)
    _thread.interrupt_main()  # Ctrl-C while the call runs (from here: not a timer racing the call)
    time.sleep(2.0)
    finished.append(True)
try:
    _cancellable(colmap_call)
except KeyboardInterrupt:
    print("interrupted, call finished:", bool(finished))
"""
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert "interrupted, call finished: True" in result.stdout, result.stdout + result.stderr


# ----------------------------------------------------------------------------- misleading messages (item 4)

def test_a_start_clearance_nowhere_met_names_its_key(two_room_scene, two_room_voxels):
    # sixth probe: planner.clearance_m=3 was reported as "with 0.5 m clearance to start from" (run.start_clearance_m)
    from frontiernet.exploration.region import sample_start
    from frontiernet.exploration.run import load_run_config

    rng = np.random.default_rng(0)
    for override, named in (("planner.clearance_m=3", "keeps planner.clearance_m = 3 m from obstacles"),
                            ("run.start_clearance_m=50", "keeps run.start_clearance_m = 50 m from obstacles")):
        with pytest.raises(InputError, match=named):
            sample_start(two_room_scene, two_room_voxels, load_run_config(overrides=[override]), rng)


@pytest.mark.parametrize("argv", [["explore", "--scene", MISSING], ["render", MISSING, "--pose", "1,1,1,0"],
                                  ["datagen", "--scenes", "procedural:3", "--views-per-scene", "1"],
                                  ["scene", "topdown", MISSING]])
def test_a_dangling_link_as_out_is_named_at_once(argv, tmp_path, one_line_error):
    # sixth probe: "cannot create output folder (File exists)", after the scene loaded
    link = tmp_path / "out"
    link.symlink_to(tmp_path / "gone" / "target")
    refused([*argv, "--out", link], f"{link}: a symbolic link to {tmp_path / 'gone' / 'target'}, which does not exist",
            one_line_error, tmp_path / "gone")


def test_a_folder_or_a_pipe_where_a_file_or_folder_goes_is_not_called_missing(tmp_path, one_line_error):
    (tmp_path / "adir").mkdir()
    os.mkfifo(tmp_path / "fifo")
    refused(["mapeval", tmp_path / "adir", "--data", tmp_path], "adir: is a folder, expected a file (predictor file)",
            one_line_error)
    refused(["sequence", "--input", tmp_path / "fifo", "--out", tmp_path / "s"], "fifo: is not a regular file nor a "
            "folder (a device or a pipe?), expected a folder (sequence)", one_line_error, tmp_path / "s")
    with pytest.raises(InputError, match="fifo.glb: not a regular file, expected a file"):
        from frontiernet.scenes.mesh_files import find_hm3d_glb

        os.mkfifo(tmp_path / "fifo.glb")
        find_hm3d_glb(tmp_path / "fifo.glb")


@pytest.mark.parametrize("argv", [["render", "procedural:3", "--pose", "3,3,1.2,0", "--out", ""],
                                  ["evaluate", "m.safetensors", "--data", ".", "--json", " "],
                                  ["bench", "--scenes", "procedural:3", "--out", ""]])
def test_an_empty_output_path_is_refused(argv, tmp_path, monkeypatch, one_line_error):
    # sixth probe: render --out '' wrote into the current folder; a second run advised --force for "."
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    assert "names no output; give a folder or file name" in one_line_error()
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv, message", [
    (["explore", "--scene", "procedural:3", "--method", "classic", "--out", "o", "--show-prediction", ""],
     "argument --show-prediction: an empty path ('') names no predictor file"),
    (["explore", "--scene", "procedural:3", "--out", "o", "--config", ""],
     "argument --config: an empty path ('') names no config file"),
    (["sequence", "--input", "", "--out", "o"], "argument --input: an empty path ('') names no sequence or recording"),
    (["datagen", "preview", ""], "argument DIR: an empty path ('') names no dataset"),
    (["evaluate", "m.safetensors", "--data", ""], "argument --data: an empty path ('') names no dataset folder"),
    (["train", "--resume", "", "data.path=d"], "argument --resume: an empty path ('') names no checkpoint"),
])
def test_an_empty_input_path_is_refused(argv, message, tmp_path, monkeypatch, one_line_error):
    # seventh probe (D20): --show-prediction '' read '.' (".: is a folder, expected a file (predictor file)"), as
    # --config '', sequence --input '' (". : unknown sequence format") and datagen preview '' did
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    assert f"{message}; give a path (the current folder is '.')" in one_line_error()
    assert list(tmp_path.iterdir()) == []


def test_an_empty_path_given_to_the_library_names_no_file(tmp_path, monkeypatch):
    from frontiernet.mapprediction import load_predictor
    from frontiernet.sequences import read_redwood

    monkeypatch.chdir(tmp_path)  # '' was read as '.': ".: is a folder, expected a file (predictor file)"
    with pytest.raises(InputError, match=r"^an empty path \(''\) names no predictor file; give a path"):
        load_predictor("")
    with pytest.raises(InputError, match=r"^an empty path \(''\) names no Redwood sequence folder; give a path"):
        read_redwood("")


BOMB = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(f"{key}: &{key} [{', '.join([f'*{previous}'] * 9)}]\n"
                                                       for previous, key in zip("abcdefg", "bcdefgh"))
"""A YAML bomb: 9^8 = 43 million strings once its aliases are expanded."""


@pytest.mark.parametrize("text, message", [
    ("hello\n", "a config must be a YAML mapping (key: value lines), got the bare value 'hello'"),  # a key 'hello'
    ("42\n", "got the bare value '42'"),  # OmegaConf's OSError, "not a readable YAML config"
    ("- a\n", "got a list"),
    (BOMB, "its YAML aliases (*name) expand past 10000 nodes, more than a config has"),  # OmegaConf's advice to
])                                                                                      # raise its limit
def test_a_config_file_that_is_no_mapping_is_named(text, message, tmp_path, one_line_error):
    (tmp_path / "c.yaml").write_text(text)
    line = refused(["render", "procedural:3", "--pose", "3,3,1.2,0", "--config", tmp_path / "c.yaml", "--out",
                    tmp_path / "o"], f"{tmp_path / 'c.yaml'}: ", one_line_error, tmp_path / "o")
    assert message in line


def test_a_demo_scene_that_is_no_text_is_named(tmp_path, one_line_error):
    # sixth probe: scene: [procedural:3] was "['procedural:3']: no such file"
    (tmp_path / "demo.yaml").write_text("scene:\n  - procedural:3\n")
    refused(["demo", "--config", tmp_path / "demo.yaml", "--out", tmp_path / "o"], "config key 'scene' takes one "
            "scene spec (text, e.g. procedural:3), got ['procedural:3']", one_line_error, tmp_path / "o")


def test_a_failed_scene_is_named_once():
    # sixth probe: "procedural:3?rooms_max=0: scene spec 'procedural:3?rooms_max=0': procedural option ..."
    from datagen.summary import scene_error

    spec = "procedural:3?rooms_max=0"
    assert scene_error(spec, InputError(f"scene spec '{spec}': procedural option rooms_max ...")) == \
        "procedural option rooms_max ..."
    assert scene_error("plan.png", InputError("other.npy: empty")) == "other.npy: empty"


@pytest.mark.parametrize("scale, median", [(1e-300, "2e+303"), (1e300, "2e-297")])
def test_a_depth_scale_that_makes_depths_infinite_or_zero_is_blamed(scale, median, tmp_path):
    # sixth probe: --depth-scale 1e-300 said "depth has 3072 infinite pixels; mark invalid pixels with 0 or
    # NaN" (the file's fault), 1e300 "no valid depth"
    from frontiernet.sequences.images import read_depth

    cv2.imwrite(str(tmp_path / "d.png"), np.full((48, 64), 2000, np.uint16))
    with pytest.raises(InputError, match=re.escape(f"median depth {median} m is implausible (read with depth scale")):
        read_depth(tmp_path / "d.png", scale, scale_given=True)


@pytest.mark.parametrize("scenes, message", [
    (["procedural:3", ""], "an empty scene spec (item 2 of the 2 given); give scene specs as separate words"),
    (["procedural:3,,procedural:4"], "scenes are separate words (--scenes procedural:3 procedural:4), not joined by "
                                     "commas"),  # (was refused by the workers: "procedural seed must be an integer")
])
def test_empty_or_comma_joined_scenes_are_named(scenes, message, tmp_path, one_line_error):
    out = tmp_path / "o"
    refused(["datagen", "--scenes", *scenes, "--views-per-scene", "1", "--out", out], message, one_line_error, out)


def test_an_option_of_another_benchmark_is_named_so(one_line_error):
    # sixth probe: bench render --no-baseline asked "did you mean --scene?"
    with pytest.raises(SystemExit) as stop:
        main(["bench", "render", "--no-baseline"])
    assert stop.value.code == 2
    assert "unrecognized option --no-baseline (--no-baseline is an option of `frontiernet bench train`)" in \
        one_line_error()


def test_a_bench_yaml_setting_in_set_is_named_as_one(tmp_path, one_line_error):
    # sixth probe: "override: unknown config key 'budget'" for the benchmark's own budget.max_steps
    refused(["bench", "--scenes", "procedural:3", "--out", tmp_path / "o", "--set", "budget.max_steps=100"],
            "budget.max_steps is a setting of configs/bench.yaml, which the benchmark reads itself", one_line_error,
            tmp_path / "o")


# ----------------------------------------------------------------------------- slow refusals (item 6)

@pytest.mark.parametrize("argv, message", [
    (["explore", "--scene", MISSING, "anchoring.gradient_kernel_px=4"],
     "anchoring.gradient_kernel_px must be odd and at most 31, got 4"),
    (["explore", "--scene", MISSING, *(f"anchoring.feature_weights.{k}=0" for k in ("pixel", "direction", "depth"))],
     "anchoring.feature_weights must give at least one feature a weight > 0"),
    (["bench", "--scenes", MISSING, "--set", "anchoring.gradient_kernel_px=4"], "anchoring.gradient_kernel_px must"),
    (["mapgen", "--scenes", MISSING, "--set", "mapgen.runs=[{method: seer, depth: gt}]", "seer.predictor={tmp}/p.st"],
     "p.st: predictor file not found"),  # (every run of every scene failed on it)
    (["evaluate", "{tmp}/none.safetensors", "--data", "{tmp}", "--depth", "sonar"],
     "depth source 'sonar' (--depth) is unknown"),  # (after the data load)
    (["datagen", "consistency", "--scenes", MISSING, "--json", "{tmp}/no/x.json"], "--json {tmp}/no/x.json: cannot "
                                                                                   "write in {tmp}/no"),
    (["mapeval", "{tmp}/none.safetensors", "--data", "{tmp}", "--json", "{tmp}/no/x.json"], "cannot write in {tmp}/no"),
])
def test_settings_and_outputs_are_refused_before_the_work(argv, message, tmp_path, one_line_error):
    out = tmp_path / "o"
    argv = [word.replace("{tmp}", str(tmp_path)) for word in argv]
    refused(argv + (["--out", out] if argv[0] in ("explore", "bench", "mapgen") else []),
            message.replace("{tmp}", str(tmp_path)), one_line_error, out)


def test_a_folder_where_a_run_writes_a_file_is_refused_before_the_run(tmp_path, one_line_error):
    # sixth probe: explore --force --out D with D/metrics.json a folder was refused after the whole run
    (tmp_path / "o" / "metrics.json").mkdir(parents=True)
    refused(["explore", "--scene", MISSING, "--force", "--out", tmp_path / "o"],
            f"{tmp_path / 'o' / 'metrics.json'}: a folder is where the run writes its metrics.json", one_line_error)


def test_a_uniform_gain_class_past_the_model_is_refused_before_the_first_frame():
    # sixth probe: ablations.uniform_gain_class=255 was refused at the first frame, after the scene and model
    from types import SimpleNamespace

    from frontiernet.exploration.ablations import UniformGain

    base = SimpleNamespace(runtime=SimpleNamespace(labels={"bin_edges": list(range(11))}))
    with pytest.raises(InputError, match=r"uniform_gain_class 255 is not a gain class of this model \(0 to 10\)"):
        UniformGain(base, 255)
    assert UniformGain(base, 10).gain_class == 10

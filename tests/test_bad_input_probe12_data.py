"""Bad input of the twelfth probe of issue 55 (runs/probe12_report.md) in training runs, datasets and map datasets:
S4 (SIGTERM to ``train`` after its fit), S10 (``dataset.json`` a dangling link: datagen and mapgen adopted the
shards under a new description), S15 (a map dataset whose ``shards`` is a dangling link "holds no snapshots yet").
Each refusal one line, exit code 2, nothing written before lost; each test failed before its fix (but S4's
signal while the results are written, which already ended so: a guard)."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from conftest import REPO_ROOT
from frontiernet.cli.main import main

DATAGEN_SET = ["camera.width=64", "camera.height=64", "camera.focal_px=40", "writer.shard_size=2"]
"""two_scenes' settings (conftest)."""
SMALL = "floors=1&footprint_min=8&footprint_max=10&rooms_min=3&rooms_max=4"
MAP_SCENE = f"procedural:5?{SMALL}"
MAP_SCENES = [MAP_SCENE, f"procedural:6?{SMALL}"]
MAPGEN_SET = ["sim.camera.width=64", "sim.camera.height=64", "sim.camera.focal_px=40", "mapgen.max_steps=8",
              "mapgen.snapshot_every_steps=4", "mapgen.first_snapshot_step=4",
              "mapgen.runs=[{method: classic, depth: gt}]"]


def snapshot(folder: Path) -> dict[str, object]:
    """Every file's bytes and every link's target under `folder`."""
    return {str(path.relative_to(folder)): os.readlink(path) if path.is_symlink() else path.read_bytes()
            for path in sorted(folder.rglob("*")) if path.is_symlink() or path.is_file()}


@pytest.fixture(scope="module")
def map_data(tmp_path_factory) -> Path:
    """A tiny map dataset: two small procedural scenes (one to train a predictor on, one to validate it), one
    classic run of 8 steps each."""
    out = tmp_path_factory.mktemp("maps") / "mg"
    assert main(["mapgen", "--scenes", *MAP_SCENES, "--no-progress", "--out", str(out), "--set", *MAPGEN_SET]) == 0
    return out


def copy_of(folder: Path, tmp_path: Path, name: str = "copy") -> Path:
    shutil.copytree(folder, tmp_path / name, symlinks=True)
    return tmp_path / name


def dangling(path: Path, tmp_path: Path) -> str:
    """Replace `path` (a file or a folder) by a symbolic link to nothing; returns the link's target."""
    if path.is_dir():
        shutil.rmtree(path)
    else:
        path.unlink()
    target = str(tmp_path / "nonexistent" / path.name)
    path.symlink_to(target)
    return target


# --------------------------------------------------------------------------- S4: SIGTERM after the fit

SLOW_PHASE = """
import sys, time
from lightning.pytorch.trainer.states import TrainerFn
import train.main
from train.mapprediction import MapPredictionModule
from train.module import FrontierNetModule

def reached():  # the phase under test: say so, then take long enough for the signal to land in it
    print("PHASE REACHED", file=sys.stderr, flush=True)
    time.sleep(120)

def slow_final_validation(module):
    step = module.validation_step
    def validation_step(self, *args, **kwargs):
        if self.trainer.state.fn == TrainerFn.VALIDATING:
            reached()
        return step(self, *args, **kwargs)
    module.validation_step = validation_step

if sys.argv[1] == "validation":  # the final validation (trainer.validate, after the fit)
    slow_final_validation(FrontierNetModule)
    slow_final_validation(MapPredictionModule)
else:  # writing model.safetensors
    save = train.main.save_model
    def save_model(*args, **kwargs):
        reached()
        return save(*args, **kwargs)
    train.main.save_model = save_model
from frontiernet.cli.main import main
sys.argv = ["frontiernet", *sys.argv[2:]]
sys.exit(main())
"""


MAPEX_TINY = """name: tiny
predictor: {kind: mapex, network: {widths: [4, 8, 8], dilations: [1]}}
data: {topdown_size: 32, batch_size: 1, val_fraction: 0.5}
trainer: {max_epochs: 1, max_steps: 1, max_time: null, val_check_interval: 1.0, log_every_n_steps: 1}
optim: {horizon: steps, warmup_steps: 1}
"""


@pytest.mark.parametrize("kind, phase", [("frontiernet", "validation"), ("frontiernet", "results"),
                                         ("mapex", "validation")])
def test_sigterm_after_the_fit_ends_the_run_as_interrupted(kind, phase, two_scenes, map_data, tmp_path):
    """A SIGTERM that landed in the final validation (after ``Trainer.fit stopped``) ended with exit 1 and no
    "interrupted" line: Lightning's ``sys.exit(1)`` came out of ``trainer.validate``, outside the context that
    turns it into the interrupt (a map predictor's training too). Reached deterministically: the phase,
    monkeypatched slow, says when it starts."""
    out = tmp_path / "run"
    if kind == "mapex":
        (tmp_path / "mapex.yaml").write_text(MAPEX_TINY)
        args = ["train", "--config", str(tmp_path / "mapex.yaml"), "--no-progress", f"data.path={map_data}",
                f"out={out}"]
    else:
        args = ["train", "--config", str(REPO_ROOT / "configs" / "train_tiny.yaml"), "--no-progress",
                f"data.path={two_scenes}", f"out={out}", "data.batch_size=1", "trainer.max_steps=1",
                "model.network.pretrained=false"]
    process = subprocess.Popen([sys.executable, "-c", SLOW_PHASE, phase, *args], cwd=REPO_ROOT, text=True,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    watchdog = threading.Timer(300, process.kill)  # (a hang fails the test instead of the suite)
    watchdog.start()
    try:
        before = []
        for line in process.stderr:
            before.append(line)
            if line.strip() == "PHASE REACHED":
                process.send_signal(signal.SIGTERM)
                break
        _, err = process.communicate(timeout=240)
    finally:
        watchdog.cancel()
        if process.poll() is None:
            process.kill()
            process.wait()
    assert before and before[-1].strip() == "PHASE REACHED", "".join(before)[-3000:]
    lines = err.strip().splitlines()
    assert (process.returncode, lines[-1:]) == (130, ["frontiernet train: interrupted"]), err[-3000:]
    assert "Traceback" not in err and "internal error" not in err, err[-3000:]
    run = out / "tiny"
    assert (run / "checkpoints" / "last.ckpt").is_file()  # the fit's weights, to resume from
    assert not (run / "summary.json").exists()


# --------------------------------------------------------------------------- S10: dataset.json a dangling link

@pytest.mark.parametrize("resume", [False, True])
def test_datagen_with_a_dangling_dataset_json_is_refused_and_writes_nothing(two_scenes, tmp_path, resume,
                                                                            one_line_error):
    data = copy_of(two_scenes, tmp_path)
    target = dangling(data / "dataset.json", tmp_path)
    before = snapshot(data)
    args = ["datagen", "--scenes", "procedural:3", "procedural:4", "--views-per-scene", "2", "--no-progress",
            "--out", str(data), "--set", *DATAGEN_SET] + (["--resume"] if resume else [])
    assert main(args) == 2  # (was exit 0: a new description of today's settings, the shards adopted unchecked)
    assert one_line_error() == (f"frontiernet datagen: error: {data / 'dataset.json'}: dataset description not "
                                f"found: a symbolic link to {target}, which does not exist")
    assert snapshot(data) == before


@pytest.mark.parametrize("resume", [False, True])
def test_mapgen_with_a_dangling_dataset_json_is_refused_and_writes_nothing(map_data, tmp_path, resume,
                                                                           one_line_error, capsys):
    data = copy_of(map_data, tmp_path)
    target = dangling(data / "dataset.json", tmp_path)
    before = snapshot(data)
    args = ["mapgen", "--scenes", *MAP_SCENES, "--no-progress", "--out", str(data), "--set", *MAPGEN_SET]
    assert main(args + (["--resume"] if resume else [])) == 2
    assert one_line_error() == (f"frontiernet mapgen: error: {data / 'dataset.json'}: dataset description not "
                                f"found: a symbolic link to {target}, which does not exist")
    assert "note" not in capsys.readouterr().out  # (was "holds no dataset yet ... starting a new one")
    assert snapshot(data) == before


# --------------------------------------------------------------------------- S15: shards a dangling link

def test_mapeval_names_a_shards_folder_that_is_a_dangling_link_or_a_file(map_data, tmp_path, one_line_error):
    from datagen.mapshards import open_map_dataset
    from frontiernet.errors import InputError
    from frontiernet.mapprediction import shipped_predictor_path

    data = copy_of(map_data, tmp_path)
    shards = data / "shards"
    target = dangling(shards, tmp_path)
    args = ["mapeval", str(shipped_predictor_path("mapex")), "--data", str(data), "--max-snapshots", "1"]
    assert main(args) == 2  # (was "the map dataset holds no snapshots yet")
    assert one_line_error() == (f"frontiernet mapeval: error: {shards}: map shards folder not found: a symbolic link "
                                f"to {target}, which does not exist")
    shards.unlink()
    shards.write_text("")
    with pytest.raises(InputError, match=f"^{shards}: is a file, expected a folder \\(map shards\\)$"):
        open_map_dataset(data)  # (train's reader too)
    assert shards.is_file()
    shards.unlink()  # nothing there: a dataset whose runs have not been made, as before
    with pytest.raises(InputError, match="the map dataset holds no snapshots yet$"):
        open_map_dataset(data)

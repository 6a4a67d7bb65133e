"""Bad input of the fourteenth probe of issue 55 (docs/bad_input.md, "Probe 14") to training (P9): a SIGTERM to
``frontiernet train`` before its first checkpoint left ``<out>/<name>/`` holding config.yaml, hparams.yaml and
metrics.csv but no checkpoint, which refused both the same command again ("holds an earlier training run's files")
and ``--resume`` ("nothing to resume"), and Lightning printed 4 lines of its own before "interrupted". A run stopped
before its first checkpoint now leaves nothing that blocks the same command, and says so in one line."""

from __future__ import annotations

import logging
import os
import signal
from pathlib import Path
from types import SimpleNamespace

import pytest

from frontiernet.cli.main import main

TINY = ["trainer.max_steps=1", "data.image_size=64", "data.batch_size=2", "augment.crop_size=null",
        "data.num_workers=0", "data.cache=false", "data.max_val_samples=2", "trainer.accelerator=cpu",
        "trainer.threads=1", "model.network.pretrained=false"]
"""Overrides of a FrontierNet training of one step on 64 px views (as tests/test_bad_input_training.py)."""
LIGHTNING_LINES = ("Received SIGTERM", "Detected KeyboardInterrupt")


def train_args(data, out) -> list[str]:
    return ["train", "--no-progress", f"data.path={data}", f"out={out}", "name=tiny", *TINY]


@pytest.fixture
def sigterm_at_the_first_step(monkeypatch):
    """``kill -TERM`` of this process as the first training step starts (global step 0: no checkpoint yet)."""
    from train.module import FrontierNetModule

    step = FrontierNetModule.training_step

    def stopped(self, batch, batch_index):
        os.kill(os.getpid(), signal.SIGTERM)
        return step(self, batch, batch_index)

    monkeypatch.setattr(FrontierNetModule, "training_step", stopped)


@pytest.fixture
def no_trainer(monkeypatch):
    """Makes Lightning's Trainer an internal error (exit 1): a run that gets there passed every check of its folder."""
    import train.main

    def refuse(*args, **kwargs):
        raise RuntimeError("the trainer was set up")

    monkeypatch.setattr(train.main.L, "Trainer", refuse)


def test_a_sigterm_before_the_first_checkpoint_leaves_no_run_folder_and_one_line(two_scenes, tmp_path, capsys, caplog,
                                                                                  sigterm_at_the_first_step):
    runs = tmp_path / "runs"
    with caplog.at_level(logging.INFO):
        assert main(train_args(two_scenes, runs)) == 130
    assert capsys.readouterr().err.strip().splitlines()[-1] == "frontiernet train: interrupted"
    said = [record.getMessage() for record in caplog.records]
    assert any("GPU available" in text for text in said)  # (Lightning's lines are seen here)
    assert not [text for text in said if any(line in text for line in LIGHTNING_LINES)]  # (4 lines before)
    assert not runs.exists()  # (runs/tiny held config.yaml, hparams.yaml, metrics.csv: the rerun was refused)


def test_a_sigterm_in_a_run_folder_that_was_there_removes_only_what_the_run_made(two_scenes, tmp_path, capsys,
                                                                                  monkeypatch,
                                                                                  sigterm_at_the_first_step):
    run = tmp_path / "runs" / "tiny"
    run.mkdir(parents=True)
    (run / "notes.txt").write_text("mine")
    assert main(train_args(two_scenes, tmp_path / "runs")) == 130
    assert capsys.readouterr().err.strip().splitlines()[-1] == "frontiernet train: interrupted"
    assert sorted(path.name for path in run.iterdir()) == ["notes.txt"]
    import train.main

    monkeypatch.setattr(train.main.L, "Trainer", lambda *args, **kwargs: (_ for _ in ()).throw(
        RuntimeError("the trainer was set up")))
    assert main(train_args(two_scenes, tmp_path / "runs")) == 1  # the same command again passes every check
    err = capsys.readouterr().err
    assert "the trainer was set up" in err and "earlier training run" not in err


class FakeTrainer(SimpleNamespace):
    """What :func:`train.main.run_folder` reads of Lightning's trainer."""

    interrupted: bool = False


def test_run_folder_removes_what_an_interrupted_run_made_before_its_first_checkpoint(tmp_path):
    from train.main import run_folder

    # Lightning ends a Ctrl-C or SIGTERM as sys.exit(1), the trainer marked interrupted
    trainer, out = FakeTrainer(interrupted=False), tmp_path / "runs" / "tiny"
    with pytest.raises(KeyboardInterrupt):
        with run_folder(out, trainer, tmp_path / "runs"):
            for name in ("config.yaml", "hparams.yaml", "metrics.csv"):
                (out / name).write_text("of the stopped run")
            (out / "checkpoints").mkdir()
            trainer.interrupted = True
            raise SystemExit(1)
    assert not (tmp_path / "runs").exists()
    out.mkdir(parents=True)  # a folder that was there: only what the run made goes
    (out / "notes.txt").write_text("mine")
    trainer.interrupted = False
    with pytest.raises(KeyboardInterrupt):
        with run_folder(out, trainer):
            (out / "metrics.csv").write_text("of the stopped run")
            trainer.interrupted = True
            raise SystemExit(1)
    assert sorted(path.name for path in out.iterdir()) == ["notes.txt"]
    trainer.interrupted = False
    with pytest.raises(KeyboardInterrupt):  # a checkpoint saved: the run resumes from it, and keeps all
        with run_folder(out, trainer):
            (out / "checkpoints").mkdir()
            (out / "checkpoints" / "last.ckpt").write_text("a checkpoint")
            trainer.interrupted = True
            raise SystemExit(1)
    assert (out / "checkpoints" / "last.ckpt").is_file()


@pytest.mark.parametrize("override, message", [
    ("out=null", "out: the folder of the training runs is null; give one, e.g. out=runs"),
    ("name=~", "name: the run's folder name inside out= is null; give one, e.g. name=tiny"),
    ("trainer.strategy=null", "trainer.strategy=null: not one this training takes"),
    ("trainer.precision=~", "trainer.precision=null: not one this training takes"),
    ("trainer.devices=null", "trainer.devices=null: training runs on the CPU here"),
])
def test_training_settings_of_null_are_named_as_null(override, message, tmp_path, one_line_error, no_trainer):
    # P14: "trainer.strategy=None", and out=null an internal error (a path of None)
    if override.startswith("trainer.devices"):
        import torch

        if torch.cuda.is_available():
            pytest.skip("a GPU here: devices=null is not refused for the CPU")
    assert main(["train", "--no-progress", f"data.path={tmp_path / 'none'}", f"out={tmp_path / 'runs'}", *TINY,
                 override]) == 2
    line = one_line_error()
    assert message in line and "None" not in line
    assert not (tmp_path / "runs").exists() and not Path("None").exists()

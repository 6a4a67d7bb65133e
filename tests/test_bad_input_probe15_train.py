"""Bad input of the fifteenth probe of issue 55 (docs/bad_input.md, "Probe 15") to training (Q5-Q8, Q11): a fresh
run replaced a config.yaml or hparams.yaml in its folder without a word, and trained into the dataset's own folder
(``out=dsk name=shards``), or called the dataset "an earlier training run" (``out=. name=dsk``); ``--resume`` cut
metrics.csv to the session's rows, and, at or past the checkpoint's step, trained nothing and still wrote its model
and metrics anew; ``data.val_scenes`` took no seed range (``procedural:11-12`` "is not a scene of the dataset"), and
an empty list fell back to the val_fraction split in silence."""

from __future__ import annotations

import csv
import re
import shutil

import pytest

from conftest import folder_files
from frontiernet.cli.main import main
from test_bad_input_probe14_train import TINY, no_trainer  # noqa: F401 (a fixture)


def train_args(data, out, *more) -> list[str]:
    return ["train", "--no-progress", f"data.path={data}", f"out={out}", "name=tiny", *TINY, *more]


@pytest.fixture(scope="module")
def trained(two_scenes, tmp_path_factory):
    """A finished tiny run of 2 steps (its last checkpoint at step 2); tests resume copies of it."""
    runs = tmp_path_factory.mktemp("runs")
    assert main(train_args(two_scenes, runs, "trainer.max_steps=2", "trainer.log_every_n_steps=1")) == 0
    return runs / "tiny"


def metric_rows(path) -> list[tuple[str, str]]:
    """(step, train/loss) of each row of a metrics CSV file."""
    with open(path, newline="") as handle:
        return [(row["step"], row.get("train/loss", "")) for row in csv.DictReader(handle)]


@pytest.mark.parametrize("name", ["config.yaml", "hparams.yaml", "checkpoints"])
def test_a_fresh_run_is_refused_where_it_would_replace_a_file_a_run_writes(name, two_scenes, tmp_path, one_line_error,
                                                                           no_trainer):
    # Q5: runs/mine/config.yaml (a user's) replaced by the run's, as hparams.yaml; a file named checkpoints
    run = tmp_path / "runs" / "tiny"
    run.mkdir(parents=True)
    (run / name).write_text("my: precious")
    assert main(train_args(two_scenes, tmp_path / "runs")) == 2
    shown = "checkpoints/" if name == "checkpoints" else name
    assert one_line_error().endswith(f"error: {run}: holds an earlier training run's files ({shown}), which a new run "
                                     "would replace; it has no checkpoint to resume from: choose another out= or "
                                     "name=, or move them away")
    assert folder_files(run) == {run.joinpath(name).relative_to(run): b"my: precious"}


@pytest.mark.parametrize("inside", [False, True])
def test_a_run_folder_that_is_or_is_inside_the_dataset_is_refused(inside, two_scenes, one_line_error, no_trainer):
    # Q5: out=dsk name=shards trained among the dataset's shards; Q6: out=. name=dsk called datagen's summary.json
    # "an earlier training run's files"
    before = folder_files(two_scenes)
    out, name = (two_scenes, "shards") if inside else (two_scenes.parent, two_scenes.name)
    assert main(["train", "--no-progress", f"data.path={two_scenes}", f"out={out}", f"name={name}", *TINY]) == 2
    where = f"is inside the dataset (data.path={two_scenes})" if inside else \
        f"is the dataset (data.path={two_scenes}) itself"
    assert one_line_error().endswith(f"error: {out / name}: the run folder (out=, name=) {where}, which the training "
                                     "reads; choose another out= or name=")
    assert folder_files(two_scenes) == before


def test_a_resumed_run_continues_its_metrics_csv(trained, two_scenes, tmp_path, capsys):
    # Q7: Lightning's CSV logger started metrics.csv afresh: after --resume it held the new session's rows only
    run = shutil.copytree(trained, tmp_path / "tiny")
    earlier = metric_rows(run / "metrics.csv")
    assert [step for step, loss in earlier if loss] == ["0", "1"]
    with pytest.warns() as said:
        assert main(train_args(two_scenes, tmp_path, "trainer.max_steps=3", "trainer.log_every_n_steps=1",
                               "--resume")) == 0
    assert not [warning for warning in said if "will be deleted" in str(warning.message)]  # (no longer true)
    rows = metric_rows(run / "metrics.csv")
    new = [int(step) for step, loss in rows[len(earlier):] if loss]  # (the third step's loss)
    assert rows[:len(earlier)] == earlier and len(new) == 1 and new[0] >= 2, rows
    assert metric_rows(run / "metrics-part1.csv") == earlier  # the rows as they stood at the resume, kept


@pytest.mark.parametrize("budget, message", [
    (["trainer.max_steps=2"], "trainer.max_steps=2: the checkpoint {ckpt} is at step 2 already; give more steps"),
    (["trainer.max_steps=1"], "trainer.max_steps=1: the checkpoint {ckpt} is at step 2 already; give more steps"),
    (["trainer.max_steps=-1", "trainer.max_epochs=1"],
     "trainer.max_epochs=1: the checkpoint {ckpt} is at epoch 2 already; give more epochs"),
])
def test_a_resume_with_no_steps_left_is_refused_and_rewrites_nothing(budget, message, trained, two_scenes, tmp_path,
                                                                     one_line_error):
    # Q8: trained nothing, said "trained 2 steps", and wrote model.safetensors and a metrics.csv of one row anew
    run = shutil.copytree(trained, tmp_path / "tiny")
    before = folder_files(run)
    assert main(train_args(two_scenes, tmp_path, *budget, "--resume")) == 2
    line = one_line_error()
    assert message.format(ckpt=run / "checkpoints" / "last.ckpt") in line, line
    assert folder_files(run) == before


def test_val_scenes_take_seed_ranges_and_refuse_an_empty_list(two_scenes, tmp_path, capsys, one_line_error,
                                                              no_trainer):
    # Q11: 'procedural:3-4' "is not a scene of the dataset"; [] fell back to the val_fraction split in silence
    from train.config import load_train_config

    conf = load_train_config(None, [f"data.path={two_scenes}", "data.val_scenes=[procedural:3-4, procedural:7]"])
    assert list(conf.data.val_scenes) == ["procedural:3", "procedural:4", "procedural:7"]
    args = ["train", "--no-progress", f"data.path={two_scenes}", f"out={tmp_path / 'runs'}", *TINY]
    assert main(args + ["data.val_scenes=[procedural:4-4]"]) == 1  # every check passed: the trainer's turn
    assert "the trainer was set up" in capsys.readouterr().err
    assert main(args + ["data.val_scenes=[]"]) == 2
    assert one_line_error().endswith("error: data.val_scenes is an empty list: give scenes, or null for the "
                                     "val_fraction split")
    assert main(args + ["data.val_scenes=[procedural:3-x]"]) == 2
    assert re.search(r"error: data\.val_scenes: .*procedural:3-x", one_line_error())
    assert not (tmp_path / "runs").exists()

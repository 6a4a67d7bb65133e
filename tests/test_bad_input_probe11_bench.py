"""Bad input of the eleventh probe of issue 55 (runs/probe11_report.md) in benchmark folders, its Q5, Q9, Q10 and
Q14: `bench --report`, `--pack` and a resume on a folder whose `runs` is a file, whose plan.json is a folder or a
pipe, whose results.csv is a folder: each refusal one line naming the file, exit code 2, nothing written lost."""

from __future__ import annotations

import gzip
import os
import shutil
import subprocess
import sys

import pytest

from conftest import copy_tracked, folder_files
from frontiernet.cli.main import main
from test_benchmark import bench


def refused(*args) -> bool:
    """Whether ``frontiernet bench ARGS`` exits 2 (its stderr is left for ``one_line_error``)."""
    return main(["bench", *map(str, args)]) == 2

SMALL = "docs/benchmark/loop_fixes/base"
"""A small tracked benchmark folder (40 packed runs), copied, never written to (tests/test_readme_table.py)."""


@pytest.fixture
def small(tmp_path):
    """A copy of :data:`SMALL`'s tracked files, its plan unpacked (plan.json, as a benchmark writes it)."""
    folder = copy_tracked(SMALL, tmp_path / "bench")
    (folder / "plan.json").write_bytes(gzip.decompress((folder / "plan.json.gz").read_bytes()))
    (folder / "plan.json.gz").unlink()
    return folder


@pytest.mark.parametrize("action", ["--report", "--pack"])
def test_a_runs_file_is_refused_and_the_plan_kept(action, small, one_line_error):
    # Q5: --report an internal error (NotADirectoryError); Q10: --pack "packed 0 run(s)", exit 0, the plan gzipped
    shutil.rmtree(small / "runs")
    (small / "runs").write_text("not the runs\n")
    before = folder_files(small)
    assert refused(action, "--out", small)
    assert one_line_error().endswith(f"{small / 'runs'}: is a file, expected the benchmark's runs folder")
    assert folder_files(small) == before  # the plan not packed, no report written


def test_a_file_in_the_way_of_a_runs_metrics_is_named_not_an_internal_error(small, one_line_error):
    # Q5 (read_metrics): an OSError reading a run's metrics.json was no "not a run's metrics"
    scene = small / "runs" / "procedural_2000-0bf50f"
    shutil.rmtree(scene)
    scene.write_text("")
    assert refused("--report", "--out", small)
    error = one_line_error()
    assert f"{scene}/" in error and "metrics.json: not a run's metrics (Not a directory)" in error
    assert not (small / "results.csv").exists()


def test_a_metrics_file_that_is_a_pipe_is_refused_not_waited_on(tmp_path):
    # (Q5's read_metrics: a pipe's read would wait for a writer)
    path = tmp_path / "metrics.json"
    os.mkfifo(path)
    code = ("import sys; from frontiernet.benchmark.store import read_metrics; from frontiernet.errors import "
            f"InputError\ntry:\n    read_metrics({str(path)!r})\nexcept InputError as error:\n    print(error)")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.stdout.strip() == (f"{path}: not a run's metrics (not a regular file); remove the run's folder to "
                                     "run it again"), result.stderr


@pytest.mark.parametrize("action", ["--report", "--pack"])
def test_a_plan_that_is_a_folder_is_named_not_missing(action, small, one_line_error):
    # Q14: "no benchmark here (no plan.json)"
    (small / "plan.json").unlink()
    (small / "plan.json").mkdir()
    before = folder_files(small)
    assert refused(action, "--out", small)
    assert one_line_error().endswith(f"{small / 'plan.json'}: is a folder, expected a file (benchmark plan)")
    assert folder_files(small) == before and (small / "plan.json").is_dir()


def test_a_resume_on_a_plan_that_is_a_folder_names_it(small, one_line_error):
    # (Q14 for a benchmark run: "holds files but no benchmark (no plan.json)")
    (small / "plan.json").unlink()
    (small / "plan.json").mkdir()
    before = folder_files(small)
    assert refused("--scenes", "procedural:3", "--methods", "classic", "--max-steps", "4", "--out", small)
    assert one_line_error().endswith(f"{small / 'plan.json'}: is a folder, expected a file (benchmark plan)")
    assert folder_files(small) == before


def test_a_plan_that_is_a_pipe_is_named_not_missing(small):
    # Q14 (a FIFO): "no benchmark here (no plan.json)"; in a process of its own, should it wait on the pipe
    plan = small / "plan.json"
    plan.unlink()
    os.mkfifo(plan)
    code = ("import sys; from frontiernet.cli.main import main; "
            f"sys.exit(main(['bench', '--report', '--out', {str(small)!r}]))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert (result.returncode, result.stderr.strip()) == (
        2, f"frontiernet bench: error: {plan}: not a regular file, expected a file (benchmark plan)")
    assert not (small / "results.csv").exists()


def test_report_files_are_checked_before_redo_changed_discards_runs(plan_spec, tmp_path, caplog, one_line_error):
    # Q9: "... 1 finished runs of them discarded, to run again", then the refusal for results.csv
    out = tmp_path / "bench"
    args = ["--scenes", plan_spec, "--methods", "classic", "--starts", "1", "--repeats", "1", "--max-steps", "4",
            "--depth", "gt,emulated", "--out", out]
    code, _, stderr = bench(*args)
    assert code == 0, stderr
    (out / "results.csv").unlink()
    (out / "results.csv").mkdir()
    before = folder_files(out)
    caplog.clear()
    assert refused(*args, "--set", "map.monocular_log_odds_miss=-1.2", "--redo-changed")
    assert one_line_error().endswith(f"{out / 'results.csv'}: a folder is where the run writes its results.csv; "
                                     "remove it, or choose another --out")
    assert "discarded" not in caplog.text
    assert folder_files(out) == before  # the emulated run's metrics kept, the plan as it was
    assert refused("--report", "--out", out)  # and --report before it writes table.md, plots
    assert "results.csv: a folder is where the run writes" in one_line_error() and folder_files(out) == before

"""The parallel runner (frontiernet/workers.py: run_parallel) that datagen and the benchmark share:
results in task order, a task whose worker process died is rerun a bounded number of times then
reported failed, SIGTERM to the parent ends every worker. The commands' own tests:
tests/test_datagen_run.py (kills), tests/test_benchmark.py, tests/test_bad_input.py (SIGTERM)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

from conftest import check_sigterm_ends_workers
from frontiernet.workers import run_parallel


def double_but_die_first(marker: str, value: int) -> int:
    """2 * `value`; the first call of all that share `marker` (a file path) ends its process
    abruptly instead, as a worker killed mid-task."""
    try:
        os.close(os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
    except FileExistsError:
        return 2 * value
    os._exit(1)


def always_die() -> None:
    os._exit(1)


def died(index: int, error: str) -> dict:
    return {"index": index, "error": error}


def test_a_task_whose_worker_died_is_rerun_and_every_result_arrives_in_task_order(tmp_path, caplog):
    marker = str(tmp_path / "died")
    arrived = []
    results = run_parallel(double_but_die_first, [(marker, value) for value in range(5)], workers=2,
                           on_result=lambda index, result: arrived.append((index, result)), died=died)
    assert Path(marker).exists()  # a worker did die
    assert results == [0, 2, 4, 6, 8]
    assert sorted(arrived) == [(index, 2 * index) for index in range(5)]  # each result once
    assert "a worker process died; retrying" in caplog.text


def test_a_task_whose_worker_dies_every_time_is_reported_through_died():
    results = run_parallel(always_die, [()], workers=2, died=died, retries=1)
    assert results == [{"index": 0, "error": "worker process died twice (killed or out of memory)"}]


def test_one_local_worker_runs_the_tasks_in_this_process():
    assert run_parallel(os.getpid, [(), ()], workers=1, died=died) == [os.getpid()] * 2


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads worker processes from Linux's /proc")
def test_sigterm_to_the_parent_ends_every_worker_and_interrupts_it():
    script = ("import sys, time; from frontiernet.workers import run_parallel\n"
              "try:\n"
              "    run_parallel(time.sleep, [(600,)] * 3, workers=2, died=lambda index, error: None)\n"
              "except KeyboardInterrupt:\n"
              "    print('interrupted', file=sys.stderr)\n"
              "    sys.exit(130)\n")
    check_sigterm_ends_workers([], command=[sys.executable, "-c", script])


@pytest.mark.slow
def test_ray_reruns_a_task_whose_worker_died(tmp_path, monkeypatch):
    pytest.importorskip("ray")
    # Ray's workers import this module by name (the library's own tasks live in the package); pytest
    # put tests/ on this process's path only, the local Ray instance inherits the environment
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(Path(__file__).parent), os.environ.get("PYTHONPATH", "")]))
    marker = str(tmp_path / "died")
    results = run_parallel(double_but_die_first, [(marker, value) for value in range(3)], backend="ray",
                           workers=2, died=died)
    assert Path(marker).exists() and results == [0, 2, 4]

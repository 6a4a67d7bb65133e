"""Benchmark runs: one exploration each, in parallel, resumable, failures recorded.

:func:`run_one` never raises: a run that fails comes back as a row with its error (and
``failed/<key>.json`` records it; a later invocation tries it again), so one bad run never
stops a benchmark. A finished run (``runs/<key>/metrics.json``, or its line in a pack:
:mod:`.store`) is never redone: an interrupted benchmark resumes where it stopped. Runs write
into ``<key>.partial`` and are renamed when complete, so a half-written run is never taken for a
finished one. A run marked
``copy_of`` another (a repeat that would be identical, :mod:`.plan`) is not run: its row is the
other run's, with its own scene, start, repeat and seed.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import sys
import time
from pathlib import Path

from ..errors import InputError
from ..workers import BACKENDS, check_backend, run_parallel
from .store import FinishedRuns, read_metrics

log = logging.getLogger(__name__)

ROW_FIELDS = ("scene", "method", "start", "repeat", "seed", "status", "error", "steps", "max_steps", "coverage",
              "vox25", "vox50", "vox100", "success", "surface_coverage", "surface_auc", "chamfer_m", "completeness",
              "path_length_m", "collisions", "step_ms", "wall_s", "stop_reason", "copy_of")
_IDENTITY = ("scene", "method", "depth", "start", "repeat", "seed", "key", "copy_of")
"""A row's fields from its run; ``depth`` is None in a benchmark of one depth source (and
results.csv has no such column then: :func:`~frontiernet.benchmark.report.write_report`)."""


def _row(run: dict, status: str, record: dict | None = None, error: str = "") -> dict:
    row = {name: run.get(name) for name in _IDENTITY}
    row.update(status=status, error=error)
    if record is not None:
        vox = record["vox_at"]
        row.update(steps=record["steps"], max_steps=record["max_steps"], coverage=record["coverage"],
                   vox25=vox["25"], vox50=vox["50"], vox100=vox["100"], success=record["success"],
                   surface_coverage=record["surface_coverage"], surface_auc=record["surface_auc"],
                   chamfer_m=record["chamfer_m"], completeness=record["completeness"],
                   path_length_m=record["path_length_m"], collisions=record["collisions"],
                   step_ms=record["timing"]["step_ms_without_motion"], wall_s=record["wall_s"],
                   stop_reason=record["stop_reason"])
    return row


def _limit_threads(threads: int) -> None:
    """Keep a worker to its share of the cores (torch and numba would each take all of them)."""
    try:
        import torch

        torch.set_num_threads(threads)
    except Exception:  # pragma: no cover - torch is a dependency; never fail a run over threads
        pass
    try:
        import numba

        numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    except Exception:  # pragma: no cover
        pass


def _failed_path(out: Path, key: str) -> Path:
    return Path(out) / "failed" / (key.replace("/", "__") + ".json")


def finished_row(run: dict, finished: FinishedRuns) -> dict | None:
    """The row of `run` (a plan's run dict) if it finished (`finished`: the runs of its benchmark
    folder, per run or packed) or failed, else None (not run yet). Runs nothing."""
    record = finished.metrics(run["key"])
    if record is not None:
        return _row(run, "done", record)
    failed = _failed_path(finished.out, run["key"])
    if failed.is_file():
        return _row(run, "failed", error=json.loads(failed.read_text())["error"])
    return None


def _copied_row(run: dict, original: dict) -> dict:
    """The row of `run`, a copy of the run whose row is `original` (see the module docstring)."""
    if original["status"] != "done":
        return _row(run, "failed", error=f"the run it repeats ({run['copy_of']}) failed: {original['error']}")
    return {**original, **{name: run.get(name) for name in _IDENTITY}}


def with_copies(runs: list[dict], rows_by_key: dict) -> list:
    """The rows of `runs` in order: a run's own row, or for a run marked ``copy_of`` its original's
    (:func:`_copied_row`); None where that row is missing."""
    rows = []
    for run in runs:
        original = rows_by_key.get(run.get("copy_of") or run["key"])
        rows.append(_copied_row(run, original) if original is not None and run.get("copy_of") else original)
    return rows


def run_one(run: dict, settings: dict) -> dict:
    """Run (or find finished) one benchmark run; returns its result row. Never raises.

    Args:
        run: a :class:`~frontiernet.benchmark.plan.RunSpec` as a dict, plus its ``key``.
        settings: ``out`` (benchmark folder), ``conf`` (the explore config as a dict),
            ``max_steps``, ``model``, ``depth`` (the benchmark's one source, or None: ``run.depth``;
            a run that carries its own ``depth`` takes that; likewise its own ``max_steps``: its
            scene's budget), ``threads``.
    """
    from omegaconf import OmegaConf

    from ..exploration.methods import runs_frontiernet_model
    from ..exploration.run import main

    out = Path(settings["out"])
    final, failed = out / "runs" / run["key"], _failed_path(out, run["key"])
    if (final / "metrics.json").is_file():  # (run_all leaves out the runs finished before, packed ones too)
        return _row(run, "done", read_metrics(final / "metrics.json"))
    partial = final.with_name(final.name + ".partial")
    shutil.rmtree(partial, ignore_errors=True)
    _limit_threads(int(settings["threads"]))
    try:
        record = main(OmegaConf.create(settings["conf"]), run["scene"], partial, method=run["method"],
                      model=settings["model"] if runs_frontiernet_model(run["method"]) else None,  # --model's methods
                      depth=run.get("depth") or settings["depth"],
                      max_steps=int(run.get("max_steps") or settings["max_steps"]),
                      start=",".join(str(v) for v in run["start_pose"]), seed=int(run["seed"]), video=False,
                      progress=False)
        shutil.rmtree(final, ignore_errors=True)
        os.replace(partial, final)
        failed.unlink(missing_ok=True)
        return _row(run, "done", record)
    except Exception as error:  # a failing run is recorded, never stops the benchmark
        log.debug("run %s failed", run["key"], exc_info=True)
        message = (str(error).splitlines() or [type(error).__name__])[0]
        if not isinstance(error, InputError):
            message = f"{type(error).__name__}: {message}"
        failed.parent.mkdir(parents=True, exist_ok=True)
        tmp = failed.with_suffix(".tmp")
        tmp.write_text(json.dumps({**run, "error": message}, indent=1))
        os.replace(tmp, failed)
        shutil.rmtree(partial, ignore_errors=True)
        return _row(run, "failed", error=message)


def run_all(runs, settings: dict, workers: int = 1, backend: str = "local", progress: bool = True) -> list[dict]:
    """Every run of `runs` (:class:`~frontiernet.benchmark.plan.RunSpec`), rows in the same order;
    runs marked ``copy_of`` another take its row (the other run must be among `runs`).

    Args:
        workers: parallel runs (local processes, or Ray tasks in flight); each gets
            ``cores // workers`` threads (at least 1).
        backend: ``local`` (processes on this machine) or ``ray`` (a Ray cluster: connects to
            ``RAY_ADDRESS`` when set; needs the ``ray`` extra).

    Runs go through :func:`frontiernet.workers.run_parallel`: a run whose worker process dies is
    run once more, then its row is failed; Ctrl-C or SIGTERM ends every worker.
    """
    workers = check_backend(backend, workers)
    every = [{**run.as_dict(), "key": run.key} for run in runs]
    done = {}  # finished before: read here, so progress (and its time left) counts only runs to do
    finished = FinishedRuns(settings["out"])
    for task in every:
        row = None if task["copy_of"] else finished_row(task, finished)
        if row is not None and row["status"] == "done":
            done[task["key"]] = row
    tasks = [task for task in every if not task["copy_of"] and task["key"] not in done]
    settings = {**settings, "threads": max(1, (os.cpu_count() or 1) // workers)}
    with _Progress(len(tasks), progress) as bar:
        rows = run_parallel(run_one, [(task, settings) for task in tasks], backend=backend, workers=workers,
                            on_result=lambda index, row: bar.advance(row),
                            died=lambda index, error: _row(tasks[index], "failed", error=error),
                            cpus_per_task=settings["threads"])
    return with_copies(every, {**done, **{row["key"]: row for row in rows}})


def time_left(elapsed_s: float, finished: int, total: int) -> str:
    """How long the runs not yet finished will take at the rate so far, for a log line: ``about
    6.1 h left`` (``min`` under an hour, ``s`` under a minute); "" before the first run or after
    the last. The rate is wall time per finished run of this invocation, so parallel workers and
    whatever else the machine does are in it.

    Args:
        elapsed_s: wall time since the first run started (s).
        finished: runs finished so far; total: runs this invocation runs.
    """
    if finished <= 0 or finished >= total:
        return ""
    seconds = elapsed_s / finished * (total - finished)
    if seconds >= 3600:
        return f"about {seconds / 3600:.1f} h left"
    return f"about {seconds / 60:.0f} min left" if seconds >= 60 else f"about {seconds:.0f} s left"


class _Progress:
    """A rich progress bar over the runs on a terminal; elsewhere (a log file of a background
    run) a line per finished run, with the time left (:func:`time_left`); silent when disabled."""

    def __init__(self, total: int, enabled: bool) -> None:
        self.total, self.enabled, self._bar, self._count = total, enabled, None, 0
        self._lines = enabled and not sys.stderr.isatty()
        self._started = time.monotonic()

    def __enter__(self):
        if self.enabled and not self._lines:
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

            self._bar = Progress(TextColumn("bench"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                                 TextColumn("{task.fields[last]}"))
            self._bar.__enter__()
            self._task = self._bar.add_task("runs", total=self.total, last="")
        return self

    def advance(self, row: dict) -> None:
        self._count += 1
        last = f"{row['method']} {row['status']}"
        if row["status"] == "done":
            last += f" {row.get('coverage', 0):.1%}"
        if self._bar is not None:
            self._bar.update(self._task, advance=1, last=last)
        elif self._lines:
            took = f" in {row['wall_s']:.0f} s" if row.get("wall_s") is not None else ""
            left = time_left(time.monotonic() - self._started, self._count, self.total)
            print(f"bench {self._count}/{self.total}: {row['key']} {last}{took}{'; ' + left if left else ''}",
                  file=sys.stderr, flush=True)

    def __exit__(self, *exc) -> None:
        if self._bar is not None:
            self._bar.__exit__(*exc)


__all__ = ["run_one", "run_all", "time_left", "finished_row", "with_copies", "BACKENDS", "ROW_FIELDS"]

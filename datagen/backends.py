"""Run shard tasks: in this process, on local worker processes, or as Ray tasks
(:func:`frontiernet.workers.run_parallel`).

Every backend runs the same function, :func:`run_shard_task`, which never raises: a
failing scene comes back as a result with its error, so one bad scene never stops a run.
A worker process that dies (killed, out of memory) costs the shards it was writing one
retry; a second death marks them failed. On Ray (``--backend ray``) the run connects to the
cluster named by ``RAY_ADDRESS`` (``ray start --head`` on one machine, ``ray start
--address=...`` on the others), or starts a local Ray instance; every node must see the output
folder (a shared file system) and the scene files at the same paths.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
import queue
import time

import numpy as np
from omegaconf import OmegaConf

from frontiernet.errors import InputError
from frontiernet.simulator.raycast import select_backend
from frontiernet.workers import check_backend, run_parallel, sigterm_as_interrupt

from .summary import scene_error

log = logging.getLogger(__name__)

MAX_ATTEMPTS = 2
_CACHE: dict = {}  # per process: (scene spec, config hash) -> (scene, voxels, generator), the last two
_PROGRESS = None  # per worker process: a queue that receives one item per computed view


def _scene_state(spec: str, conf):
    """Scene, voxel grid and ground-truth generator of `spec`, cached per process.

    The cache key includes the config: one process may run datasets of different configs
    (workers=1 runs in the caller's process, a Ray worker serves several runs)."""
    from .config import config_hash

    key = (spec, config_hash(conf))
    if key not in _CACHE:
        from frontiernet.simulator.world import build_world

        from .ground_truth import GroundTruthGenerator

        while len(_CACHE) >= 2:
            _CACHE.pop(next(iter(_CACHE)))
        world = build_world(spec, conf, conf.scenes)
        _CACHE[key] = (world.scene, world.voxels,
                       GroundTruthGenerator(world.scene, world.voxels, conf, renderer=world.renderer))
    return _CACHE[key]


def _record(truth, kind: str, spec: str, camera, num_classes: int) -> dict:
    return {"scene": spec, "T_world_cam": truth.T_world_cam.tolist(), "K": truth.K.tolist(),
            "width": camera.width, "height": camera.height, "max_depth": camera.max_depth, "view_kind": kind,
            "frontier_pixels": int(truth.frontier_mask.sum()),
            "frontier_projected_pixels": int(truth.frontier_projected.sum()),
            "frontier_voxels": len(truth.frontier_voxels), "observed_voxels": truth.observed_voxels,
            "max_gain_m3": float(truth.gain.max(initial=0.0)),
            "class_histogram": np.bincount(truth.gain_class.reshape(-1), minlength=num_classes).tolist()}


def _report_view() -> None:
    """One view done: tell the progress bar; a lost progress channel never fails a shard."""
    try:
        _PROGRESS.put(1)
    except Exception:  # the manager process is gone (the run is being torn down)
        pass


def run_shard_task(task: dict, conf_dict: dict, info: dict) -> dict:
    """Generate and write one shard (see :class:`datagen.generate.ShardTask`); never raises.

    Returns a result dict: task name, spec, ``ok``, and either the view/candidate counts
    and per-stage seconds or ``error`` (one line).
    """
    from .shards import write_shard
    from .views_balance import shard_views

    start = time.perf_counter()
    name = os.path.basename(task["path"])
    try:
        conf = OmegaConf.create(conf_dict)
        raycast = select_backend(conf.raycast.backend)
        scene, voxels, generator = _scene_state(task["spec"], conf)
        loaded = time.perf_counter()
        rng = np.random.default_rng(task["seed"])
        on_view = _report_view if _PROGRESS is not None else None
        views, tried = shard_views(generator, task["num_views"], rng, conf, on_view=on_view)
        num_classes = len(conf.ground_truth.gain.bin_edges)
        samples, timings = [], {}
        for truth, kind in views:
            samples.append({**truth.arrays(), "record": _record(truth, kind, task["spec"], generator.camera,
                                                                  num_classes)})
            for stage, seconds in truth.timings.items():
                timings[stage] = timings.get(stage, 0.0) + seconds
        meta = {"scene": task["spec"], "scene_index": task["scene_index"], "shard_index": task["shard_index"],
                "seed": task["seed"], "candidates": tried, "config_hash": info["config_hash"],
                "generator_version": info["generator_version"]}
        write_shard(task["path"], samples, meta, conf.writer)
        return {"task": name, "spec": task["spec"], "ok": True, "views": len(views), "candidates": tried,
                "seconds": time.perf_counter() - start, "load_seconds": loaded - start, "timings": timings,
                "pid": os.getpid(), "raycast_backend": raycast}
    except InputError as error:
        message, bad_input = scene_error(task["spec"], error), True
    except Exception as error:  # a failing scene is reported, never kills the run
        log.debug("shard %s failed", name, exc_info=True)
        message, bad_input = f"{type(error).__name__}: {error}", False
    return {"task": name, "spec": task["spec"], "ok": False, "error": message.splitlines()[0] if message else "",
            "bad_input": bad_input, "seconds": time.perf_counter() - start}


def _init_worker(progress_queue, threads: int) -> None:
    global _PROGRESS
    _PROGRESS = progress_queue
    try:
        import numba

        numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    except Exception:  # pragma: no cover - numba without threading layer
        pass


class _Bar:
    """A rich progress bar counting views (views/s shown) and failed shards, or nothing when disabled."""

    def __init__(self, total: int, enabled: bool) -> None:
        self.progress, self.failed = None, 0
        if enabled:
            from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                                       TimeRemainingColumn)

            self.progress = Progress(TextColumn("datagen"), BarColumn(), MofNCompleteColumn(),
                                     TextColumn("views  {task.fields[rate]} views/s  {task.fields[failed]}"),
                                     TimeElapsedColumn(), TimeRemainingColumn())
            self.task = self.progress.add_task("views", total=total, rate="-", failed="")
            self.start = time.perf_counter()
            self.progress.start()

    def advance(self, views: int = 1) -> None:
        if self.progress is None:
            return
        self.progress.advance(self.task, views)
        done = self.progress.tasks[0].completed
        rate = done / max(time.perf_counter() - self.start, 1e-9)
        failed = f"{self.failed} failed shard(s)" if self.failed else ""
        self.progress.update(self.task, rate=f"{rate:.2f}", failed=failed)

    def close(self) -> None:
        if self.progress is not None:
            self.progress.stop()


def run_tasks(tasks: list[dict], conf_dict: dict, info: dict, *, backend: str = "local", workers: int = 1,
              progress: bool = True, total_views: int = 0) -> list[dict]:
    """Run shard tasks with :func:`frontiernet.workers.run_parallel`; one result per task, in the
    order of `tasks`. The progress bar counts views as the workers make them (as shards finish on
    Ray); a shard whose worker process died twice comes back failed."""
    check_backend(backend, workers)
    if not tasks:
        return []
    bar = _Bar(total_views, progress)

    def on_result(index: int, result: dict) -> None:
        bar.failed += not result["ok"]
        bar.advance(tasks[index]["num_views"] if backend == "ray" else 0)  # (else the views came by the channel)

    def died(index: int, error: str) -> dict:
        return {"task": os.path.basename(tasks[index]["path"]), "spec": tasks[index]["spec"], "ok": False,
                "error": error, "seconds": 0.0}

    try:
        with _view_channel(backend, workers, bar) as (initializer, initargs, poll):
            return run_parallel(run_shard_task, [(task, conf_dict, info) for task in tasks], backend=backend,
                                workers=workers, on_result=on_result, died=died, retries=MAX_ATTEMPTS - 1,
                                initializer=initializer, initargs=initargs, poll=poll)
    finally:
        bar.close()


class _BarQueue:
    """Stands in for the worker progress queue when shards run in this process."""

    def __init__(self, bar: _Bar) -> None:
        self.bar = bar

    def put(self, item) -> None:
        self.bar.advance(item)


@contextlib.contextmanager
def _view_channel(backend: str, workers: int, bar: _Bar):
    """How views made reach `bar`: yields (worker initializer, its arguments, poll) for
    :func:`~frontiernet.workers.run_parallel`. Shards in this process put into the bar directly;
    worker processes into a queue of a spawned manager process (which survives a worker killed
    mid-put), read by poll; Ray tasks send nothing (the bar advances by shard)."""
    global _PROGRESS
    if backend == "ray":
        yield None, (), None
    elif workers == 1:
        _PROGRESS = _BarQueue(bar)
        try:
            yield None, (), None
        finally:
            _PROGRESS = None
    else:
        with sigterm_as_interrupt():  # a stop while the manager starts ends it too
            manager = multiprocessing.get_context("spawn").Manager()
            try:
                progress_queue = manager.Queue()
                threads = max(1, (os.cpu_count() or 1) // workers)
                yield _init_worker, (progress_queue, threads), lambda: _drain(progress_queue, bar)
            finally:
                manager.shutdown()


def _drain(progress_queue, bar: _Bar) -> None:
    count = 0
    try:
        while True:
            count += progress_queue.get_nowait()
    except (queue.Empty, EOFError, OSError):
        pass
    if count:
        bar.advance(count)

"""Run shard tasks: in this process, on local worker processes, or as Ray tasks.

Every backend runs the same function, :func:`run_shard_task`, which never raises: a
failing scene comes back as a result with its error, so one bad scene never stops a run.
A worker process that dies (killed, out of memory) costs the shards it was writing one
retry; a second death marks them failed.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import queue
import time
from concurrent.futures import FIRST_COMPLETED, wait
from concurrent.futures.process import BrokenProcessPool

import numpy as np
from omegaconf import OmegaConf

from frontiernet.errors import InputError
from frontiernet.simulator.raycast import select_backend
from frontiernet.workers import check_backend, process_pool, sigterm_as_interrupt

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
        from frontiernet.scenes import load_scene
        from frontiernet.simulator.voxels import voxelize_scene

        from .ground_truth import GroundTruthGenerator

        while len(_CACHE) >= 2:
            _CACHE.pop(next(iter(_CACHE)))
        scene = load_scene(spec)
        voxels = voxelize_scene(scene, conf.voxels)
        _CACHE[key] = (scene, voxels, GroundTruthGenerator(scene, voxels, conf))
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
        message = str(error)
    except Exception as error:  # a failing scene is reported, never kills the run
        log.debug("shard %s failed", name, exc_info=True)
        message = f"{type(error).__name__}: {error}"
    return {"task": name, "spec": task["spec"], "ok": False, "error": message.splitlines()[0] if message else "",
            "seconds": time.perf_counter() - start}


def _init_worker(progress_queue, threads: int) -> None:
    global _PROGRESS
    _PROGRESS = progress_queue
    try:
        import numba

        numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    except Exception:  # pragma: no cover - numba without threading layer
        pass


class _Bar:
    """A rich progress bar counting views (views/s shown), or nothing when disabled."""

    def __init__(self, total: int, enabled: bool) -> None:
        self.progress = None
        if enabled:
            from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                                       TimeRemainingColumn)

            self.progress = Progress(TextColumn("datagen"), BarColumn(), MofNCompleteColumn(),
                                     TextColumn("views  {task.fields[rate]} views/s  {task.fields[failed]}"),
                                     TimeElapsedColumn(), TimeRemainingColumn())
            self.task = self.progress.add_task("views", total=total, rate="-", failed="")
            self.start = time.perf_counter()
            self.progress.start()

    def advance(self, views: int = 1, failed: int = 0) -> None:
        if self.progress is None:
            return
        self.progress.advance(self.task, views)
        done = self.progress.tasks[0].completed
        rate = done / max(time.perf_counter() - self.start, 1e-9)
        self.progress.update(self.task, rate=f"{rate:.2f}", failed=f"{failed} failed shard(s)" if failed else "")

    def close(self) -> None:
        if self.progress is not None:
            self.progress.stop()


def run_tasks(tasks: list[dict], conf_dict: dict, info: dict, *, backend: str = "local", workers: int = 1,
              progress: bool = True, total_views: int = 0) -> list[dict]:
    """Run shard tasks on a backend; returns one result per task (in completion order)."""
    check_backend(backend, workers)
    if not tasks:
        return []
    bar = _Bar(total_views, progress)
    try:
        if backend == "ray":
            from .ray_backend import run_on_ray

            return run_on_ray(tasks, conf_dict, info, workers, bar)
        if workers == 1:
            return _run_inline(tasks, conf_dict, info, bar)
        return _run_processes(tasks, conf_dict, info, workers, bar)
    finally:
        bar.close()


class _BarQueue:
    """Stands in for the worker progress queue when shards run in this process."""

    def __init__(self, bar: _Bar) -> None:
        self.bar = bar

    def put(self, item) -> None:
        self.bar.advance(item)


def _run_inline(tasks, conf_dict, info, bar: _Bar) -> list[dict]:
    global _PROGRESS
    _PROGRESS = _BarQueue(bar)
    try:
        return [run_shard_task(task, conf_dict, info) for task in tasks]
    finally:
        _PROGRESS = None


def _run_processes(tasks, conf_dict, info, workers: int, bar: _Bar) -> list[dict]:
    """Run on a pool of spawned processes; restart the pool when a worker dies. When the run is
    stopped (Ctrl-C, or SIGTERM to this process alone) the workers and the progress queue's
    manager end with it (:func:`frontiernet.workers.process_pool`)."""
    threads = max(1, (os.cpu_count() or 1) // workers)
    attempts = {task["path"]: 0 for task in tasks}
    results: list[dict] = []
    remaining = list(tasks)
    failed = 0
    with sigterm_as_interrupt():
        manager = multiprocessing.get_context("spawn").Manager()
        try:
            progress_queue = manager.Queue()
            while remaining:
                with process_pool(min(workers, len(remaining)), _init_worker, (progress_queue, threads)) as pool:
                    pending = {}
                    for task in remaining:
                        attempts[task["path"]] += 1
                        pending[pool.submit(run_shard_task, task, conf_dict, info)] = task
                    remaining = []
                    while pending:
                        done, _ = wait(pending, timeout=0.25, return_when=FIRST_COMPLETED)
                        _drain(progress_queue, bar, failed)
                        for future in done:
                            task = pending.pop(future)
                            try:
                                result = future.result()
                            except BrokenProcessPool:
                                remaining.append(task)
                                continue
                            results.append(result)
                            failed += not result["ok"]
                retry = [task for task in remaining if attempts[task["path"]] < MAX_ATTEMPTS]
                for task in remaining:
                    if attempts[task["path"]] >= MAX_ATTEMPTS:
                        results.append({"task": os.path.basename(task["path"]), "spec": task["spec"], "ok": False,
                                        "error": "worker process died twice (killed or out of memory)",
                                        "seconds": 0.0})
                        failed += 1
                if remaining:
                    log.warning("a worker process died; retrying %d shard(s)", len(retry))
                remaining = retry
            _drain(progress_queue, bar, failed)
        finally:
            manager.shutdown()
    return results


def _drain(progress_queue, bar: _Bar, failed: int) -> None:
    count = 0
    try:
        while True:
            count += progress_queue.get_nowait()
    except (queue.Empty, EOFError, OSError):
        pass
    if count:
        bar.advance(count, failed)

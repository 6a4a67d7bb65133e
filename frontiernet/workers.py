"""Parallel runs on this machine or a Ray cluster: checking the choice, and ending workers with their parent.

``frontiernet bench --scenes`` and ``frontiernet datagen`` run tasks in spawned worker processes
(or Ray tasks). Both check ``--backend`` / ``--workers`` with :func:`check_backend` before they
write anything, and run their pool inside :func:`process_pool`: when the parent is stopped (Ctrl-C,
or SIGTERM to the parent alone, as ``kill PID`` sends) its workers are terminated with it. Left
running they would go on, unseen, beside a resumed run (each datagen worker holds ~630 MB).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import signal
import threading
from concurrent.futures import ProcessPoolExecutor

from .errors import InputError

BACKENDS = ("local", "ray")


def import_ray():
    """The ``ray`` module; InputError saying how to install it when it is missing."""
    try:
        import ray
    except ImportError:
        raise InputError("--backend ray needs Ray: pip install 'frontiernet[ray]' (or pip install ray)") from None
    return ray


def check_backend(backend: str, workers) -> int:
    """`workers` as an int after checking `backend` is ``local`` or ``ray`` (Ray importable) and
    `workers` >= 1; InputError naming the bad option otherwise."""
    if backend not in BACKENDS:
        raise InputError(f"--backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise InputError(f"--workers must be an integer >= 1, got {workers!r}")
    if backend == "ray":
        import_ray()
    return workers


@contextlib.contextmanager
def sigterm_as_interrupt():
    """Within the block, SIGTERM raises KeyboardInterrupt (as Ctrl-C does), so that cleanup runs
    (``frontiernet`` then exits 130, "interrupted"); the previous handler is restored after. Only
    the main thread can set handlers: elsewhere (a caller's thread) nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum, frame):
        raise KeyboardInterrupt(f"signal {signum}")

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def terminate_workers(pool: ProcessPoolExecutor) -> None:
    """End `pool`'s worker processes now (SIGTERM) and shut it down, dropping queued tasks."""
    for process in list((getattr(pool, "_processes", None) or {}).values()):  # no public way before 3.14
        process.terminate()
    pool.shutdown(wait=True, cancel_futures=True)


@contextlib.contextmanager
def process_pool(workers: int, initializer=None, initargs=()):
    """A ``ProcessPoolExecutor`` of `workers` spawned processes (spawn: torch and Open3D threads of
    this process must not be forked half-initialised). Inside the block SIGTERM interrupts as Ctrl-C
    does (:func:`sigterm_as_interrupt`); when the block ends by any exception (an interruption
    included) the workers are terminated, else the pool is shut down once its tasks are done."""
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=initializer, initargs=initargs)
    with sigterm_as_interrupt():
        try:
            yield pool
        except BaseException:
            terminate_workers(pool)
            raise
    pool.shutdown(wait=True)


__all__ = ["BACKENDS", "check_backend", "import_ray", "process_pool", "sigterm_as_interrupt", "terminate_workers"]

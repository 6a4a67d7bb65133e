"""Parallel runs on this machine or a Ray cluster: one runner, its checks, and ending workers with their parent.

``frontiernet bench --scenes`` and ``frontiernet datagen`` both run their tasks with
:func:`run_parallel`: in the caller's process (one local worker), in spawned worker processes, or
as Ray tasks. Both check ``--backend`` / ``--workers`` with :func:`check_backend` before they write
anything. A task whose worker process dies (killed, out of memory) is run again on a new pool, a
bounded number of times, then reported failed; one task's death never stops the others. When the
parent is stopped (Ctrl-C, or SIGTERM to the parent alone, as ``kill PID`` sends) its workers are
ended with it (:func:`process_pool`; Ray tasks are cancelled). Left running they would go on,
unseen, beside a resumed run (each datagen worker holds ~630 MB).
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
import signal
import sys
import threading
from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from .errors import InputError, cpu_count_option, whole_number

log = logging.getLogger(__name__)

BACKENDS = ("local", "ray")
POLL_S = 0.25
"""Seconds between calls of :func:`run_parallel`'s `poll` while local worker processes run."""


def import_ray():
    """The ``ray`` module; InputError saying how to install it when it is missing."""
    try:
        import ray
    except ImportError:
        raise InputError("--backend ray needs Ray: pip install 'frontiernet[ray]' (or pip install ray)") from None
    return ray


def check_backend(backend: str, workers) -> int:
    """`workers` as an int after checking `backend` is ``local`` or ``ray`` (Ray importable) and
    `workers` >= 1 (local processes: at most :data:`~frontiernet.errors.PER_CORE` per core of this
    machine, :func:`~frontiernet.errors.cpu_count_option`); InputError naming the bad option otherwise."""
    if backend not in BACKENDS:
        raise InputError(f"--backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    if backend == "ray":
        whole_number(workers, "--workers", 1)
        import_ray()
        return workers
    return cpu_count_option(workers, "--workers")


REDELIVER_S = 0.05
"""Seconds after a finaliser swallowed an interrupt (or one came during an import) that
:func:`sigterm_as_interrupt` raises it again."""


class SignalInterrupt(KeyboardInterrupt):
    """The KeyboardInterrupt that SIGTERM raises within :func:`sigterm_as_interrupt` (``signal 15``)."""


@contextlib.contextmanager
def sigterm_as_interrupt():
    """Within the block, SIGTERM raises KeyboardInterrupt (as Ctrl-C does), so that cleanup runs
    (``frontiernet`` then exits 130, "interrupted"); the previous handler is restored after. Only
    the main thread can set handlers: elsewhere (a caller's thread) nothing changes.

    A SIGTERM during the block is neither dropped nor printed as a traceback: Python runs a signal's handler
    wherever the main thread is, a ``__del__`` or weakref callback included, which swallows the
    KeyboardInterrupt ("Exception ignored in ...", and the run went on to exit 0); such a one is taken from
    ``sys.unraisablehook`` and raised again :data:`REDELIVER_S` later (at the latest as the block ends). A
    SIGTERM pending as the block ends (``signal.signal`` runs pending handlers before it restores the previous
    one) is raised after the previous handler is back (unless an exception already ends the block), so the
    raising handler never outlives the block (into interpreter shutdown). A SIGTERM during an ``import`` is
    held until the import is done (:func:`_importing`), then raised the same way."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    state = {"closing": False, "in_hook": False, "lost": None, "late": None}

    def interrupt(signum, frame):
        if state["closing"] or state["in_hook"]:  # (raised below once the handler is restored / by the timer)
            state["late" if state["closing"] else "lost"] = signum
            return
        if _importing(frame):  # raised once the import is done: the timer delivers it again until then
            state["lost"] = state["lost"] or signum
            _redeliver_later(state)
            return
        signum, state["lost"] = state["lost"] or signum, None
        raise SignalInterrupt(f"signal {signum}")

    def unraisable(report):  # (a finaliser's exception, which Python prints and drops)
        state["in_hook"] = True
        try:
            if isinstance(report.exc_value, KeyboardInterrupt):
                state["lost"] = signal.SIGTERM if isinstance(report.exc_value, SignalInterrupt) else signal.SIGINT
            else:
                previous_hook(report)
        finally:
            if state["lost"]:  # (also one that came while the hook ran: `interrupt` noted it)
                _redeliver_later(state)
            state["in_hook"] = False

    previous = signal.getsignal(signal.SIGTERM)
    previous_hook = sys.unraisablehook
    try:
        signal.signal(signal.SIGTERM, interrupt)
        sys.unraisablehook = unraisable
        yield
    finally:
        state["closing"] = True
        signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)  # (None: a native one)
        if sys.unraisablehook is unraisable:
            sys.unraisablehook = previous_hook
    if state["late"] or state["lost"]:  # the block ended, not by an exception: the interrupt ends it now
        raise SignalInterrupt(f"signal {state['late'] or state['lost']}")


def _importing(frame) -> bool:
    """Whether the main thread, stopped at `frame`, is inside an ``import`` (the import system's frames
    are on its stack). An interrupt raised there leaves a native library half set up (torch, open3d:
    the process later aborted with a native stack trace, or the next import of it failed with
    ImportError), so :func:`sigterm_as_interrupt` holds it until the import is done."""
    while frame is not None:
        if frame.f_code.co_filename.startswith("<frozen importlib"):
            return True
        frame = frame.f_back
    return False


def _redeliver_later(state: dict) -> None:
    """Start the timer that delivers a held interrupt again (:func:`_redeliver`) :data:`REDELIVER_S` from now."""
    timer = threading.Timer(REDELIVER_S, _redeliver, (state,))
    timer.daemon = True
    timer.start()


def _redeliver(state: dict) -> None:
    """In a timer's thread: the interrupt that a finaliser swallowed (:func:`sigterm_as_interrupt`), delivered
    again to the main thread as a SIGTERM, which the block's handler raises there (None: raised already)."""
    import _thread

    if state["lost"] and not state["closing"]:
        _thread.interrupt_main(signal.SIGTERM)


@contextlib.contextmanager
def keep_sigterm_handler():
    """Around the import of a native library that installs its own SIGTERM handler (pycolmap: glog's,
    which prints a native stack trace): Python's handler from before (:func:`sigterm_as_interrupt`'s,
    or the default) is installed again after the block. Only in the main thread."""
    previous = signal.getsignal(signal.SIGTERM)
    try:
        yield
    finally:
        if previous is not None and threading.current_thread() is threading.main_thread():
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
    try:
        with sigterm_as_interrupt():
            yield pool
    except BaseException:  # (an interruption that the block's end raises too)
        terminate_workers(pool)
        raise
    pool.shutdown(wait=True)


def _times(count: int) -> str:
    return {1: "once", 2: "twice"}.get(count, f"{count} times")


def run_parallel(function: Callable, tasks: Sequence[tuple], *, backend: str = "local", workers: int = 1,
                 on_result: Callable[[int, Any], None] | None = None, died: Callable[[int, str], Any],
                 retries: int = 1, initializer: Callable | None = None, initargs: tuple = (),
                 cpus_per_task: int = 1, poll: Callable[[], None] | None = None) -> list:
    """``function(*task)`` for every task of `tasks`; the results in the order of `tasks`.

    ``local`` with one worker runs the tasks one after the other in this process (no pool, no
    retry, `initializer` not called: the caller sets up its own process). Otherwise at most
    `workers` tasks run at once, each in a spawned process (``local``) or as a Ray task (``ray``,
    :func:`import_ray`; connects to ``RAY_ADDRESS`` when set, else starts a local instance, which is
    shut down after). `function` should return its failures as results: an exception it raises
    ends the run (and its workers) here.

    Args:
        function: a picklable (module-level) function.
        tasks: one tuple of picklable arguments per task.
        on_result: called in this process with (task index, result) as each result arrives
            (completion order), e.g. to advance a progress bar or record what is done for a resume.
        died: (task index, one-line message) -> the result of a task whose worker died
            ``retries + 1`` times (or whose Ray task failed); it is passed on like any result.
        retries: reruns of a task whose worker process died while running it (a local pool breaks
            as a whole: every task in flight in it is charged one attempt and rerun); Ray's
            ``max_retries``.
        initializer, initargs: run once in each spawned worker process (local backend).
        cpus_per_task: CPUs a Ray task reserves.
        poll: called in this process about every :data:`POLL_S` seconds while local worker
            processes run, and once after (e.g. to read progress the workers send).
    Raises:
        KeyboardInterrupt: Ctrl-C, or SIGTERM to this process while workers run; every worker
            process is terminated (every Ray task cancelled) first.
    """
    results: list = [None] * len(tasks)

    def deliver(index: int, result) -> None:
        results[index] = result
        if on_result is not None:
            on_result(index, result)

    if backend == "ray":
        _run_ray(function, tasks, workers, retries, cpus_per_task, deliver, died)
    elif workers == 1:
        with sigterm_as_interrupt():
            for index, task in enumerate(tasks):
                deliver(index, function(*task))
    else:
        _run_processes(function, tasks, workers, retries, initializer, initargs, deliver, died, poll)
    return results


def _run_processes(function, tasks, workers, retries, initializer, initargs, deliver, died, poll) -> None:
    """:func:`run_parallel` on pools of spawned processes: a pool that breaks (a worker died) is
    replaced, and its tasks in flight are rerun there until they have had ``1 + retries`` tries."""
    attempts = [0] * len(tasks)
    todo = deque(range(len(tasks)))
    with sigterm_as_interrupt():  # (also between two pools)
        while todo:
            broken = []
            with process_pool(min(workers, len(todo)), initializer, initargs) as pool:
                running = {}
                while running or (todo and not broken):
                    while todo and not broken and len(running) < workers:
                        index = todo.popleft()
                        attempts[index] += 1
                        running[pool.submit(function, *tasks[index])] = index
                    done, _ = wait(running, timeout=POLL_S, return_when=FIRST_COMPLETED)
                    if poll is not None:
                        poll()
                    for future in done:
                        index = running.pop(future)
                        try:
                            result = future.result()
                        except BrokenProcessPool:  # this pool's workers are gone (the broken pool ends them)
                            broken.append(index)
                            continue
                        deliver(index, result)
            retry = [index for index in broken if attempts[index] <= retries]
            if broken:
                log.warning("a worker process died; retrying %d task(s)", len(retry))
            for index in broken:
                if attempts[index] > retries:
                    deliver(index, died(index, f"worker process died {_times(attempts[index])} "
                                               "(killed or out of memory)"))
            todo.extendleft(reversed(retry))
        if poll is not None:
            poll()


def _run_ray(function, tasks, workers, retries, cpus_per_task, deliver, died) -> None:
    """:func:`run_parallel` as Ray tasks, `workers` in flight; Ray reruns a task whose worker died."""
    ray = import_ray()
    started_here = not ray.is_initialized()
    if started_here:
        address = os.environ.get("RAY_ADDRESS")
        ray.init(address=address or None, num_cpus=None if address else workers * cpus_per_task,
                 include_dashboard=False, log_to_driver=False, configure_logging=False)
    remote = ray.remote(num_cpus=cpus_per_task, max_retries=retries)(function)
    todo = deque(range(len(tasks)))
    running: dict = {}
    try:
        with sigterm_as_interrupt():
            while todo or running:
                while todo and len(running) < workers:
                    index = todo.popleft()
                    running[remote.remote(*tasks[index])] = index
                done, _ = ray.wait(list(running), num_returns=1, timeout=1.0)
                for ref in done:
                    index = running.pop(ref)
                    try:
                        result = ray.get(ref)
                    except Exception as error:  # the worker died `retries + 1` times, or Ray itself failed
                        result = died(index, f"Ray task failed: {type(error).__name__}")
                    deliver(index, result)
    except BaseException:
        for ref in running:
            with contextlib.suppress(Exception):
                ray.cancel(ref, force=True)
        raise
    finally:
        if started_here:
            ray.shutdown()


__all__ = ["BACKENDS", "SignalInterrupt", "check_backend", "import_ray", "keep_sigterm_handler", "process_pool",
           "run_parallel", "sigterm_as_interrupt", "terminate_workers"]

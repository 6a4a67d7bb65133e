"""How a training run stops early: a Ctrl-C or SIGTERM inside Lightning ends as the command's interrupt (exit 130,
one line ``frontiernet train: interrupted``: :func:`lightning_interrupts`), and a run that stopped or failed before its
first checkpoint leaves nothing that blocks the same command again (:func:`run_folder`). Used by FrontierNet's
training (:mod:`train.main`) and the map predictors' (:mod:`train.mapprediction`)."""

from __future__ import annotations

import logging
import os
from contextlib import contextmanager
from pathlib import Path


LIGHTNING_INTERRUPT_LINES = ("Received SIGTERM", "Detected KeyboardInterrupt")
"""What Lightning logs of a Ctrl-C or SIGTERM (each twice: its own handler and the root's), before the command's one
line ``frontiernet train: interrupted`` says it: left out (:func:`lightning_interrupts`)."""


class _InterruptLines(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return not any(text in str(record.msg) for text in LIGHTNING_INTERRUPT_LINES)


@contextmanager
def lightning_interrupts(trainer):
    """Ctrl-C or SIGTERM in Lightning's `trainer` (``fit``, ``validate``) ends the body as KeyboardInterrupt, which
    ``frontiernet`` ends as every command's interrupt (exit 130, "interrupted"): Lightning turns it into
    ``sys.exit(1)`` after its ``on_exception`` hooks (an exit 1 with no word of the signal), or only marks the
    trainer interrupted. Lightning's own lines about it (:data:`LIGHTNING_INTERRUPT_LINES`) are left out."""
    quiet = _InterruptLines()
    loggers = [logging.getLogger(name) for name in list(logging.root.manager.loggerDict)
               if name.split(".")[0] in ("lightning", "lightning_utilities", "lightning_fabric", "pytorch_lightning")]
    for logger in loggers:  # (a filter acts where a record is made: on each of Lightning's loggers)
        logger.addFilter(quiet)
    try:
        yield
    except SystemExit:
        if trainer.interrupted:
            raise KeyboardInterrupt from None
        raise
    finally:
        for logger in loggers:
            logger.removeFilter(quiet)
    if trainer.interrupted:
        raise KeyboardInterrupt


@contextmanager
def run_folder(out: Path, trainer, made: Path | None = None):
    """Run folder `out` made (with the folders above it that are missing) for the training in the body, which
    Lightning's `trainer` runs: where the body fails before any checkpoint was saved (it never stepped, it
    diverged first: :class:`~train.module.TrainingDiverged`, or Ctrl-C or SIGTERM stopped it), the folders made
    here, or `made` (the outermost folder that :func:`~train.resume.claimed_run_folder` made for the run), are
    removed, as nothing could resume from them; in a folder that was there before, what the run made in it
    (config.yaml, Lightning's hparams.yaml and metrics.csv: they refused the same command again, and --resume
    found nothing). Ctrl-C ends as KeyboardInterrupt (:func:`lightning_interrupts`)."""
    made = made or next((folder for folder in reversed((out, *out.parents)) if not folder.exists()), None)
    before = set(os.listdir(out)) if made is None and out.is_dir() else set()
    out.mkdir(parents=True, exist_ok=True)
    with lightning_interrupts(trainer):
        try:
            yield out
        except BaseException as error:
            # (Lightning ends a Ctrl-C or SIGTERM as sys.exit(1), the trainer marked interrupted)
            stopped = not isinstance(error, SystemExit) or trainer.interrupted
            if stopped and not any((out / "checkpoints").glob("*.ckpt")):
                _remove_unresumable(out, made, before)
            raise


def _remove_unresumable(out: Path, made: Path | None, before: set[str]) -> None:
    """Remove what a run that saved no checkpoint made: folder `made` (and all in it), or else the entries of run
    folder `out` that were not among `before` (its names when the run began: the lock file, a user's files)."""
    import shutil

    if made is not None:
        shutil.rmtree(made, ignore_errors=True)
        return
    for name in set(os.listdir(out)) - before:
        path = out / name
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path, ignore_errors=True)
        else:
            path.unlink(missing_ok=True)

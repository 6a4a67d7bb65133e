"""A training run's folder before its setup: the checkpoint it resumes from, checked to be one of the run's kind
and architecture, with steps (epochs) left to train (:func:`resume_checkpoint`); a fresh run refused where an earlier
run's outputs would be replaced (:func:`check_fresh_run`), and a run folder that is (inside) the dataset it reads
(:func:`check_not_the_dataset`); the folder locked for the run (:func:`claimed_run_folder`), so that a second
training on it meanwhile is refused; and a resumed run's metrics.csv continuing the earlier sessions' rows
(:func:`continued_metrics`). Used by FrontierNet's training (:mod:`train.main`) and the map predictors'
(:mod:`train.mapprediction`)."""

from __future__ import annotations

import csv
import os
import re
import warnings
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from omegaconf import OmegaConf

from frontiernet.errors import InputError
from frontiernet.io import check_not_locked, claim_output_folder, input_file
from frontiernet.model import load_model
from frontiernet.model.files import check_finite, load_checkpoint

RESUME_KEYS = ("pytorch-lightning_version", "state_dict", "optimizer_states", "lr_schedulers", "loops",
               "hyper_parameters")
"""What Lightning reads from a checkpoint to resume a run (``frontiernet train`` writes them all; a
weights-only save lacks the optimiser's and the loops' state)."""
RUN_OUTPUTS = ("model.safetensors", "predictor.safetensors", "summary.json", "metrics.csv", "config.yaml",
               "hparams.yaml")
"""The files a training run writes in its folder (besides its checkpoints and ``metrics-part*.csv``): a fresh run
there would replace them (:func:`check_fresh_run`; a config.yaml of the user's was replaced without a word)."""
FRONTIERNET = "a FrontierNet model"
"""What a FrontierNet training trains, as the messages say it (a map predictor's: ``a seer map predictor``)."""


def _trains(hyper: dict) -> str | None:
    """What the checkpoint of hyperparameters `hyper` trained (:data:`FRONTIERNET`, ``a mapex map predictor``),
    None when neither (a checkpoint of another program)."""
    predictor = hyper.get("predictor")
    if isinstance(predictor, dict):
        return f"a {predictor.get('kind')} map predictor"
    if isinstance(hyper.get("model"), dict) and "network" in hyper["model"]:
        return FRONTIERNET
    return None


def _check_predictor(path: str, hyper: dict, state: dict, spec) -> None:
    """InputError naming checkpoint `path` (of hyperparameters `hyper`, weights `state`) unless its predictor
    has the kind, members and network of the run's `spec` (a :class:`PredictorSpec`) and its weights fit them."""
    from frontiernet.mapprediction.networks import PredictorSpec

    try:
        theirs = PredictorSpec.from_dict(hyper["predictor"])
    except InputError as error:
        raise InputError(f"{path}: {error}") from None
    ours = {"predictor.members": spec.members, **{f"predictor.network.{key}": value
                                                  for key, value in spec.network.to_dict().items()}}
    recorded = {"predictor.members": theirs.members, **{f"predictor.network.{key}": value
                                                        for key, value in theirs.network.to_dict().items()}}
    differs = next((key for key in ours if ours[key] != recorded[key]), None)
    if differs is not None:
        raise InputError(f"{path}: a {theirs.kind} map predictor's checkpoint of another architecture ({differs}: "
                         f"{recorded[differs]} there, {ours[differs]} in this run); give the checkpoint's, or start "
                         "afresh without --resume")
    own = {f"net.{name}": tensor.shape for name, tensor in spec.build().state_dict().items()}
    found = {name: value.shape for name, value in state.items() if name.startswith("net.")}
    if own != found:
        raise InputError(f"{path}: its weights do not fit the {theirs.kind} predictor its hyperparameters declare "
                         "(a damaged or edited checkpoint)")


def _check_steps_left(path: str, state: dict, trainer) -> None:
    """InputError naming the ``trainer.max_steps`` (``max_epochs``) that checkpoint `path` (its loaded `state`) has
    reached already, as Lightning's fit loop judges it (its global step; its epochs processed): the resumed run
    trained nothing, said "trained 6 steps", and wrote its model, summary and metrics.csv anew."""
    steps, epochs = trainer.max_steps, trainer.max_epochs
    step = state.get("global_step")
    if isinstance(step, int) and steps != -1 and step >= steps:
        raise InputError(f"trainer.max_steps={steps}: the checkpoint {path} is at step {step} already; give more "
                         "steps to continue it")
    loops = state.get("loops") if isinstance(state.get("loops"), dict) else {}
    done = ((loops.get("fit_loop") or {}).get("epoch_progress") or {}).get("current", {}).get("processed")
    if isinstance(done, int) and epochs is not None and epochs != -1 and done >= epochs:
        raise InputError(f"trainer.max_epochs={epochs}: the checkpoint {path} is at epoch {done} already; give "
                         "more epochs to continue it")


def check_checkpoint(path: str, spec=None, trainer=None) -> dict:
    """The hyperparameters of a checkpoint to resume from, which must load as one (plain data only: no
    code runs; memory-mapped, so a second look costs little). Refused, naming the file: a file that is no
    torch checkpoint, one without the state Lightning resumes from (:data:`RESUME_KEYS`), one of another kind
    than the run's (`spec`: the :class:`PredictorSpec` a map predictor's run trains, None for a FrontierNet
    training), of another architecture (a map predictor's: a FrontierNet run takes its network from the
    checkpoint), or weights that do not fit the network it declares (:func:`load_model`) or are not all finite,
    or (`trainer`: the run's ``trainer`` settings) one at the run's step or epoch budget already
    (:func:`_check_steps_left`)."""
    state = load_checkpoint(path, "training checkpoint", mmap=True)
    if not isinstance(state, dict) or "state_dict" not in state:
        raise InputError(f"{path}: not a training checkpoint (no state_dict)")
    missing = [key for key in RESUME_KEYS if key not in state]
    if missing:
        raise InputError(f"{path}: not a training checkpoint (no {', '.join(missing)}: nothing to resume from)")
    hyper = state.get("hyper_parameters") or {}
    found = _trains(hyper) if isinstance(hyper, dict) else None
    wanted = FRONTIERNET if spec is None else f"a {spec.kind} map predictor"
    if found != wanted:  # (Lightning failed after its setup: "Error(s) in loading state_dict")
        what = f"the checkpoint of {found}" if found else "a checkpoint of neither FrontierNet nor a map predictor"
        raise InputError(f"{path}: {what}; this run trains {wanted}: resume from one of its own checkpoints, or "
                         "start afresh without --resume")
    if spec is None:
        load_model(path)  # a FrontierNet's: its weights fit the network it declares and are finite
    else:
        _check_predictor(path, hyper, state["state_dict"], spec)
        check_finite(state["state_dict"], path)
    if trainer is not None:
        _check_steps_left(path, state, trainer)
    return hyper


def resumed_settings(conf, hyper: dict) -> None:
    """Set in `conf` what a resumed run takes from its checkpoint (`hyper`: its hyperparameters,
    :func:`resume_checkpoint`), not from the config: the network it trains and the fine-tuning settings
    (``init_weights``, ``init_inputs``, ``freeze``) that made it, so that the written model file shares
    the same layers with the same base."""
    model, train = hyper.get("model") or {}, hyper.get("train") or {}
    if "network" in model:
        conf.model.network = OmegaConf.create(model["network"])
    for key in ("init_weights", "init_inputs", "freeze"):
        if key in train:
            conf[key] = train[key]


def earlier_outputs(out: Path) -> list[str]:
    """The files of an earlier training run in run folder `out` (its checkpoints, :data:`RUN_OUTPUTS`,
    ``metrics-part*.csv``), as paths inside it; [] for a new folder or one holding none of them (a run stopped
    before its first checkpoint leaves none: :func:`~train.stopping.run_folder`). A ``checkpoints`` that is a file,
    or a folder holding other files, counts as ``checkpoints/``."""
    if not out.is_dir():
        return []
    checkpoints = out / "checkpoints"
    found = sorted(str(path.relative_to(out)) for path in checkpoints.glob("*.ckpt"))
    if not found and (checkpoints.is_file() or checkpoints.is_dir() and any(checkpoints.iterdir())):
        found.append("checkpoints/")
    found += [name for name in RUN_OUTPUTS if (out / name).exists()]
    return found + sorted(path.name for path in out.glob("metrics-part*.csv"))


def check_fresh_run(out: Path, resume: str | None) -> None:
    """InputError naming run folder `out` when a run that does not resume (`resume` None) would replace an
    earlier run's files there (:func:`earlier_outputs`: its model, metrics and summary were replaced without a
    word): it says to pass ``--resume`` (with the checkpoint there) or to choose another ``out=`` / ``name=``."""
    if resume is not None:
        return
    found = earlier_outputs(out)
    if not found:
        return
    if (out / "checkpoints" / "last.ckpt").exists():
        raise InputError(f"{out} already holds a training run; pass --resume to continue it or change name= (or out=)")
    checkpoint = next((name for name in found if name.endswith(".ckpt")), None)
    shown = ", ".join(found[:3]) + (f" and {len(found) - 3} more" if len(found) > 3 else "")
    advice = (f"pass --resume {out / checkpoint} to continue it, or choose another out= or name=" if checkpoint
              else "it has no checkpoint to resume from: choose another out= or name=, or move them away")
    raise InputError(f"{out}: holds an earlier training run's files ({shown}), which a new run would replace; {advice}")


def check_not_the_dataset(out: Path, data) -> None:
    """InputError when run folder `out` is the dataset `data` (``data.path``) or a folder inside it: ``out=dsk
    name=shards`` wrote a run among the dataset's shards, and ``out=. name=dsk`` was refused as a folder holding "an
    earlier training run's files (summary.json)", datagen's."""
    if data is None or not str(data).strip():
        return
    run, dataset = os.path.realpath(out), os.path.realpath(str(data))
    if run == dataset or run.startswith(dataset.rstrip(os.sep) + os.sep):
        where = "is the dataset (data.path=" if run == dataset else "is inside the dataset (data.path="
        raise InputError(f"{out}: the run folder (out=, name=) {where}{data}){' itself' if run == dataset else ''}, "
                         "which the training reads; choose another out= or name=")


def resume_checkpoint(out: Path, resume: str | None, spec=None, trainer=None) -> tuple[str | None, dict]:
    """(the checkpoint a run in folder `out` resumes from, its hyperparameters): `resume` as given
    (``"last"``: the run's last checkpoint), checked to be a training checkpoint of the run's kind (`spec`:
    :func:`check_checkpoint`) with steps left to train under the run's `trainer` settings; (None, {}) for a fresh
    run. InputError: nothing to resume, a missing or foreign
    checkpoint, a folder another run is writing in (:func:`~frontiernet.io.check_not_locked`), or a fresh run into a folder holding
    an earlier run (:func:`check_fresh_run`)."""
    check_not_locked(out, "out= or name=")  # before its files are judged: a run in progress wrote some
    last = out / "checkpoints" / "last.ckpt"
    if resume == "last":
        if not last.is_file():
            raise InputError(f"{last}: nothing to resume (no last checkpoint in the run folder)")
        resume = str(last)
    if resume is not None:  # (a 0-byte one was "not a training checkpoint (RuntimeError)")
        input_file(resume, "checkpoint to resume from", empty_ok=False)
    check_fresh_run(out, resume)
    return resume, (check_checkpoint(resume, spec, trainer) if resume is not None else {})


LAUNCHED_RANK = ("LOCAL_RANK", "NODE_RANK", "RANK")
"""Environment variables that Lightning's DDP launcher (or torchrun) sets in the processes it starts: one of
them above 0 is a copy of the command that trains beside the first process, which holds the run folder."""


def launched_copy() -> bool:
    """Whether this process is one that a multi-process launch started beside the first (:data:`LAUNCHED_RANK`)."""
    return any(os.environ.get(name, "0").strip() not in ("", "0") for name in LAUNCHED_RANK)


@contextmanager
def claimed_run_folder(out: Path, resume: str | None) -> Iterator[Path | None]:
    """Run folder `out` locked for the training in the body (:func:`~frontiernet.io.claim_output_folder`): a
    second training started on it meanwhile is refused at once (``another run (process N) is writing there``;
    two ran side by side before, each writing its checkpoints and model over the other's). Under the lock the
    fresh run is checked again (:func:`check_fresh_run`: what a run that ended just now wrote counts). Yields
    the outermost folder this call made (None: `out` was there), which the body's :func:`run_folder` removes
    when the run fails before its first checkpoint. The processes a multi-process launch started beside the
    first (:func:`launched_copy`) take no lock: the first holds it."""
    if launched_copy():
        yield None
        return
    made = next((folder for folder in reversed((out, *out.parents)) if not folder.exists()), None)
    with claim_output_folder(out, force=True):
        check_fresh_run(out, resume)
        yield made


METRICS_PART = re.compile(r"metrics-part(\d+)\.csv")
"""The earlier rows of a resumed run's metrics.csv, as they stood at its Nth resume (:func:`continued_metrics`)."""


@contextmanager
def continued_metrics(out: Path, resume: str | None) -> Iterator[None]:
    """A resumed run's ``metrics.csv`` in run folder `out` continues its earlier sessions' rows: Lightning's CSV logger
    deletes the file it finds (after "Previous log files in this directory will be deleted"), so before the session
    it is set aside as ``metrics-part<N>.csv`` (what it held at the Nth resume, kept: it survives a process killed
    mid-session), and when the body ends, however it ends, metrics.csv becomes those rows then the session's
    (:func:`_join_rows`). Nothing for a fresh run (`resume` None: a metrics.csv there was refused,
    :func:`check_fresh_run`). Lightning's warning that the folder's "previous log files ... will be deleted", said of
    every run (the run's config.yaml is there), is left out: untrue."""
    warnings.filterwarnings("ignore", message=r"Experiment logs directory .* exists and is not empty")
    earlier = None
    if resume is not None and (out / "metrics.csv").is_file():
        parts = [int(match.group(1)) for path in out.glob("metrics-part*.csv")
                 if (match := METRICS_PART.fullmatch(path.name))]
        earlier = out / f"metrics-part{max(parts, default=0) + 1}.csv"
        (out / "metrics.csv").rename(earlier)
    try:
        yield
    finally:
        if earlier is not None:
            _join_rows(earlier, out / "metrics.csv")


def _join_rows(earlier: Path, metrics: Path) -> None:
    """Write `metrics` (the CSV Lightning wrote this session, or none) as the rows of `earlier` then its own, under
    the union of their columns, sorted as Lightning sorts them."""
    from frontiernet.io import atomic_path

    tables = []
    for path in (earlier, metrics):
        if path.is_file():
            with open(path, newline="") as handle:
                reader = csv.DictReader(handle)
                tables.append((reader.fieldnames or [], list(reader)))
    columns = sorted({name for names, _ in tables for name in names})
    with atomic_path(metrics) as tmp, open(tmp, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=columns, extrasaction="ignore")
        writer.writeheader()
        for _, rows in tables:
            writer.writerows(rows)

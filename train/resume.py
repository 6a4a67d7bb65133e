"""A training run's folder before its setup: the checkpoint it resumes from, checked to be one of the run's kind
and architecture (:func:`resume_checkpoint`); a fresh run refused where an earlier run's outputs would be
replaced (:func:`check_fresh_run`); and the folder locked for the run (:func:`claimed_run_folder`), so that a
second training on it meanwhile is refused. Used by FrontierNet's training (:mod:`train.main`) and the map
predictors' (:mod:`train.mapprediction`)."""

from __future__ import annotations

import os
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
RUN_OUTPUTS = ("model.safetensors", "predictor.safetensors", "summary.json", "metrics.csv")
"""The files a finished training run leaves in its folder (besides its checkpoints and ``metrics-part*.csv``):
a fresh run there would replace them (:func:`check_fresh_run`)."""
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


def check_checkpoint(path: str, spec=None) -> dict:
    """The hyperparameters of a checkpoint to resume from, which must load as one (plain data only: no
    code runs; memory-mapped, so a second look costs little). Refused, naming the file: a file that is no
    torch checkpoint, one without the state Lightning resumes from (:data:`RESUME_KEYS`), one of another kind
    than the run's (`spec`: the :class:`PredictorSpec` a map predictor's run trains, None for a FrontierNet
    training), of another architecture (a map predictor's: a FrontierNet run takes its network from the
    checkpoint), or weights that do not fit the network it declares (:func:`load_model`) or are not all finite."""
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
    ``metrics-part*.csv``), as paths inside it; [] for a new or empty folder (or one holding only the
    ``config.yaml`` / ``hparams.yaml`` of a run that was stopped before its first checkpoint)."""
    if not out.is_dir():
        return []
    found = sorted(str(path.relative_to(out)) for path in (out / "checkpoints").glob("*.ckpt"))
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


def resume_checkpoint(out: Path, resume: str | None, spec=None) -> tuple[str | None, dict]:
    """(the checkpoint a run in folder `out` resumes from, its hyperparameters): `resume` as given
    (``"last"``: the run's last checkpoint), checked to be a training checkpoint of the run's kind (`spec`:
    :func:`check_checkpoint`); (None, {}) for a fresh run. InputError: nothing to resume, a missing or foreign
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
    return resume, (check_checkpoint(resume, spec) if resume is not None else {})


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

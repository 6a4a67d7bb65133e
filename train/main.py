"""``main(conf)``: train FrontierNet with Lightning, write checkpoints, a CSV log and the model file.

Outputs in ``<out>/<name>/``:

- ``config.yaml``: the resolved config of the run;
- ``checkpoints/last.ckpt`` (every ``trainer.checkpoint_every_minutes``, every
  ``checkpoint_every_n_epochs`` epochs, when training ends and on Ctrl-C) and ``checkpoints/best.ckpt`` (lowest validation loss): resume with
  ``--resume``;
- ``metrics.csv``: losses per logging step, validation metrics per validation (a resumed run
  continues it; its rows as they stood at each resume are kept in ``metrics-part1.csv``, ``metrics-part2.csv`` ...:
  :func:`~train.resume.continued_metrics`);
- ``model.safetensors``: the best weights as a model file (``frontiernet predict --model``): the
  validated state with the lowest validation loss, the final weights always among them;
- ``summary.json``: data, scenes, steps, time, hardware and the last validation metrics.
"""

from __future__ import annotations

import json
import logging
import os
import platform
import time
import warnings
from datetime import timedelta
from pathlib import Path

import lightning as L
import torch
from lightning.pytorch.callbacks import Callback, LearningRateMonitor, ModelCheckpoint
from lightning.pytorch.loggers import CSVLogger
from lightning.fabric.utilities.exceptions import MisconfigurationException
from omegaconf import OmegaConf

from frontiernet.allocator import keep_freed_memory
from frontiernet.errors import InputError
from frontiernet.frontiers.gain import labels_gain_definition
from frontiernet.io import write_json
from frontiernet.model import load_model, save_model
from frontiernet.model.files import model_base
from frontiernet.model.network import resolve_pretrained

from .config import check_max_time, plain
from .cache import check_cache_folder
from .data import (FrontierDataModule, check_training_cache, gain_bins_mismatch, open_training_data, view_size,
                   worker_count)
from .finetune import freeze, init_file, initial_weights, shared_base
from .module import FiniteTraining, FrontierNetModule, TrainingDiverged, check_schedule
from .resume import (check_not_the_dataset, claimed_run_folder, continued_metrics, resume_checkpoint,
                     resumed_settings)
from .stopping import lightning_interrupts, run_folder  # (train.mapprediction's too)

log = logging.getLogger(__name__)


class LastCheckpoint(Callback):
    """Saves ``last.ckpt`` when training ends (``max_time`` included) or stops on an exception
    (Ctrl-C included), so the newest state is always there to resume from."""

    def __init__(self, path: Path):
        self.path = path

    def on_train_end(self, trainer, module) -> None:
        if trainer.global_step > 0:
            trainer.save_checkpoint(self.path)

    def on_exception(self, trainer, module, exception) -> None:
        if trainer.global_step > 0 and not isinstance(exception, TrainingDiverged):  # (NaN weights: not saved)
            trainer.save_checkpoint(self.path)
            log.warning("saved %s (resume with --resume)", self.path)


def channels_last_wanted(trainer_conf) -> bool:
    """``trainer.channels_last``: true, false, or auto (on when training runs on a CUDA GPU)."""
    setting = trainer_conf.get("channels_last", False)
    if str(setting) == "auto":
        accelerator = str(trainer_conf.accelerator)
        return torch.cuda.is_available() and accelerator in ("gpu", "cuda", "auto")
    if not isinstance(setting, bool):
        raise InputError(f"trainer.channels_last: must be true, false or auto, got {setting!r}")
    return setting


def _trainer_args(trainer_conf) -> dict:
    keys = ("max_epochs", "max_steps", "max_time", "accelerator", "devices", "num_nodes", "strategy",
            "precision", "gradient_clip_val", "val_check_interval", "check_val_every_n_epoch",
            "limit_val_batches", "log_every_n_steps")
    return {key: trainer_conf[key] for key in keys}


def resolve_gain_definition(conf, dataset_definition: str, init_labels: dict) -> None:
    """Set ``conf.model.labels.gain_definition`` to the dataset's gain definition (the model file
    records what it learned); InputError when the config names another one, or when the
    ``init_weights`` model was trained on another (its labels would mean other volumes)."""
    path = conf.data.path
    named = conf.model.labels.get("gain_definition")
    if named and str(named) != dataset_definition:
        raise InputError(f"model.labels.gain_definition: {named}, but {path} holds gain labels of definition "
                         f"{dataset_definition} (datagen ground_truth.gain.volume/spread); set it to "
                         f"{dataset_definition} or null, or train on a dataset made with {named}")
    if init_labels and labels_gain_definition(init_labels) != dataset_definition:
        raise InputError(f"init_weights: {conf.init_weights} was trained on gain definition "
                         f"{labels_gain_definition(init_labels)}, but {path} holds {dataset_definition} labels; "
                         f"start from a model of that definition or without init_weights")
    conf.model.labels.gain_definition = dataset_definition


def check_loop_settings(conf, train_samples: int) -> None:
    """Refuse, naming the key, the settings Lightning would only reject with a traceback mid-run."""
    batch_size = conf.data.batch_size
    if not isinstance(batch_size, int) or batch_size < 1:
        raise InputError(f"data.batch_size: must be a whole number >= 1, got {batch_size}")
    batches = train_samples // batch_size  # the training loader drops the last partial batch
    if batches < 1:
        raise InputError(f"data.batch_size: {batch_size} is more than the {train_samples} training views")
    for key in ("lr", "weight_decay"):
        value = conf.optim[key]
        if not isinstance(value, (int, float)) or not value >= (1e-300 if key == "lr" else 0):
            raise InputError(f"optim.{key}: must be a number {'> 0' if key == 'lr' else '>= 0'}, got {value}")
    check_schedule(conf.optim, bool(conf.trainer.max_time))
    channels_last_wanted(conf.trainer)
    interval = conf.trainer.val_check_interval
    if isinstance(interval, int) and not isinstance(interval, bool) and not 1 <= interval <= batches \
            and conf.trainer.check_val_every_n_epoch is not None:
        raise InputError(f"trainer.val_check_interval: {interval} steps, but an epoch has {batches} batches "
                         f"({train_samples} views / batch {batch_size}); give at most {batches} or a fraction "
                         f"of an epoch (e.g. 1.0)")
    if isinstance(interval, float) and not 0.0 < interval <= 1.0:
        raise InputError(f"trainer.val_check_interval: a fraction of an epoch must be in (0, 1], got {interval}")


def check_settings(conf) -> None:
    """Before anything is read or written (:func:`main` calls it first): InputError naming the key of
    a setting that needs no data to be judged wrong: the run folder (``out``/``name``) a file or
    under one, or the dataset (``data.path``) or inside it; an epoch or step budget with no end (Lightning's
    -1 needs the other set); a crop or image size outside [8, 2048] px; an augmentation probability outside
    [0, 1] or an amplitude outside [0, 1); a crop larger than ``data.image_size`` (:func:`check_crop`); an
    ``optim.final_lr_fraction`` outside [0, 1]; threads or loader workers outside 0 (1) to 4 per core; a
    checkpoint period that is not positive; a ``trainer.max_time`` of no time (:func:`check_max_time`); a
    ``data.cache`` folder that cannot be made (:func:`~train.cache.check_cache_folder`)."""
    from frontiernet.errors import check_seed, cpu_count_option, positive_number, whole_number
    from frontiernet.io import check_output_folder
    from frontiernet.model.predictor import input_size

    if conf.out is None or not str(conf.out).strip():  # (null was an internal error: no path of None)
        raise InputError(f"out: the folder of the training runs is {'null' if conf.out is None else 'blank'}; give one, "
                         "e.g. out=runs")
    if conf.name is None or not str(conf.name).strip():  # (' ' trained into a folder named ' '; null one named None)
        shown = "null" if conf.name is None else f"blank ({conf.name!r})"
        raise InputError(f"name: the run's folder name inside out= is {shown}; give one, e.g. name=tiny")
    if Path(str(conf.name)).name != str(conf.name) or str(conf.name) in (".", ".."):
        raise InputError(f"name: the run's folder name inside out= (no / or ..), got {conf.name!r}")
    check_seed(conf.seed, "seed")  # (Lightning's seed_everything raises past its range)
    check_output_folder(run_dir(conf), force=True)  # (a run resumes in it)
    check_not_the_dataset(run_dir(conf), conf.data.path)  # (out=dsk name=shards trained among the dataset's shards)
    trainer, data, augment = conf.trainer, conf.data, conf.augment
    steps, epochs = trainer.max_steps, trainer.max_epochs
    if steps != -1:
        whole_number(steps, "trainer.max_steps (-1: no limit)", 1)
    if epochs != -1 or steps == -1:
        whole_number(epochs, "trainer.max_epochs" + (" (-1: no limit, with trainer.max_steps > 0)" if steps == -1
                                                     else " (-1: no limit)"), 1)
    for key, value in (("data.image_size", data.image_size), ("augment.crop_size", augment.crop_size)):
        if value is not None:
            input_size(value, f"{key} (or null)")
    if data.image_size is not None:
        check_crop(augment.crop_size, int(data.image_size), "data.image_size")
    for key in ("hflip", "no_depth_fraction", "emulated_depth_fraction"):
        if not 0.0 <= positive_number(augment[key], f"augment.{key}", allow_zero=True) <= 1.0:
            raise InputError(f"augment.{key} is a probability, between 0 and 1; got {augment[key]}")
    for key in ("brightness", "contrast", "saturation", "gamma"):
        if not positive_number(augment[key], f"augment.{key}", allow_zero=True) < 1.0:
            raise InputError(f"augment.{key}: factors are drawn from [1 - a, 1 + a], so a must be below 1; got "
                             f"{augment[key]}")
    for key in ("depth_scale_sigma", "depth_noise_sigma"):
        positive_number(augment[key], f"augment.{key}", allow_zero=True)
    for key in ("max_train_samples", "max_val_samples"):
        if data[key] is not None:
            whole_number(data[key], f"data.{key} (or null)", 1)
    fraction = conf.optim.final_lr_fraction
    if isinstance(fraction, bool) or not isinstance(fraction, (int, float)) or not 0.0 <= fraction <= 1.0:
        raise InputError(f"optim.final_lr_fraction: the cosine ends at lr times this fraction, which must be "
                         f"between 0 and 1; got {fraction!r}")
    if trainer.threads is not None:
        cpu_count_option(trainer.threads, "trainer.threads (or null)")
    positive_number(trainer.checkpoint_every_minutes, "trainer.checkpoint_every_minutes", "minutes")
    whole_number(trainer.checkpoint_every_n_epochs, "trainer.checkpoint_every_n_epochs", 1)
    check_max_time(trainer.max_time)
    for key in ("num_workers", "cache_workers"):  # (read when the loaders start: after the trainer's setup)
        worker_count(data[key], f"data.{key}")
    check_cache_folder(data.cache)  # where nothing can be made, or under a folder that is not there
    check_trainer(trainer)
    pretrained = conf.model.network.get("pretrained")
    if pretrained:  # (read when the module is made: after the trainer's setup and its lines on stderr)
        resolve_pretrained(str(conf.model.network.encoder), pretrained)


CLUSTER_VARIABLES = ("NODE_RANK", "GROUP_RANK", "SLURM_NTASKS", "LSB_JOBID", "OMPI_COMM_WORLD_SIZE", "PMI_SIZE")
"""Environment variables one of which a multi-node launch sets (Lightning's own, torchrun, SLURM, LSF, MPI):
without any, ``trainer.num_nodes`` > 1 waits for the other nodes for ever."""
PRECISIONS = ("32-true", "32", "16-mixed", "16", "bf16-mixed", "bf16")
"""The ``trainer.precision`` values a run takes: Lightning's, less those that cast the weights (``64-true``,
``16-true``, ``bf16-true``: the loaders' float32 views then fail at the first step) and Transformer Engine's."""
STRATEGIES = ("auto", "ddp", "ddp_find_unused_parameters_false", "ddp_find_unused_parameters_true", "single_device")
"""The ``trainer.strategy`` values a run takes: Lightning's that train in this process, which writes the model file
(``ddp`` starts the other ranks as copies of the command); not those that train in spawned or forked processes
(``ddp_spawn``: exit 0, the untrained weights written), DeepSpeed's, FSDP's or XLA's (the network fits one device)."""


def check_trainer(trainer) -> None:
    """InputError naming the ``trainer.*`` setting that Lightning takes but this run cannot, or refuses only after
    its first lines on stderr (a ``limit_val_batches`` fraction above 1): several nodes
    outside a multi-node launch (:data:`CLUSTER_VARIABLES`: it waits for ever), a precision not in
    :data:`PRECISIONS` (64-true failed at the first step) or a strategy not in :data:`STRATEGIES`, a GPU where there
    is none, several devices on the CPU (the processes Lightning starts there share one dataset's loaders and write
    no results)."""
    limit = trainer.limit_val_batches
    if isinstance(limit, float) and not 0.0 <= limit <= 1.0:  # (Lightning refuses it after its INFO lines)
        raise InputError(f"trainer.limit_val_batches: a fraction of the validation batches is in [0, 1] (or give a "
                         f"whole number of batches, e.g. {int(limit)}), got {limit}")
    nodes = trainer.num_nodes
    if nodes != 1 and not any(name in os.environ for name in CLUSTER_VARIABLES):
        raise InputError(f"trainer.num_nodes={nodes}: no multi-node launch here (none of "
                         f"{', '.join(CLUSTER_VARIABLES)} is set), so the run would wait for the other nodes for ever; "
                         "give trainer.num_nodes=1, or start it on every node (torchrun, srun)")
    for key, valid, why in (("precision", PRECISIONS, "the views are float32: a precision that casts the weights "
                                                      "fails at the first step"),
                            ("strategy", STRATEGIES, "the weights this process holds are written as the model: it "
                                                     "must train them itself")):
        if str(trainer[key]) not in valid:
            raise InputError(f"trainer.{key}={_typed(trainer[key])}: not one this training takes; valid: {', '.join(valid)} "
                             f"({why})")
    accelerator = str(trainer.accelerator)
    if accelerator in ("gpu", "cuda") and not torch.cuda.is_available():  # (Lightning: "No supported gpu backend")
        raise InputError(f"trainer.accelerator={accelerator}: no CUDA GPU here (torch finds none); give "
                         "trainer.accelerator=cpu, or auto (a GPU where there is one)")
    on_cpu = accelerator == "cpu" or (accelerator == "auto" and not torch.cuda.is_available())
    if on_cpu and str(trainer.devices) not in ("auto", "1"):
        raise InputError(f"trainer.devices={_typed(trainer.devices)}: training runs on the CPU here (trainer.accelerator="
                         f"{accelerator}{', no CUDA GPU' if accelerator == 'auto' else ''}), in one process; give "
                         "trainer.devices=1 (or auto), or train on GPUs (trainer.accelerator=gpu)")


def _typed(value) -> str:
    """A ``key=value`` setting's value as the user typed it: text as is, ``null`` for None (not Python's ``None``)."""
    return "null" if value is None else str(value)


def check_crop(crop, size: int, size_key: str) -> None:
    """Refuse an ``augment.crop_size`` larger than the `size` px views it crops (`size_key`: the setting
    that makes them that size): such a crop is skipped in silence, the whole view trained on."""
    if crop is not None and int(crop) > size:
        raise InputError(f"augment.crop_size: {crop} px is larger than the {size} px views it crops ({size_key}); "
                         f"give at most {size}, or null for no crop")


def check_view_size(size: int, conf) -> None:
    """configs/ranges/train.yaml's relation of ``data.image_size``, ``data.batch_size`` and the network's
    ``pad_multiple`` for the dataset's own `size` px views (``data.image_size: null``, which it skips): the encoder's
    last stage, at 1/32 of the padded view, holds one value a channel at 32 px, which BatchNorm cannot train on in a
    batch of 1 (a ValueError after the trainer's setup)."""
    multiple = int(conf.model.network.pad_multiple)
    if int(conf.data.batch_size) == 1 and -(-size // multiple) * multiple <= 32:
        raise InputError(f"data.image_size: null keeps the dataset's {size} px views, within the encoder's 32 px "
                         "stride: its last stage holds one value a channel, which BatchNorm cannot train on in a "
                         "batch of 1; give data.image_size above 32 or data.batch_size=2 or more")


def run_dir(conf) -> Path:
    return Path(conf.out) / str(conf.name)


def main(conf, resume: str | None = None, progress: bool = True) -> Path:
    """Train with the resolved config `conf` (``train.config.load_train_config``).

    Args:
        resume: ``"last"`` to continue ``<run>/checkpoints/last.ckpt``, or a checkpoint path (one of a FrontierNet
            training: :func:`~train.resume.resume_checkpoint`).
    Returns:
        The run folder. A run that does not resume is refused where an earlier run's files would be replaced, and
        the folder is locked while the run writes there (a second run on it is refused): :mod:`train.resume`.
    """
    check_settings(conf)
    out = run_dir(conf)
    resume, hyper = resume_checkpoint(out, resume, trainer=conf.trainer)  # (one at max_steps already: refused)
    if resume is not None:
        resumed_settings(conf, hyper)
    init, init_labels = initial_weights(conf) if resume is None else (None, {})
    base = shared_base(conf, init)  # (the frozen layers' names are checked against a fresh run's network)
    dataset = open_training_data(conf.data.path)
    if conf.data.image_size is None and conf.augment.crop_size is not None:
        check_crop(conf.augment.crop_size, view_size(dataset), "data.image_size: null keeps the dataset's size")
    elif conf.data.image_size is None:
        check_view_size(view_size(dataset), conf)
    resolve_gain_definition(conf, dataset.gain_definition, init_labels)
    if differs := gain_bins_mismatch(conf.model.labels, dataset):  # (else an internal error at the first validation)
        raise InputError(f"model.labels.bin_edges: gain classes of {differs} (datagen ground_truth.gain); give the "
                         "dataset's (model.labels.num_classes: as many), or train on a dataset made with yours")
    datamodule = FrontierDataModule(conf, progress, dataset)
    check_loop_settings(conf, len(datamodule.split()[0]))  # before the training cache is built
    check_training_cache(conf.data, conf.model, dataset)  # a folder that is not a cache of this training: now
    with claimed_run_folder(out, resume) as made:  # (a second run on the folder meanwhile: refused here)
        return _fit(conf, out, resume, init, base, datamodule, progress, made)


def _fit(conf, out: Path, resume: str | None, init, base, datamodule, progress: bool, made: Path | None) -> Path:
    """The training of :func:`main`, its checks passed and its run folder `out` claimed (`made`: the outermost
    folder the claim made, removed when the run fails before its first checkpoint: :func:`run_folder`)."""
    last = out / "checkpoints" / "last.ckpt"
    checkpoints = out / "checkpoints"
    best = ModelCheckpoint(dirpath=checkpoints, filename="best", monitor="val/loss", mode="min", save_top_k=1,
                           enable_version_counter=False)
    periodic = ModelCheckpoint(dirpath=checkpoints, filename="last", save_top_k=1, enable_version_counter=False,
                               train_time_interval=timedelta(minutes=float(conf.trainer.checkpoint_every_minutes)))
    epoch_end = ModelCheckpoint(dirpath=checkpoints, filename="last", save_top_k=1, enable_version_counter=False,
                                every_n_epochs=int(conf.trainer.checkpoint_every_n_epochs),
                                save_on_train_epoch_end=True)
    callbacks = [best, periodic, epoch_end, LastCheckpoint(last), LearningRateMonitor("step"), FiniteTraining(
        {"optim.lr": conf.optim.lr, "model.input.rgb_std": list(conf.model.input.rgb_std)})]
    try:  # (also before the cache: a trainer setting Lightning refuses leaves no cache either)
        trainer = L.Trainer(**_trainer_args(conf.trainer), default_root_dir=out, callbacks=callbacks,
                            logger=CSVLogger(out, name="", version=""), enable_progress_bar=progress,
                            enable_model_summary=False, deterministic=False)
    except (ValueError, TypeError, ImportError, MisconfigurationException) as error:
        raise InputError(f"trainer: {str(error).splitlines()[0]}") from None
    datamodule.setup()

    L.seed_everything(int(conf.seed), workers=True, verbose=False)
    if conf.trainer.threads:
        torch.set_num_threads(int(conf.trainer.threads))
    keep_freed_memory()  # each step's activations are not page-faulted in anew (2.4x a CPU step: frontiernet.allocator)
    train_part = {key: plain(conf[key]) for key in ("loss", "optim")}
    train_part["val_scenes"] = list(datamodule.val_scenes)  # evaluate reads them from the checkpoint
    init_path = init_file(conf)  # absolute, so that the checkpoint names its base from any folder
    train_part.update(init_weights=None if init_path is None else "default" if conf.init_weights == "default"
                      else str(init_path.resolve()), init_inputs=conf.get("init_inputs"))
    train_part["freeze"] = list(base.prefixes) if base else []
    module = FrontierNetModule(model=plain(conf.model), train=train_part)
    module.use_channels_last(channels_last_wanted(conf.trainer))
    if init is not None:
        module.net.load_state_dict(init.state_dict())
    module.freeze(freeze(module.net, base))
    if base is not None:  # the frozen layers are meant to be in eval mode (their BatchNorm statistics kept)
        warnings.filterwarnings("ignore", message=r"Found \d+ module\(s\) in eval mode at the start of training")
    # every check passed: only now is anything written to the run folder
    started = time.time()
    with continued_metrics(out, resume):  # (Lightning's CSV logger started metrics.csv afresh)
        with run_folder(out, trainer, made):
            (out / "config.yaml").write_text(OmegaConf.to_yaml(conf, resolve=True))
            trainer.fit(module, datamodule=datamodule, ckpt_path=resume, weights_only=True)  # never runs pickled code
        with lightning_interrupts(trainer):  # a signal in the final validation ends the run as one in the fit
            checkpoint = best.best_model_path or str(last)
            if trainer.global_step > module.validated_at_step:
                # Lightning skips the validation due at the last step when max_steps ends the run, so the
                # final weights (often the best: the learning rate has decayed) would never be judged
                final = trainer.validate(module, datamodule=datamodule, verbose=False)[0]
                if best.best_model_score is None or final["val/loss"] < float(best.best_model_score):
                    checkpoint = str(last)
            elapsed = time.time() - started
            if trainer.is_global_zero:
                _write_results(out, conf, trainer, datamodule, checkpoint, elapsed, resume)
    return out


def _write_results(out: Path, conf, trainer, datamodule, checkpoint: str, elapsed: float, resume) -> None:
    """model.safetensors from the best checkpoint and summary.json."""
    metrics = {key: float(value) for key, value in trainer.callback_metrics.items() if value.numel() == 1}
    hardware = (torch.cuda.get_device_name(0) if torch.cuda.is_available() and conf.trainer.accelerator != "cpu"
                else f"CPU ({platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
                     f"{torch.get_num_threads()} torch threads)")
    summary = {"dataset": str(Path(conf.data.path).resolve()), "train_scenes": len(datamodule.train_scenes),
               "val_scenes": datamodule.val_scenes, "train_samples": len(datamodule.train_set),
               "val_samples": len(datamodule.val_set),
               "epochs": round(trainer.global_step * int(conf.data.batch_size) / max(len(datamodule.train_set), 1), 3),
               "steps": trainer.global_step, "init_weights": conf.get("init_weights"),
               "init_inputs": conf.get("init_inputs"), "freeze": list(conf.get("freeze") or []),
               "seconds_this_session": round(elapsed, 1), "resumed_from": resume,
               "hardware": hardware, "checkpoint": Path(checkpoint).name, "last_metrics": metrics,
               "encoder": conf.model.network.encoder, "inputs": conf.model.network.inputs}
    model, model_conf = load_model(checkpoint)
    save_model(out / "model.safetensors", model, model_conf, info=summary, base=model_base(model_conf))
    write_json(out / "summary.json", summary)
    log.info("wrote %s", json.dumps(summary)[:200])

"""Training the map predictors: ``frontiernet train --config configs/train_seer.yaml`` (or
``train_mapex.yaml``) on a ``frontiernet mapgen`` dataset (docs/mapprediction.md).

A config with a ``predictor:`` section is a map predictor's (:func:`is_map_config`); its base is the shipped
``configs/train_<kind>.yaml`` over the ``optim`` and ``trainer`` sections of ``configs/train.yaml`` (the same
Lightning trainer, schedule, checkpoints and resume as FrontierNet's training: :mod:`train.main`), then the
user's file and ``key=value`` overrides. Outputs in ``<out>/<name>/``: ``config.yaml``,
``checkpoints/last.ckpt`` and ``best.ckpt`` (highest validation mIoU of the unknown space near frontiers),
``metrics.csv``, ``predictor.safetensors`` (the best weights: :func:`frontiernet.mapprediction.load_predictor`)
and ``summary.json``.
"""

from __future__ import annotations

import json
import os
import platform
import time
from pathlib import Path

import lightning as L
import numpy as np
import torch
import torch.nn.functional as F
from omegaconf import OmegaConf

from frontiernet.config import load_config, merge_user
from frontiernet.allocator import keep_freed_memory
from frontiernet.errors import InputError
from frontiernet.io import write_json
from frontiernet.mapprediction.networks import NetworkSettings, PredictorSpec, parameter_count
from frontiernet.mapprediction.predictor import save_predictor
from frontiernet.mapprediction.quality import scores

from .config import check_max_time
from .module import FiniteTraining, FrontierNetModule, check_schedule


def is_map_config(path) -> bool:
    """Whether the YAML file `path` configures a map predictor (has a ``predictor:`` section)."""
    if not path or not Path(path).is_file():
        return False
    import yaml

    try:
        data = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError):
        return False  # load_train_config reports it
    return isinstance(data, dict) and isinstance(data.get("predictor"), dict)


def load_map_train_config(user_file, overrides=()):
    """The resolved config of a map predictor's training (module docstring); InputError naming a bad key."""
    import yaml

    kind = (yaml.safe_load(Path(user_file).read_text()) or {}).get("predictor", {}).get("kind")
    if kind not in ("seer", "mapex"):
        raise InputError(f"{user_file}: predictor.kind must be seer or mapex, got {kind!r}")
    shipped = load_config("train")
    base = OmegaConf.merge({"optim": shipped.optim, "trainer": shipped.trainer}, load_config(f"train_{kind}"))
    conf = merge_user(base, user_file, overrides,
                      layout={"optim": "train.optim", "trainer": "train.trainer", "": f"train_{kind}"})
    refuse_other_kinds_keys(conf, base, kind)
    if not conf.data.path:
        raise InputError("data.path is not set: give the map dataset folder (data.path=DIR)")
    predictor_spec(conf)  # a bad architecture or schedule fails here, before any data is read
    check_schedule(conf.optim, bool(conf.trainer.max_time))
    check_max_time(conf.trainer.max_time)  # (00:00:00:00 trained nothing and left a run folder)
    return conf


KIND_KEYS = {"data.crops_per_snapshot": ("seer", "a seer predictor trains on crops around frontier pieces"),
             "data.jitter_m": ("seer", "it moves the seer training crops"),
             "predictor.crop_shape": ("seer", "the size of a seer crop"),
             "data.topdown_size": ("mapex", "the size of a mapex training window"),
             "data.anywhere_fraction": ("mapex", "where mapex training windows are placed"),
             "predictor.band_m": ("mapex", "the height band of the mapex top-down map")}
"""The keys of the map predictors' training configs that one kind alone reads: key -> (that kind, what it sets)."""


def refuse_other_kinds_keys(conf, shipped, kind: str) -> None:
    """InputError naming a key of :data:`KIND_KEYS` that the user's file or overrides set to other than the
    shipped `shipped` config's value while the run trains a predictor of another `kind`: it was ignored in silence
    (``data.crops_per_snapshot=1000000000`` in a mapex training)."""
    for key, (reader, what) in KIND_KEYS.items():
        if reader != kind and OmegaConf.select(conf, key) != OmegaConf.select(shipped, key):
            value = OmegaConf.select(conf, key)
            raise InputError(f"{key}: a {kind} training does not read it ({reader} only: {what}), got "
                             f"{OmegaConf.to_container(value) if OmegaConf.is_config(value) else value!r}; "
                             f"leave it out (or train a {reader} predictor: configs/train_{reader}.yaml)")


def predictor_spec(conf) -> PredictorSpec:
    """The :class:`PredictorSpec` of a training config's ``predictor`` section."""
    p = conf.predictor
    values = {"kind": p.kind, "network": OmegaConf.to_container(p.network, resolve=True), "members": p.members,
              "voxel_size": p.voxel_size, "crop_shape": list(p.crop_shape), "band_m": p.band_m,
              "extra": {"occupied_threshold": float(p.occupied_threshold), "member_holdout": bool(p.member_holdout)}}
    if not isinstance(p.members, int) or isinstance(p.members, bool) or p.members < 1:
        raise InputError(f"predictor.members must be a positive integer, got {p.members!r}")
    if not 0.0 < float(p.occupied_threshold) < 1.0:
        raise InputError(f"predictor.occupied_threshold must lie strictly between 0 and 1, got {p.occupied_threshold}")
    NetworkSettings.from_dict(values["network"])
    return PredictorSpec.from_dict(values)


class MapPredictionModule(L.LightningModule):
    """The ensemble with its masked, weighted BCE and the validation scores of the unknown space near
    frontiers. `predictor`: the spec as a dict (``PredictorSpec.to_dict``); `train`: ``loss`` and ``optim``.
    Both are hyperparameters, so a checkpoint is self-describing (``load_predictor`` reads it)."""

    def __init__(self, predictor: dict, train: dict):
        super().__init__()
        self.save_hyperparameters()
        self.spec = PredictorSpec.from_dict(predictor)
        self.net = self.spec.build()
        self.counts = torch.zeros(4, dtype=torch.int64)
        self.validated_at_step = -1

    def _loss(self, batch: dict) -> tuple[torch.Tensor, torch.Tensor]:
        loss_conf = self.hparams.train["loss"]
        logits = self.net(batch["input"])[:, :, 0]  # (M, B, ...)
        label = batch["label"].long()
        valid = label != 255
        target = (label == 1).float()
        weight = torch.where(batch["known"], float(loss_conf["known_weight"]), float(loss_conf["unknown_weight"]))
        weight = weight * valid * torch.where(label == 1, float(loss_conf["occupied_weight"]), 1.0)
        per_cell = F.binary_cross_entropy_with_logits(logits, target.expand_as(logits), reduction="none") * weight
        use = batch["members"].t().float()  # (M, B): which members learn from which sample
        cell_sums = per_cell.sum(dim=tuple(range(2, per_cell.ndim)))  # (M, B)
        weight_sums = weight.sum(dim=tuple(range(1, weight.ndim)))  # (B,)
        member_loss = (cell_sums * use).sum(dim=1) / ((weight_sums[None] * use).sum(dim=1) + 1e-6)
        return member_loss.mean(), logits

    def training_step(self, batch: dict, batch_index: int) -> torch.Tensor:
        loss, _ = self._loss(batch)
        self.log("train/loss", loss, batch_size=len(batch["label"]), on_step=True, on_epoch=False)
        self.log("loss", loss, prog_bar=True, logger=False, batch_size=len(batch["label"]))
        return loss

    def validation_step(self, batch: dict, batch_index: int) -> None:
        loss, logits = self._loss(batch)
        self.log("val/loss", loss, batch_size=len(batch["label"]))
        occupied = torch.sigmoid(logits).mean(dim=0) > float(self.spec.extra.get("occupied_threshold", 0.5))
        region, truth = batch["region"], batch["label"] == 1
        self.counts += torch.stack([(occupied & truth & region).sum(), (occupied & ~truth & region).sum(),
                                    (~occupied & truth & region).sum(), (~occupied & ~truth & region).sum()]).cpu()

    def on_validation_epoch_end(self) -> None:
        figures = scores(self.counts.numpy())
        self.log_dict({f"val/{name}": float(figures[name]) if np.isfinite(figures[name]) else 0.0
                       for name in ("accuracy", "iou_occupied", "iou_free", "miou")})
        self.log("val_miou", float(np.nan_to_num(figures["miou"])), prog_bar=True, logger=False)
        self.counts.zero_()
        if not self.trainer.sanity_checking:
            self.validated_at_step = self.global_step

    def configure_optimizers(self):
        # FrontierNet's optimiser and schedule (AdamW, linear warm-up, cosine to final_lr_fraction over the
        # steps or trainer.max_time): it reads only hparams.train["optim"], parameters() and the trainer
        return FrontierNetModule.configure_optimizers(self)


def _refused(scene: str, patterns) -> bool:
    """Whether `scene` matches one of ``data.refuse_scenes``: procedural seed ranges (``procedural:1000-1009``)
    or a scene file's or folder's name (a KTH plan's id)."""
    from frontiernet.scenes.spec import expand_specs

    bare = scene.split("?")[0]
    for pattern in patterns:
        pattern = str(pattern)
        if pattern.startswith("procedural:"):
            if bare in expand_specs([pattern]):
                return True
        elif Path(bare.split(":", 1)[-1]).name == pattern or bare == pattern:
            return True
    return False


def open_map_training_data(conf):
    """(dataset, spec, train snapshots, val snapshots, train scenes, val scenes); InputError naming the dataset
    file or config key for a dataset of another resolution, a refused scene or too little data."""
    from datagen.mapshards import check_voxel_size, open_map_dataset, read_map_dataset_info

    from .config import check_scene_list
    from .data import _limit, split_scenes

    spec = predictor_spec(conf)
    if not Path(conf.data.path).exists():
        raise InputError(f"{conf.data.path}: map dataset folder not found (make one with frontiernet mapgen)")
    # (a file: "is a file, expected a folder (map dataset)", from read_map_dataset_info's input_folder)
    check_voxel_size(read_map_dataset_info(conf.data.path), conf.data.path, spec.voxel_size, "predictor.voxel_size")
    dataset = open_map_dataset(conf.data.path)
    refused = [scene for scene in dataset.scenes if _refused(scene, conf.data.refuse_scenes or [])]
    if refused:
        raise InputError(f"{conf.data.path}: holds {refused[0]}, a scene data.refuse_scenes keeps out of training "
                         f"(a benchmark test or development scene); make the training data without it")
    val_scenes = check_scene_list(conf.data.val_scenes, "data.val_scenes")
    train_scenes, val_scenes = split_scenes(dataset.scenes, val_scenes, float(conf.data.val_fraction), int(conf.seed))
    by_scene: dict[str, list[int]] = {}
    for index, (shard, _) in enumerate(dataset.snapshots):
        by_scene.setdefault(dataset.metas[shard]["scene"], []).append(index)
    train = [i for scene in train_scenes for i in by_scene.get(scene, [])]
    val = _limit([i for scene in val_scenes for i in by_scene.get(scene, [])], conf.data.max_val_snapshots, int(conf.seed))
    if not train or not val:
        raise InputError(f"{conf.data.path}: no snapshots in the {'training' if not train else 'validation'} scenes")
    return dataset, spec, train, val, train_scenes, val_scenes


def main(conf, resume: str | None = None, progress: bool = True) -> Path:
    """Train a map predictor with the resolved config `conf` (:func:`load_map_train_config`); returns the run folder.

    Args:
        resume: ``"last"`` (the run's last checkpoint) or a checkpoint path.
    """
    from .main import check_trainer, run_dir
    from .mapdata import make_samples
    from .resume import check_not_the_dataset, claimed_run_folder, resume_checkpoint

    check_trainer(conf.trainer)
    out = run_dir(conf)
    check_not_the_dataset(out, conf.data.path)
    resume = resume_checkpoint(out, resume, predictor_spec(conf), conf.trainer)[0]  # (of another kind: refused now)
    dataset, spec, train, val, train_scenes, val_scenes = open_map_training_data(conf)
    batch = int(conf.data.batch_size)
    train_set, val_set = make_samples(dataset, train, spec, conf, True), make_samples(dataset, val, spec, conf, False)
    if batch < 1 or len(train_set) < batch:
        raise InputError(f"data.batch_size: {batch} must be between 1 and the {len(train_set)} training samples")
    with claimed_run_folder(out, resume) as made:  # (a second run on the folder meanwhile: refused here)
        return _fit(conf, out, resume, spec, (train_set, val_set), (train_scenes, val_scenes), progress, made)


def _fit(conf, out: Path, resume, spec, samples, scenes, progress: bool, made) -> Path:
    """The training of :func:`main`, its checks passed and run folder `out` claimed (`made`: what the claim made)."""
    from lightning.pytorch.callbacks import LearningRateMonitor, ModelCheckpoint
    from lightning.pytorch.loggers import CSVLogger
    from torch.utils.data import DataLoader

    from .main import LastCheckpoint, _trainer_args, lightning_interrupts, run_folder
    from .resume import continued_metrics

    last = out / "checkpoints" / "last.ckpt"
    (train_set, val_set), (train_scenes, val_scenes) = samples, scenes
    batch = int(conf.data.batch_size)
    L.seed_everything(int(conf.seed), workers=True, verbose=False)
    if conf.trainer.threads:
        torch.set_num_threads(int(conf.trainer.threads))
    keep_freed_memory()  # each step's activations are not page-faulted in anew (2.4x a CPU step: frontiernet.allocator)
    train_part = {key: OmegaConf.to_container(conf[key], resolve=True) for key in ("loss", "optim")}
    train_part["scenes"] = {"train": train_scenes, "val": val_scenes}  # mapeval leaves them out (checkpoints too)
    module = MapPredictionModule(spec.to_dict(), train_part)
    checkpoints = out / "checkpoints"
    best = ModelCheckpoint(dirpath=checkpoints, filename="best", monitor="val/miou", mode="max", save_top_k=1,
                           enable_version_counter=False)
    from datetime import timedelta

    periodic = ModelCheckpoint(dirpath=checkpoints, filename="last", save_top_k=1, enable_version_counter=False,
                               train_time_interval=timedelta(minutes=float(conf.trainer.checkpoint_every_minutes)))
    callbacks = [best, periodic, LastCheckpoint(last), LearningRateMonitor("step"), FiniteTraining({"optim.lr": conf.optim.lr})]
    try:
        trainer = L.Trainer(**_trainer_args(conf.trainer), default_root_dir=out, callbacks=callbacks,
                            logger=CSVLogger(out, name="", version=""), enable_progress_bar=progress,
                            enable_model_summary=False, deterministic=False)
    except (ValueError, TypeError, ImportError) as error:
        raise InputError(f"trainer: {str(error).splitlines()[0]}") from None
    workers = int(conf.data.num_workers)
    loaders = [DataLoader(samples, batch_size=batch, shuffle=shuffle, drop_last=shuffle, num_workers=workers,
                          persistent_workers=workers > 0) for samples, shuffle in ((train_set, True), (val_set, False))]
    started = time.time()
    with continued_metrics(out, resume):  # (Lightning's CSV logger started metrics.csv afresh)
        with run_folder(out, trainer, made):
            (out / "config.yaml").write_text(OmegaConf.to_yaml(conf, resolve=True))
            trainer.fit(module, *loaders, ckpt_path=resume, weights_only=True)
        checkpoint = best.best_model_path or str(last)
        if trainer.global_step > module.validated_at_step:
            with lightning_interrupts(trainer):  # a signal here ends the run as one in the fit: exit 130, "interrupted"
                final = trainer.validate(module, loaders[1], verbose=False)[0]
            if best.best_model_score is None or final["val/miou"] > float(best.best_model_score):
                checkpoint = str(last)  # LastCheckpoint saved the final weights when training ended
    metrics = {key: float(value) for key, value in trainer.callback_metrics.items() if value.numel() == 1}
    summary = {"dataset": str(Path(conf.data.path).resolve()), "kind": spec.kind, "members": spec.members,
               "parameters": parameter_count(module.net), "train_scenes": train_scenes, "val_scenes": val_scenes,
               "train_samples": len(train_set), "val_samples": len(val_set), "steps": trainer.global_step,
               "epochs": round(trainer.global_step * batch / max(len(train_set), 1), 3),
               "seconds_this_session": round(time.time() - started, 1), "resumed_from": resume,
               "hardware": f"CPU ({platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
                           f"{torch.get_num_threads()} torch threads)", "checkpoint": Path(checkpoint).name,
               "last_metrics": metrics}
    state = torch.load(checkpoint, map_location="cpu", weights_only=True)["state_dict"]
    save_predictor(out / "predictor.safetensors", spec, {k[len("net."):]: v for k, v in state.items()
                                                           if k.startswith("net.")}, info=summary)
    write_json(out / "summary.json", summary)
    return out


def run_map_train(args) -> int:
    """``frontiernet train --config <a map predictor's config>`` (called by :mod:`train.cli`)."""
    conf = load_map_train_config(args.config, args.overrides)
    out = main(conf, resume=args.resume, progress=not args.no_progress)
    summary = json.loads((out / "summary.json").read_text())
    miou = summary["last_metrics"].get("val/miou", float("nan"))
    print(f"trained a {summary['kind']} predictor ({summary['members']} member(s), {summary['parameters']:,} "
          f"parameters): {summary['steps']} steps ({summary['epochs']} epochs) in "
          f"{summary['seconds_this_session']:.0f} s; validation mIoU near frontiers {miou:.3f}")
    print(f"predictor: {out / 'predictor.safetensors'}  (frontiernet mapeval {out / 'predictor.safetensors'} --data DIR)")
    return 0

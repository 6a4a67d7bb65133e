"""The training config: ``configs/model.yaml`` under ``model``, then ``configs/train.yaml``,
a user file and ``key=value`` overrides."""

from __future__ import annotations

import re
from datetime import timedelta
from pathlib import Path
from typing import Iterable

from omegaconf import DictConfig, ListConfig, OmegaConf

from frontiernet.config import load_config, merge_user
from frontiernet.errors import InputError


LOSS_WEIGHTS = ("distance_weight", "ce_weight", "dice_weight")
"""The ``loss`` keys that weigh its terms: at least one must be > 0, or the loss is 0 and nothing trains."""


def load_train_config(user_file: str | Path | None = None, overrides: Iterable[str] = ()) -> DictConfig:
    """The resolved training config (see ``configs/train.yaml``). InputError naming the key: no
    ``data.path``; a bad loss option, or every loss weight 0 (:data:`LOSS_WEIGHTS`); a
    ``data.val_scenes`` that is not a list (or null), or an empty one (:func:`check_scene_list`: its seed ranges
    expanded)."""
    conf = merge_user(OmegaConf.merge({"model": load_config("model")}, load_config("train")), user_file, overrides,
                      layout={"model": "model", "": "train"})
    if not conf.data.path:
        raise InputError("data.path is not set: give the dataset folder (data.path=DIR)")
    from .losses import loss_settings

    loss = loss_settings(conf.loss)  # a bad loss option fails here, before any data is read
    if not any(loss[key] > 0 for key in LOSS_WEIGHTS):
        raise InputError(f"{', '.join('loss.' + key for key in LOSS_WEIGHTS)}: all 0, so the loss is 0 and nothing "
                         f"trains; give at least one a weight > 0")
    conf.data.val_scenes = check_scene_list(conf.data.val_scenes, "data.val_scenes")
    return conf


def check_scene_list(value, key: str) -> list[str] | None:
    """The scene specs of `key` (e.g. ``data.val_scenes``) with procedural seed ranges expanded as ``evaluate
    --scenes`` expands them (``procedural:11-12`` was "not a scene of the dataset"), None for null. Refused: neither
    null nor a list (a single spec given as text would be read as a list of its characters, as a list key whose
    default is a list, e.g. ``freeze``, refuses text), or an empty list (it fell back to the ``val_fraction`` split
    in silence), or a malformed range."""
    if value is None:
        return None
    if not isinstance(value, (ListConfig, list, tuple)):
        raise InputError(f"{key}: takes a list of scene specs (or null), got {value!r}; write one scene as a "
                         f"one-element list, e.g. '{key}=[{value}]'")
    if not value:
        raise InputError(f"{key} is an empty list: give scenes, or null for the val_fraction split")
    from .evaluate import expand_scene_ranges

    try:
        return expand_scene_ranges([str(spec).strip() for spec in value])
    except InputError as error:
        raise InputError(f"{key}: {error}") from None


def plain(conf) -> dict:
    """A resolved plain-dict copy of a DictConfig or mapping (what checkpoints store)."""
    return OmegaConf.to_container(conf if isinstance(conf, DictConfig) else OmegaConf.create(conf), resolve=True)


MAX_TIME = re.compile(r"(\d+):(\d\d):(\d\d):(\d\d)")
"""``trainer.max_time`` as text: DD:HH:MM:SS, as Lightning's Timer reads it."""


def check_max_time(value) -> None:
    """InputError naming ``trainer.max_time`` unless it is null (no limit), DD:HH:MM:SS text or a mapping of
    timedelta's keys (``{hours: 2}``), as Lightning takes it, of more than 0 s: 00:00:00:00 stopped the run
    before its first step, which then failed at its end ("last.ckpt: model file not found") and left its
    folder behind."""
    if value is None:
        return
    try:
        if isinstance(value, str):
            days, hours, minutes, seconds = (int(part) for part in MAX_TIME.fullmatch(value.strip()).groups())
            if hours > 23 or minutes > 59 or seconds > 59:  # (99:99:99:99 read as 103 days)
                raise ValueError
            length = timedelta(days=days, hours=hours, minutes=minutes, seconds=seconds)
        else:
            length = timedelta(**plain(value))
    except (AttributeError, TypeError, ValueError, OverflowError):  # (no match, not a mapping, a bad key)
        raise InputError(f"trainer.max_time: a wall-clock limit is DD:HH:MM:SS (e.g. 00:01:00:00), or null for "
                         f"none; got {value!r}") from None
    if length.total_seconds() <= 0:
        raise InputError(f"trainer.max_time: {value} leaves no time to train (the run would stop before its first "
                         "step); give a limit above 0 (e.g. 00:01:00:00), or null for none")

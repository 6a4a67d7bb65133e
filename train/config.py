"""The training config: ``configs/model.yaml`` under ``model``, then ``configs/train.yaml``,
a user file and ``key=value`` overrides."""

from __future__ import annotations

from pathlib import Path
from typing import Iterable

from omegaconf import DictConfig, OmegaConf

from frontiernet.config import load_config, merge_user
from frontiernet.errors import InputError


def load_train_config(user_file: str | Path | None = None, overrides: Iterable[str] = ()) -> DictConfig:
    """The resolved training config (see ``configs/train.yaml``)."""
    conf = merge_user(OmegaConf.merge({"model": load_config("model")}, load_config("train")), user_file, overrides)
    if not conf.data.path:
        raise InputError("data.path is not set: give the dataset folder (data.path=DIR)")
    from .losses import loss_settings

    loss_settings(conf.loss)  # a bad loss option fails here, before any data is read
    return conf


def plain(conf) -> dict:
    """A resolved plain-dict copy of a DictConfig or mapping (what checkpoints store)."""
    return OmegaConf.to_container(conf if isinstance(conf, DictConfig) else OmegaConf.create(conf), resolve=True)

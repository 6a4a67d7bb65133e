"""The datagen configuration: ``configs/sim.yaml`` and ``configs/datagen.yaml`` merged."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Iterable

from omegaconf import DictConfig, OmegaConf

from frontiernet.config import load_config


def load_datagen_config(user_file: str | Path | None = None, overrides: Iterable[str] = ()) -> DictConfig:
    """Camera, voxels and poses (sim.yaml) plus ground_truth, sampling and writer (datagen.yaml),
    then a user YAML file and ``key=value`` overrides on top."""
    return load_config(("sim", "datagen"), user_file, overrides)


RUNTIME_SECTIONS = ("raycast",)
"""Config sections that choose how, not what, is computed: left out of :func:`config_hash`, so a
dataset can be resumed on a machine with another ray-cast engine (both give the same labels)."""


def config_hash(conf: DictConfig) -> str:
    """Short SHA-256 of the resolved config (stable across key order) without :data:`RUNTIME_SECTIONS`:
    names a dataset's settings."""
    settings = {key: value for key, value in OmegaConf.to_container(conf, resolve=True).items()
                if key not in RUNTIME_SECTIONS}
    text = json.dumps(settings, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]

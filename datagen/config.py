"""The datagen configuration: ``configs/sim.yaml`` and ``configs/datagen.yaml`` merged, with
``configs/scenes.yaml`` as section ``scenes``."""

from __future__ import annotations

import copy
import functools
import hashlib
import json
from pathlib import Path
from typing import Iterable

from omegaconf import DictConfig, OmegaConf

from frontiernet.config import dotted_parent, load_config


def load_datagen_config(user_file: str | Path | None = None, overrides: Iterable[str] = (),
                        names: tuple[str, ...] = ("sim", "datagen")) -> DictConfig:
    """Camera, voxels and poses (sim.yaml) plus ground_truth, sampling and writer (datagen.yaml)
    (shipped configs `names`, merged in order), the scene sources' options (scenes.yaml) as section
    ``scenes``, then a user YAML file and ``key=value`` overrides on top
    (:func:`~frontiernet.simulator.world.load_world_config` of `names`)."""
    from frontiernet.simulator.world import load_world_config

    return load_world_config(user_file, overrides, names)


RUNTIME_SECTIONS = ("raycast",)
"""Config sections that choose how, not what, is computed: left out of :func:`config_hash`, so a
dataset can be resumed on a machine with another ray-cast engine (both give the same labels)."""


KEYS_ADDED_AFTER_DATASETS = {"ground_truth.gain.volume": "unobserved", "ground_truth.gain.spread": "blend"}
"""Keys added after datasets had been made, with the value that reproduces the labels of before: at
that value a key is left out of :func:`config_hash`, so those datasets still resume."""

SECTIONS_ADDED_AFTER_DATASETS = {"scenes": "scenes"}
"""Sections added after datasets had been made, with the shipped config they were read from then
(the scene sources read ``configs/scenes.yaml`` themselves): equal to it, a section is left out of
:func:`config_hash`, so those datasets still resume; changed (``scenes.procedural.rooms_max=8``), it
names other scenes."""


def config_hash(conf: DictConfig | dict) -> str:
    """Short SHA-256 of :func:`hashed_settings` (stable across key order): names a dataset's settings."""
    return hashlib.sha256(_canonical(hashed_settings(conf)).encode()).hexdigest()[:16]


def hashed_settings(conf: DictConfig | dict) -> dict:
    """The settings of a config (resolved, or the plain dict dataset.json stores) that :func:`config_hash`
    hashes: all but :data:`RUNTIME_SECTIONS`, the keys of :data:`KEYS_ADDED_AFTER_DATASETS` at their old value
    and the sections of :data:`SECTIONS_ADDED_AFTER_DATASETS` as shipped (a resume names the first that differs)."""
    plain = OmegaConf.to_container(conf, resolve=True) if isinstance(conf, DictConfig) else copy.deepcopy(conf)
    settings = {key: value for key, value in plain.items() if key not in RUNTIME_SECTIONS}
    for section, name in SECTIONS_ADDED_AFTER_DATASETS.items():
        if section in settings and _canonical(settings[section]) == _shipped_canonical(name):
            settings.pop(section)
    for dotted, old_value in KEYS_ADDED_AFTER_DATASETS.items():
        section, key = dotted_parent(settings, dotted)
        if section is not None and section.get(key, old_value) == old_value:
            section.pop(key, None)
    return settings


def _canonical(value) -> str:
    """JSON text of a plain config value, independent of key order."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"))


@functools.lru_cache(maxsize=None)
def _shipped_canonical(name: str) -> str:
    """:func:`_canonical` of shipped config `name`, read once per process (datagen hashes its config
    once per task)."""
    return _canonical(OmegaConf.to_container(load_config(name), resolve=True))

"""Config sections of ``configs/depth.yaml``: shipped defaults merged with user values."""

from __future__ import annotations

from typing import Any, Mapping

from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from ..config import check_keys, load_config
from ..errors import InputError


def source_conf(name: str, conf: Mapping[str, Any] | DictConfig | None = None) -> dict[str, Any]:
    """Section `name` of the shipped depth config with the keys of `conf` replaced.

    `conf` is that section (all or some of its keys), or ``None`` for the defaults.
    Unknown keys raise :class:`InputError` naming them (typos fail loudly).
    Returns a plain ``dict``.
    """
    defaults = load_config("depth")[name]
    if conf is None:
        return OmegaConf.to_container(defaults, resolve=True)
    if isinstance(conf, DictConfig):
        conf = OmegaConf.to_container(conf, resolve=True)
    if not isinstance(conf, Mapping):
        raise InputError(f"depth.{name}: expected a mapping of options, got {type(conf).__name__}")
    check_keys(defaults, conf, f"depth.{name}", noun="option")
    try:
        merged = OmegaConf.merge(defaults, OmegaConf.create(dict(conf)))
    except OmegaConfBaseException as error:
        raise InputError(f"depth.{name}: bad option value ({error})") from None
    return OmegaConf.to_container(merged, resolve=True)


def number(conf: Mapping[str, Any], key: str, section: str, minimum: float = 0.0) -> float:
    """``conf[key]`` as a float >= `minimum`, else :class:`InputError` naming ``section.key``."""
    value = conf[key]
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise InputError(f"depth.{section}.{key}: expected a number, got {value!r}") from None
    if not value >= minimum:  # also catches NaN
        raise InputError(f"depth.{section}.{key}: must be >= {minimum}, got {value}")
    return value

"""Options of a depth source: the keys of its section of the shipped ``configs/depth.yaml``, and
their values, checked."""

from __future__ import annotations

from functools import lru_cache
from typing import Any, Mapping

from ..config import load_config
from ..errors import InputError


@lru_cache(maxsize=None)
def shipped_options(name: str) -> tuple[str, ...]:
    """The keys of section `name` of the shipped ``configs/depth.yaml``: the options of the depth
    source `name`, each with its default and its comment there."""
    return tuple(load_config("depth")[name])


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

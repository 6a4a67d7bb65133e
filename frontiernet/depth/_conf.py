"""Options of a depth source: its section of a depth config (``configs/depth.yaml`` as resolved), checked."""

from __future__ import annotations

from typing import Any, Mapping

from omegaconf import DictConfig

from ..config import option_section
from ..errors import InputError


def source_conf(name: str, conf: Mapping[str, Any] | DictConfig | None, options: tuple[str, ...]) -> dict[str, Any]:
    """Section `name` of a depth config (``configs/depth.yaml`` as the run resolved it) as a plain
    ``dict``: every key of `options` (the source's option names), no other.

    Raises:
        InputError: not a mapping, a missing option, or an unknown one (named, with its closest
            spellings: typos fail loudly).
    """
    return option_section(conf, options, f"depth.{name}")


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

"""Depth sources behind one interface (:class:`DepthSource`).

* ``ground_truth``: the simulator's depth, unchanged.
* ``emulated``: ground truth degraded like a monocular model (scale error, edge
  bleeding, blur, noise, dense fill), seedable.
* ``depth_anything_v2``: Depth Anything V2 metric (transformers), local weights.
* ``metric3d_v2``: Metric3D v2 (torch.hub, local clone and checkpoint).

Every source maps (H, W, 3) uint8 RGB and (3, 3) float64 ``K`` (plus ground truth for
those with ``requires_ground_truth``) to (H, W) float32 metres, NaN invalid. Options
live in ``configs/depth.yaml``.
"""

from __future__ import annotations

from typing import Any, Mapping

from omegaconf import DictConfig

from ..errors import InputError
from ..registry import Registry
from .base import DepthSource
from .depth_anything import DepthAnythingV2
from .emulated import EmulatedMonocularDepth
from .ground_truth import GroundTruthDepth
from .metric3d import Metric3DV2

DEPTH_SOURCES = Registry("depth source", None, {
    "ground_truth": GroundTruthDepth,
    "emulated": EmulatedMonocularDepth,
    "depth_anything_v2": DepthAnythingV2,
    "metric3d_v2": Metric3DV2,
})
"""The depth sources by name: a :class:`DepthSource` class built as ``Class(section)``, its section
of the run's depth config. Built in only (no entry point group)."""
SOURCES: dict[str, type[DepthSource]] = DEPTH_SOURCES.builtin
DEPTH_ALIASES = {"gt": "ground_truth"}
"""Short names every command takes for a depth source (``--depth gt``)."""


def source_options() -> DictConfig:
    """``configs/depth.yaml`` less its ``source`` key: every depth source's section, the ``depth``
    section of a command that takes the source from its own flag or key (``explore --depth`` /
    ``run.depth``, ``sequence --depth``, ``predict --depth``)."""
    from ..config import load_config

    options = load_config("depth")
    options.pop("source")
    return options


def depth_source_name(name: str) -> str:
    """`name` with its alias resolved (``gt`` -> ``ground_truth``); other names unchanged."""
    return DEPTH_ALIASES.get(name, name)


def known_source(name: str, what: str = "--depth, run.depth") -> str:
    """`name` with its alias resolved when it names a source of :data:`SOURCES`; InputError naming
    it and where it was given (`what`), with the valid names, otherwise."""
    resolved = depth_source_name(name)
    if resolved not in SOURCES:
        raise InputError(f"depth source '{name}' ({what}) is unknown; valid: gt, {', '.join(SOURCES)}")
    return resolved


def check_depth_files(name: str, conf: Mapping[str, Any] | DictConfig | None = None) -> None:
    """Before a run's setup: InputError naming what is missing when source `name`'s files (weights,
    code) are not where its section of the depth config `conf` says (a whole config like
    ``configs/depth.yaml``; None or without that section: the shipped options), found without loading
    them (:meth:`DepthSource.check_files`)."""
    source = DEPTH_SOURCES.get(depth_source_name(name))
    section = conf.get(source.name) if conf is not None else None
    if section is None:  # (was source.options(), the tuple of its option names: "expected a mapping ..., got tuple")
        section = source_options().get(source.name, {})
    source.check_files(section)


def monocular_sources() -> list[str]:
    """The depth sources that estimate depth from the image alone (the others read the simulator's
    ground truth): what a command without a simulator (``predict``, ``sequence``) offers."""
    return [name for name in DEPTH_SOURCES.names() if not DEPTH_SOURCES.get(name).requires_ground_truth]


def make_depth_source(
    name_or_conf: str | Mapping[str, Any] | DictConfig,
    conf: Mapping[str, Any] | DictConfig | None = None,
) -> DepthSource:
    """Build a depth source.

    Args:
        name_or_conf: a source name (one of :data:`SOURCES`), or a whole depth config
            (like ``configs/depth.yaml``) whose ``source`` key names the source.
        conf: with a name: that source's options (every key of its section of
            ``configs/depth.yaml``, as the run resolved it), either the section alone or a whole
            depth config holding a section of that name. Ignored when `name_or_conf` is a config.
    Raises:
        InputError: unknown source name, missing, unknown or bad option, absent weights.
    """
    if isinstance(name_or_conf, str):
        name = depth_source_name(name_or_conf)
    else:
        if not isinstance(name_or_conf, (Mapping, DictConfig)) or "source" not in name_or_conf:
            raise InputError("depth config: expected a source name or a mapping with a 'source' key")
        name, conf = str(name_or_conf["source"]), name_or_conf
    source = DEPTH_SOURCES.get(name)
    if conf is not None and ("source" in conf or isinstance(conf.get(name), (Mapping, DictConfig))):
        conf = conf.get(name)  # a whole depth config: take this source's section
    return source(conf)


__all__ = [
    "DEPTH_ALIASES",
    "check_depth_files",
    "depth_source_name",
    "known_source",
    "monocular_sources",
    "source_options",
    "DepthSource",
    "GroundTruthDepth",
    "EmulatedMonocularDepth",
    "DepthAnythingV2",
    "Metric3DV2",
    "SOURCES",
    "DEPTH_SOURCES",
    "make_depth_source",
]

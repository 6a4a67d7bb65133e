"""Scenes: one :class:`Scene` type and one :func:`load_scene` for every source
(:data:`~frontiernet.scenes.sources.SCENE_SOURCES`: mesh files, HM3D, floor plans, procedural).

See :mod:`frontiernet.scenes.spec` for the spec syntax.
"""

from __future__ import annotations

from omegaconf import DictConfig, OmegaConf

from ..config import check_keys
from .scene import Material, Scene, SceneMetadata
from .sources import SCENE_SOURCES
from .spec import DEFAULT_SPEC, EXPLORABLE_OPTIONS, SceneSpec, explorable_options, parse_spec

__all__ = ["Material", "Scene", "SceneMetadata", "SceneSpec", "load_scene", "parse_spec", "DEFAULT_SPEC"]


def _section(conf: DictConfig, source: str, spec: SceneSpec) -> DictConfig:
    base = conf[source]
    own = {key: value for key, value in spec.options.items() if key not in EXPLORABLE_OPTIONS}
    check_keys(base, own, f"scene spec '{spec.text}'", noun=f"{source} option")
    return OmegaConf.merge(base, own)


def load_scene(spec: str | SceneSpec, conf: DictConfig) -> Scene:
    """Load a scene from a spec string (see :mod:`frontiernet.scenes.spec`).

    Args:
        spec: e.g. ``"procedural:3"``, ``"house.glb"``, ``"floorplan:plan.png?resolution=0.05"``.
        conf: the scenes config as the command resolved it (``configs/scenes.yaml``: one section
            per source, merged with the spec's options).
    Returns:
        A validated :class:`Scene` in world coordinates (Z-up, metres).
    Raises:
        InputError: unknown source, missing or corrupt file, empty mesh, bad option.

    Every source also takes the options ``seed`` and ``bounds`` (:func:`~.spec.explorable_options`),
    kept on the scene's metadata for the voxeliser's explorable space.
    """
    spec = parse_spec(spec) if isinstance(spec, str) else spec
    seed, box = explorable_options(spec)
    scene = SCENE_SOURCES.get(spec.source)(spec, _section(conf, spec.source, spec))
    scene.metadata.explorable_seed, scene.metadata.explorable_bounds = seed, box
    return scene

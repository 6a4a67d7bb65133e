"""Scenes: one :class:`Scene` type and one :func:`load_scene` for every source.

See :mod:`frontiernet.scenes.spec` for the spec syntax.
"""

from __future__ import annotations

from omegaconf import DictConfig, OmegaConf

from ..config import check_keys, load_config
from ..errors import InputError
from .scene import Material, Scene, SceneMetadata
from .spec import DEFAULT_SPEC, EXPLORABLE_OPTIONS, SceneSpec, explorable_options, parse_spec

__all__ = ["Material", "Scene", "SceneMetadata", "SceneSpec", "load_scene", "parse_spec", "DEFAULT_SPEC"]


def _section(conf: DictConfig, source: str, spec: SceneSpec) -> DictConfig:
    base = conf[source]
    own = {key: value for key, value in spec.options.items() if key not in EXPLORABLE_OPTIONS}
    check_keys(base, own, f"scene spec '{spec.text}'", noun=f"{source} option")
    return OmegaConf.merge(base, own)


def load_scene(spec: str | SceneSpec, conf: DictConfig | None = None) -> Scene:
    """Load a scene from a spec string (see :mod:`frontiernet.scenes.spec`).

    Args:
        spec: e.g. ``"procedural:3"``, ``"house.glb"``, ``"floorplan:plan.png?resolution=0.05"``.
        conf: the scenes config (``configs/scenes.yaml``); loaded when None.
    Returns:
        A validated :class:`Scene` in world coordinates (Z-up, metres).
    Raises:
        InputError: unknown source, missing or corrupt file, empty mesh, bad option.

    Every source also takes the options ``seed`` and ``bounds`` (:func:`~.spec.explorable_options`),
    kept on the scene's metadata for the voxeliser's explorable space.
    """
    spec = parse_spec(spec) if isinstance(spec, str) else spec
    conf = conf if conf is not None else load_config("scenes")
    seed, box = explorable_options(spec)
    scene = _load_source(spec, _section(conf, spec.source, spec))
    scene.metadata.explorable_seed, scene.metadata.explorable_bounds = seed, box
    return scene


def _load_source(spec: SceneSpec, options: DictConfig) -> Scene:
    """The scene of `spec` from its source, `options` its section of the scenes config."""
    if spec.source == "mesh":
        from .mesh_files import load_mesh_file

        return load_mesh_file(spec.argument, spec.text, up=options.up, scale=options.scale,
                              max_texture_size=int(options.max_texture_size),
                              geometry_only=bool(options.geometry_only))
    if spec.source == "hm3d":
        from .mesh_files import load_hm3d

        return load_hm3d(spec.argument, spec.text, geometry_only=bool(options.geometry_only),
                         max_texture_size=int(options.max_texture_size))
    if spec.source == "floorplan":
        from .floorplan import load_floorplan

        return load_floorplan(spec.argument, spec.text, options)
    if spec.source == "procedural":
        from .procedural import generate_procedural_scene

        try:
            seed = int(spec.argument)
        except ValueError:
            raise InputError(f"scene spec '{spec.text}': procedural seed must be an integer") from None
        if seed < 0:
            raise InputError(f"scene spec '{spec.text}': procedural seed must be >= 0")
        return generate_procedural_scene(seed, spec.text, options)
    raise InputError(f"unknown scene source '{spec.source}'")

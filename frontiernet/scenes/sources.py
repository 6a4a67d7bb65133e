"""Scene sources: name -> loader ``load(spec, options) -> Scene`` (:data:`SCENE_SOURCES`).

`spec` is the parsed :class:`~frontiernet.scenes.spec.SceneSpec` (its ``argument``: a path or a
seed; ``text``: the spec as written, for messages and the scene's metadata) and `options` the
source's section of the scenes config (``configs/scenes.yaml``) with the spec's options merged
in. Each loader imports its module when used, so naming the sources costs nothing.
"""

from __future__ import annotations

from ..errors import InputError
from ..registry import Registry


def _mesh(spec, options):
    from .mesh_files import load_mesh_file

    return load_mesh_file(spec.argument, spec.text, up=options.up, scale=options.scale,
                          max_texture_size=int(options.max_texture_size), geometry_only=bool(options.geometry_only))


def _hm3d(spec, options):
    from .mesh_files import load_hm3d

    return load_hm3d(spec.argument, spec.text, geometry_only=bool(options.geometry_only),
                     max_texture_size=int(options.max_texture_size))


def _floorplan(spec, options):
    from .floorplan import load_floorplan

    return load_floorplan(spec.argument, spec.text, options)


def _procedural(spec, options):
    from .procedural import generate_procedural_scene

    try:
        seed = int(spec.argument)
    except ValueError:
        raise InputError(f"scene spec '{spec.text}': procedural seed must be an integer") from None
    if seed < 0:
        raise InputError(f"scene spec '{spec.text}': procedural seed must be >= 0")
    return generate_procedural_scene(seed, spec.text, options)


SCENE_SOURCES = Registry("scene source", None, {"mesh": _mesh, "hm3d": _hm3d, "floorplan": _floorplan,
                                                "procedural": _procedural})
"""The scene sources, in the order specs name them (built in only: each has its section of
``configs/scenes.yaml``)."""

__all__ = ["SCENE_SOURCES"]

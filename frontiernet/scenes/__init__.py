"""Scenes: one :class:`Scene` type and one :func:`load_scene` for every source
(:data:`~frontiernet.scenes.spec.SCENE_SOURCES`: mesh files, HM3D, floor plans, procedural).

See :mod:`frontiernet.scenes.spec` for the spec syntax and the sources.
"""

from .scene import Material, Scene, SceneMetadata
from .spec import DEFAULT_SPEC, SceneSpec, load_scene, parse_spec

__all__ = ["Material", "Scene", "SceneMetadata", "SceneSpec", "load_scene", "parse_spec", "DEFAULT_SPEC"]

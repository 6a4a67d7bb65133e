"""Scene specs: the strings users pass to name a scene.

Syntax: [SOURCE:]ARGUMENT[?key=value&key=value...]

  path/to/scene.glb                   a mesh file (.glb, .gltf, .obj, .ply), loaded as stored
  mesh:path/to/scene.glb?up=y         a mesh file, converting Y-up to Z-up (up=z is the default)
  hm3d:ROOT/SPLIT/00800-TEEsavR23oF   an HM3D scene folder (or its <id>.glb); Y-up converted
  floorplan:plan.png?resolution=0.05  a 2D occupancy image or .npy array (metres/pixel)
  floorplan:path/to/kth/50052750      a KTH/MapEx folder (occ_map.npy, valid_space.npy), 0.05 m/px
  procedural:7                        the built-in multi-room generator, seed 7
  procedural:7?floors=2               ... with generator options (configs/scenes.yaml)
  default                             procedural:0

Several scenes at once (:func:`expand_specs`, for commands that take many):

  procedural:0-199                    seeds 0 to 199 (options after '?' apply to each)
  'scans/*.glb', 'hm3d:ROOT/train/*'  a glob (quoted, so the shell leaves it alone)
  ROOT/train                          a folder of scene folders (HM3D scenes, KTH floor plans)

Every source also takes two options about the space exploration is scored on
(frontiernet/scenes/explorable.py, docs/exploration.md):

  shop.glb?seed=2.5,4                 a point (x,y or x,y,z, metres) on the floor inside the
                                      building: the explorable space is grown from there (x,y:
                                      the lowest floor there; x,y,z: the highest at or below z)
  site.glb?bounds=-5,-5,0,20,15,4     a box xmin,ymin,zmin,xmax,ymax,zmax (metres): nothing
                                      outside it is explorable (meshes with surroundings)

A bare path is recognised by what it is: a mesh file by its extension, a folder with
occ_map.npy as a floor plan, a folder with a .glb as an HM3D scene. Options after '?'
override the source's section of configs/scenes.yaml (e.g. floorplan: wall_height,
ceiling, door_height; mesh: up, scale).

:func:`load_scene` is the one way from a spec to a :class:`~frontiernet.scenes.scene.Scene`:
parse it, look its source up in :data:`SCENE_SOURCES` (name -> loader
``load(spec, options) -> Scene``, where `options` is the source's section of the scenes config
with the spec's options merged in; each loader imports its module when used, so naming the
sources costs nothing) and call that loader.
"""

from __future__ import annotations

import glob
import logging
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml
from omegaconf import DictConfig, OmegaConf

from ..config import check_ranges
from ..errors import InputError, check_keys
from ..io import present
from ..registry import Registry
from .scene import Scene

log = logging.getLogger(__name__)


MESH_SUFFIXES = (".glb", ".gltf", ".obj", ".ply")
DEFAULT_SPEC = "procedural:0"
MAX_SEED_RANGE = 100_000
"""The most scenes one seed range (``procedural:A-B``) may name: 200 times the paper's datasets;
a larger one would only be listed for minutes before any work (:func:`expand_specs`)."""


@dataclass
class SceneSpec:
    """A parsed scene spec: `source`, its `argument` (path or seed) and `options`."""

    source: str
    argument: str
    options: dict = field(default_factory=dict)
    text: str = ""


EXPLORABLE_OPTIONS = ("seed", "bounds")
"""Options every source takes (not in any source's section of configs/scenes.yaml)."""


def _numbers(spec: SceneSpec, key: str, counts: tuple[int, ...], form: str) -> np.ndarray | None:
    """The comma-separated numbers of option `key`, (n,) float64 with n in `counts`, or None."""
    value = spec.options.get(key)
    if value is None:
        return None
    try:
        numbers = np.array([float(part) for part in str(value).split(",")], np.float64)
    except ValueError:
        numbers = np.empty(0)
    if len(numbers) not in counts or not np.isfinite(numbers).all():
        raise InputError(f"scene spec '{spec.text}': {key}={value} must be {form} (finite numbers, metres)")
    return numbers


def explorable_options(spec: SceneSpec) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The spec's ``seed`` ((2,) or (3,) float64 metres) and ``bounds`` ((2, 3) float64 [min, max]
    corners, metres) options, each None when not given.

    Raises:
        InputError: a value that is not 2 or 3 numbers (seed) or 6 numbers with min < max on
            every axis (bounds), or a seed outside the bounds box.
    """
    seed = _numbers(spec, "seed", (2, 3), "x,y or x,y,z")
    box = _numbers(spec, "bounds", (6,), "xmin,ymin,zmin,xmax,ymax,zmax")
    if box is not None:
        box = box.reshape(2, 3)
        if not (box[0] < box[1]).all():
            raise InputError(f"scene spec '{spec.text}': bounds={spec.options['bounds']} must have "
                             "xmin < xmax, ymin < ymax and zmin < zmax")
        if seed is not None and not ((box[0, :len(seed)] <= seed) & (seed <= box[1, :len(seed)])).all():
            raise InputError(f"scene spec '{spec.text}': seed={spec.options['seed']} is outside "
                             f"bounds={spec.options['bounds']}")
    return seed, box


def _parse_value(text: str):
    """``"0.05"`` and ``"5e-2"`` -> 0.05, ``"true"`` -> True, anything else stays a string."""
    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError:
        return text
    if isinstance(value, str):
        try:
            return float(value)  # YAML 1.1 reads a number without its dot (5e-2, 1e9) as text
        except ValueError:
            return value
    return value


def _guess_source(argument: str) -> str:
    path = Path(argument)
    if path.suffix.lower() in MESH_SUFFIXES:
        return "mesh"
    if path.is_dir():
        if present(path / "occ_map.npy"):  # (a pipe or a folder there: the plan reader names it)
            return "floorplan"
        if any(path.glob("*.glb")):
            return "hm3d"
        raise InputError(f"{argument}: folder is neither a floor plan (no occ_map.npy) "
                         "nor an HM3D scene (no .glb)")
    if path.suffix.lower() in (".npy", ".png", ".pgm", ".jpg", ".bmp", ".tif", ".tiff"):
        return "floorplan"
    if not path.exists():
        raise InputError(f"{argument}: no such file, and not a known scene source "
                         f"(use one of {', '.join(s + ':' for s in SOURCES)} or 'default')")
    raise InputError(f"{argument}: unsupported scene format '{path.suffix}' "
                     f"(supported meshes: {', '.join(MESH_SUFFIXES)})")


def _names_a_path(body: str) -> bool:
    """Whether spec body `body` (``[SOURCE:]ARGUMENT``) names an existing file or folder."""
    source, colon, argument = body.partition(":")
    return os.path.exists(argument if colon and source in SOURCES else body)


def split_options(text: str) -> tuple[str, str, str]:
    """(body, ``?`` or ``""``, options) of scene spec `text`, split at its first ``?``, unless a ``?`` is part of
    the name of an existing file or folder (``a?b.glb``): the name wins (the spec's options, if any, follow the
    ``?`` after it; ``a?b.glb?up=y``), where the first ``?`` read ``b.glb`` as an option that is no key=value."""
    marks = [at for at, char in enumerate(text) if char == "?"]
    for at in [len(text)] + marks[:0:-1] if marks else ():
        if _names_a_path(text[:at]):
            return text[:at], text[at:at + 1], text[at + 1:]
    return text.partition("?")


def parse_spec(text: str) -> SceneSpec:
    """Parse a scene spec string; raises :class:`InputError` on a malformed one."""
    text = str(text).strip()
    if not text:
        raise InputError("empty scene spec")
    body, mark, query = split_options(text)
    if body == "default":  # (with options too: default?bounds=... is procedural:0?bounds=...)
        body = DEFAULT_SPEC
        text = body + mark + query
    options = {}
    if query:
        for item in query.split("&"):
            key, eq, value = item.partition("=")
            if not eq or not key:  # (a file named a?b.glb is read as that file where it exists: split_options)
                source, colon, name = text.partition(":")
                name = name if colon and source in SOURCES else text
                raise InputError(f"scene spec '{text}': option '{item}' is not key=value ('?' starts the options; "
                                 f"no file or folder is named '{name}')")
            if not value.strip():  # (read as null: the option would be dropped without a word)
                raise InputError(f"scene spec '{text}': option {key}= has no value; give {key}=VALUE, or leave "
                                 f"{key} out")
            options[key] = _parse_value(value)
    source, colon, argument = body.partition(":")
    if colon and source in SOURCES:
        if not argument:
            raise InputError(f"scene spec '{text}': nothing after '{source}:'")
        return SceneSpec(source, argument, options, text)
    return SceneSpec(_guess_source(body), body, options, text)


def _is_scene_folder(path: Path) -> bool:
    return present(path / "occ_map.npy") or any(path.glob("*.glb"))


def _plain_seed(text: str) -> bool:
    """Whether `text` is a seed as the docs write one: the digits 0-9 alone (``int`` also reads ``+3``, `` 3``,
    ``1_000`` and other scripts' digits, each then a second name, and a second run, of one scene)."""
    return bool(re.fullmatch(r"[0-9]+", text))


def scene_file(text: str) -> str | None:
    """The file or folder scene spec `text` reads (None: a procedural scene, made from its seed), for the checks
    that keep a command's outputs off its inputs (:func:`~frontiernet.io.check_not_an_input`)."""
    spec = parse_spec(text)
    return None if spec.source == "procedural" else spec.argument


def checked_spec(text: str) -> SceneSpec:
    """:func:`parse_spec` of `text` and, before any scene is loaded, its seed (:func:`procedural_seed`) or its file
    or folder: InputError ``<spec>: no such scene file or folder`` (for commands that load scenes one by one
    later, so a bad one among many fails before any work starts)."""
    spec = parse_spec(text)
    if spec.source == "procedural":
        procedural_seed(spec.text, spec.argument)
    elif not Path(spec.argument).exists():
        raise InputError(f"{text}: no such scene file or folder")
    return spec


def procedural_seed(text: str, argument: str) -> int:
    """The seed of procedural scene spec `text` (`argument`: what follows ``procedural:``); InputError naming
    `text` unless it is :func:`_plain_seed` (a range, ``3-5``, names several scenes: said so)."""
    if not _plain_seed(argument):
        first, dash, last = argument.partition("-")
        if dash and first.strip().isdigit() and last.strip().isdigit():
            _seed_range(text, argument)  # 3-1 names no scene: said so
            raise InputError(f"scene spec '{text}': a range of seeds names several scenes, and this takes one "
                             f"(e.g. procedural:{first.strip()})")
        if argument.strip().startswith("-") and argument.strip()[1:].isdigit():
            raise InputError(f"scene spec '{text}': procedural seed must be >= 0")
        raise InputError(f"scene spec '{text}': procedural seed must be an integer >= 0 in the digits 0-9 alone, "
                         "e.g. procedural:3")
    return int(argument)


def _seed_range(text: str, argument: str) -> tuple[int, int]:
    """(FIRST, LAST) of the seed range `argument` (``FIRST-LAST``) of scene spec `text`; InputError naming
    `text` unless both are integers with 0 <= FIRST <= LAST (an inverted range names no scene)."""
    first, _, last = argument.partition("-")
    if not (_plain_seed(first) and _plain_seed(last)):
        raise InputError(f"scene spec '{text}': a seed range is procedural:FIRST-LAST, e.g. procedural:0-199")
    low, high = int(first), int(last)
    if not 0 <= low <= high:
        raise InputError(f"scene spec '{text}': seed range must satisfy 0 <= FIRST <= LAST")
    return low, high


def expand_specs(texts) -> list[str]:
    """Expand seed ranges, globs and folders of scene folders into single scene specs.

    ``procedural:A-B`` gives seeds A..B inclusive; a spec with ``*``, ``?`` or ``[``
    gives the sorted paths it matches; a folder that is not itself a scene but holds
    scene folders (an HM3D split, a folder of KTH plans) gives those folders. Options
    after '?' and an explicit ``source:`` prefix carry over to every expanded spec.
    Duplicates (the same :func:`scene_identity`) are dropped with a warning, order is kept. Raises :class:`InputError` when a range is
    malformed or a pattern or folder yields no scene.
    """
    out: list[str] = []
    texts = list(texts)
    for index, text in enumerate(texts):
        text = str(text).strip()
        if not text:  # ('' was "empty scene spec", naming no option; a,,b a seed that is no integer)
            raise InputError(f"an empty scene spec (item {index + 1} of the {len(texts)} given); give scene specs as "
                             "separate words, e.g. --scenes procedural:3 procedural:4")
        body, mark, query = split_options(text)
        suffix = mark + query
        source, colon, argument = body.partition(":")
        prefix = source + colon if colon and source in SOURCES else ""
        argument = argument if prefix else body
        if prefix == "procedural:" and "," in argument:
            raise InputError(f"scene spec '{text}': scenes are separate words (--scenes procedural:3 procedural:4), "
                             "not joined by commas")
        if prefix == "procedural:" and "-" in argument.lstrip("-"):
            low, high = _seed_range(text, argument)
            if high - low + 1 > MAX_SEED_RANGE:
                raise InputError(f"scene spec '{text}': a seed range of {high - low + 1:,} scenes; at most "
                                 f"{MAX_SEED_RANGE:,} in one range (split the work into several runs)")
            out += [f"procedural:{seed}{suffix}" for seed in range(low, high + 1)]
        elif any(c in argument for c in "*?[") and not os.path.exists(argument):  # (a?b.glb: that file)
            matches = sorted(glob.glob(argument))
            if not matches:
                raise InputError(f"scene spec '{text}': the pattern matches no file or folder")
            out += [f"{prefix}{path}{suffix}" for path in matches]
        elif not prefix and Path(argument).is_dir() and not _is_scene_folder(Path(argument)):
            folders = sorted(p for p in Path(argument).iterdir() if p.is_dir() and _is_scene_folder(p))
            if not folders:
                raise InputError(f"{argument}: folder is not a scene and holds no scene folders "
                                 "(floor plans with occ_map.npy, HM3D scenes with a .glb)")
            out += [f"{path}{suffix}" for path in folders]
        else:
            out.append(text)
    kept: dict[tuple, str] = {}
    for text in out:
        identity = scene_identity(text)
        if identity in kept and kept[identity] != text:
            log.warning("scene %s is %s, given already: it runs once", text, kept[identity])
        kept.setdefault(identity, text)
    return list(kept.values())


def scene_identity(text: str) -> tuple:
    """What makes two specs the same scene: the source, the seed (``procedural:03`` is ``procedural:3``) or the
    resolved path, and the options in any order (``a.glb?up=z&scale=1`` is ``./a.glb?scale=1&up=z``)."""
    spec = parse_spec(text)
    argument = spec.argument
    if spec.source == "procedural":
        argument = int(argument) if _plain_seed(argument) else argument
    else:
        argument = str(Path(argument).resolve())
    return spec.source, argument, tuple(sorted((key, repr(value)) for key, value in spec.options.items()))


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

    if "resolution" in spec.options and Path(spec.argument).is_dir():  # (10x made a 427 m plan, minutes and 6.6 GB)
        raise InputError(f"scene spec '{spec.text}': ?resolution= scales an image floor plan; a KTH / MapEx plan "
                         f"folder is {float(options.kth_resolution):g} m/pixel (scenes.floorplan.kth_resolution): "
                         "leave resolution out, or set kth_resolution for plans of another scale")

    return load_floorplan(spec.argument, spec.text, options)


def _procedural(spec, options):
    from .procedural import generate_procedural_scene

    return generate_procedural_scene(procedural_seed(spec.text, spec.argument), spec.text, options)


SCENE_SOURCES = Registry("scene source", None, {"mesh": _mesh, "hm3d": _hm3d, "floorplan": _floorplan,
                                                "procedural": _procedural})
"""The scene sources, in the order specs name them (built in only: each has its section of
``configs/scenes.yaml``)."""

SOURCES = tuple(SCENE_SOURCES.names())  # the sources a spec may name before ':'


def _section(conf: DictConfig, source: str, spec: SceneSpec) -> DictConfig:
    base = conf[source]
    own = {key: value for key, value in spec.options.items() if key not in EXPLORABLE_OPTIONS}
    check_keys(base, own, f"scene spec '{spec.text}'", noun=f"{source} option")
    merged = OmegaConf.merge(base, own)
    try:  # the spec's options keep to configs/ranges/scenes.yaml as a config's do
        check_ranges(merged, {"": f"scenes.{source}"})
    except InputError as error:
        raise InputError(f"scene spec '{spec.text}': {source} option {error}") from None
    return merged


def load_scene(spec: str | SceneSpec, conf: DictConfig) -> Scene:
    """Load a scene from a spec string (see the syntax above).

    Args:
        spec: e.g. ``"procedural:3"``, ``"house.glb"``, ``"floorplan:plan.png?resolution=0.05"``.
        conf: the scenes config as the command resolved it (``configs/scenes.yaml``: one section
            per source, merged with the spec's options).
    Returns:
        A validated :class:`Scene` in world coordinates (Z-up, metres).
    Raises:
        InputError: unknown source, missing or corrupt file, empty mesh, bad option.

    Every source also takes the options ``seed`` and ``bounds`` (:func:`explorable_options`),
    kept on the scene's metadata for the voxeliser's explorable space.
    """
    spec = parse_spec(spec) if isinstance(spec, str) else spec
    seed, box = explorable_options(spec)
    scene = SCENE_SOURCES.get(spec.source)(spec, _section(conf, spec.source, spec))
    scene.metadata.explorable_seed, scene.metadata.explorable_bounds = seed, box
    return scene

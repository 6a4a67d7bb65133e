"""Mesh files (``.glb``/``.gltf``, ``.obj``, ``.ply``) and HM3D scenes, read with trimesh.

Textures (glTF ``baseColorTexture``, OBJ ``map_Kd``), flat material colours, and vertex
or face colours are kept. glTF files are loaded *as stored* by default (many robotics
exports, such as the shared AWS house, store Z-up coordinates despite glTF's Y-up
convention); ``?up=y`` converts Y-up to Z-up. HM3D scenes are always Y-up.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..geometry import T_ZUP_YUP
from ..io import input_file, present, why_missing
from .scene import Material, Scene, SceneMetadata

log = logging.getLogger(__name__)


def _texture_array(image, max_size: int) -> np.ndarray | None:
    """PIL image -> (H, W, 3) uint8, downscaled so that its longer side <= max_size."""
    if image is None:
        return None
    from PIL import Image

    image = image.convert("RGB")
    if max(image.size) > max_size:
        scale = max_size / max(image.size)
        image = image.resize((max(1, round(image.width * scale)), max(1, round(image.height * scale))),
                             Image.BILINEAR)
    return np.asarray(image, dtype=np.uint8)


def _material_of(visual, cache: dict, max_texture_size: int, geometry_only: bool):
    """(Material, has_uv) for a trimesh visual; materials are shared through `cache`."""
    material = getattr(visual, "material", None)
    if material is None:
        return None, False
    key = id(material)
    if key in cache:
        return cache[key], True
    image = None if geometry_only else (
        getattr(material, "baseColorTexture", None) or getattr(material, "image", None))
    factor = getattr(material, "baseColorFactor", None)
    if factor is None:
        factor = getattr(material, "main_color", None)
    color = np.asarray(factor if factor is not None else [180, 180, 180, 255], np.float64)[:3]
    if color.max() <= 1.0:
        color = color * 255.0
    texture = _texture_array(image, max_texture_size)
    if texture is not None and not np.allclose(color, 255.0):
        texture = (texture.astype(np.float32) * (color / 255.0)).clip(0, 255).astype(np.uint8)
    result = Material(name=getattr(material, "name", None) or f"material{len(cache)}",
                      color=color.clip(0, 255).astype(np.uint8), texture=texture)
    cache[key] = result
    return result, True


def _collect(trimesh_scene, max_texture_size: int, geometry_only: bool):
    """Flatten a trimesh scene graph into arrays, one material per source material."""
    import trimesh

    vertices, triangles, tri_material, tri_uvs, vertex_colors = [], [], [], [], []
    materials: list[Material] = []
    material_ids: dict[int, int] = {}
    cache: dict = {}
    offset = 0
    for node in trimesh_scene.graph.nodes_geometry:
        transform, geometry_name = trimesh_scene.graph[node]
        mesh = trimesh_scene.geometry.get(geometry_name)
        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
            continue
        v = trimesh.transform_points(np.asarray(mesh.vertices, np.float64), transform)
        f = np.asarray(mesh.faces, np.int64)
        visual = mesh.visual
        uv = getattr(visual, "uv", None) if visual.kind == "texture" else None
        colors = None
        material, _ = _material_of(visual, cache, max_texture_size, geometry_only) \
            if visual.kind == "texture" else (None, False)
        if visual.kind in ("vertex", "face") and not geometry_only:
            if visual.kind == "face":  # un-share vertices so each face keeps its colour
                v, f = v[f].reshape(-1, 3), np.arange(f.size).reshape(-1, 3)
                colors = np.repeat(np.asarray(visual.face_colors)[:, :3], 3, axis=0)
            else:
                colors = np.asarray(visual.vertex_colors)[:, :3]
            material = Material("vertex-colors", use_vertex_colors=True)
        if material is None:
            material = Material("default")
        if material.use_vertex_colors:
            key = -1
        else:
            key = id(material)
        if key not in material_ids:
            material_ids[key] = len(materials)
            materials.append(material)
        vertices.append(v)
        triangles.append(f + offset)
        tri_material.append(np.full(len(f), material_ids[key], np.int32))
        has_uv = uv is not None and len(uv) == len(mesh.vertices) and material.texture is not None
        tri_uvs.append(np.asarray(uv, np.float32)[f] if has_uv else np.zeros((len(f), 3, 2), np.float32))
        vertex_colors.append(colors if colors is not None else np.full((len(v), 3), 255, np.uint8))
        offset += len(v)
    return vertices, triangles, tri_material, tri_uvs, vertex_colors, materials


GLB_HEADER = 12
"""Bytes of a .glb file's header: b"glTF", its version and its whole length (little-endian uint32s)."""


def _check_glb_length(path: Path) -> None:
    """InputError naming .glb file `path` when it is shorter than its header, has no glTF header, or holds fewer
    bytes than its header says the file has (cut off in a copy or a download: trimesh then failed on the JSON
    chunk it holds, with a message about a missing ',')."""
    size = path.stat().st_size
    with open(path, "rb") as file:
        header = file.read(GLB_HEADER)
    problem = (f"{size} bytes, fewer than the {GLB_HEADER} of a .glb header" if len(header) < GLB_HEADER else
               "its first bytes are not the 'glTF' a .glb file starts with: another format named .glb?"
               if header[:4] != b"glTF" else None)
    declared = int.from_bytes(header[8:12], "little") if problem is None else 0
    if problem is None and declared > size:
        problem = f"its header says the file has {declared:,} bytes, it holds {size:,}: the end is cut off"
    if problem:
        raise InputError(f"{path}: cannot read mesh: a corrupt or truncated .glb file ({problem})")


def _trimesh_failure(error: Exception) -> str:
    """What trimesh's `error` on a corrupt mesh file says, in words (no exception class name: a KeyError's 'y'
    is a property the file's header does not declare, an IndexError a face naming a vertex there is not)."""
    import json

    text = str(error).strip().splitlines()[0][:120] if str(error).strip() else ""
    if isinstance(error, json.JSONDecodeError):
        return f"its JSON is cut off or malformed: {error.msg} at line {error.lineno} column {error.colno}"
    if isinstance(error, IndexError):
        return f"a face names a vertex the file does not have{f'; trimesh: {text}' if text else ''}"
    if isinstance(error, KeyError):
        return f"a property or element the data needs is not declared{f': {text}' if text else ''}"
    if isinstance(error, UnicodeDecodeError):
        return f"text that is not UTF-8 at byte {error.start}"
    return f"trimesh: {text}" if text else "trimesh could not parse it"


def load_mesh_file(path: str | Path, spec_text: str, *, up: str = "z", scale: float = 1.0,
                   max_texture_size: int = 1024, geometry_only: bool = False,
                   source: str = "mesh") -> Scene:
    """Read a mesh file into a :class:`Scene` (Z-up, metres).

    Args:
        path: ``.glb``, ``.gltf``, ``.obj`` or ``.ply`` file.
        spec_text: the spec, for messages and metadata.
        up: ``"z"`` (as stored) or ``"y"`` (convert Y-up to Z-up).
        scale: multiply coordinates by this (e.g. 0.01 for centimetres).
        max_texture_size: textures are downscaled to at most this many pixels a side.
        geometry_only: drop textures and colours (grey materials).
    """
    try:
        import trimesh
    except ImportError:  # a torch-only GPU node: procedural and floor-plan scenes need no trimesh
        raise InputError(f"{spec_text}: loading mesh files needs trimesh (pip install trimesh)") from None

    path = input_file(path, "mesh file", empty_ok=False)
    if path.suffix.lower() not in (".glb", ".gltf", ".obj", ".ply"):
        raise InputError(f"{path}: unsupported mesh format '{path.suffix}' (use .glb, .gltf, .obj or .ply)")
    if up not in ("y", "z"):
        raise InputError(f"{spec_text}: up must be 'y' or 'z', got '{up}'")
    if not (isinstance(scale, (int, float)) and scale > 0 and np.isfinite(scale)):
        raise InputError(f"{spec_text}: scale must be a positive number, got {scale!r}")
    if path.suffix.lower() == ".glb":
        _check_glb_length(path)
    try:
        loaded = trimesh.load(str(path), force="scene", process=False)
    except Exception as error:  # trimesh raises many types on corrupt input
        raise InputError(f"{path}: cannot read mesh: a corrupt or truncated {path.suffix.lower()} file "
                         f"({_trimesh_failure(error)})") from None
    vertices, triangles, tri_material, tri_uvs, vertex_colors, materials = _collect(
        loaded, max_texture_size, geometry_only)
    if not triangles:
        raise InputError(f"{path}: the mesh is empty (no triangles)")
    vertices = np.concatenate(vertices)
    if up == "y":
        vertices = vertices @ T_ZUP_YUP[:3, :3].T
    vertices = vertices * scale
    any_texture = any(m.texture is not None for m in materials)
    any_colors = any(m.use_vertex_colors for m in materials)
    metadata = SceneMetadata(
        name=path.name.split(".")[0], source=source, spec=spec_text,
        up_axis_conversion="y-up to z-up" if up == "y" else "none",
        extra={"file": str(path), "scale": scale, "materials": len(materials),
               "textured_materials": sum(m.texture is not None for m in materials)},
    )
    return Scene(
        vertices=vertices, triangles=np.concatenate(triangles), triangle_material=np.concatenate(tri_material),
        materials=materials, metadata=metadata,
        triangle_uvs=np.concatenate(tri_uvs) if any_texture else None,
        vertex_colors=np.concatenate(vertex_colors) if any_colors else None,
    )


def find_hm3d_glb(path: str | Path) -> Path:
    """Resolve an HM3D scene folder (``<root>/<split>/<NNNNN-id>``) or file to its ``<id>.glb``, else the
    folder's one .glb (``.basis.glb``) file; InputError for none, or for several, none named ``<id>.glb``
    (two unrelated meshes: the first by name was read as the scene)."""
    path = Path(path)
    if path.is_file():
        return path
    if path.exists() and not path.is_dir():  # a device or a pipe
        input_file(path, "HM3D scene file")
    if not path.is_dir():
        raise InputError(f"{path}: no such HM3D scene folder or file{why_missing(path)}")
    scene_id = path.name.split("-", 1)[-1]
    if present(path / f"{scene_id}.glb"):  # the scene's own file: a pipe, a folder or a loop there named so
        return input_file(path / f"{scene_id}.glb", "HM3D scene mesh")
    plain = [glb for glb in sorted(path.glob("*.glb"))
             if glb.is_file() and not glb.name.endswith((".basis.glb", ".semantic.glb"))]
    for found in (plain, sorted(path.glob("*.basis.glb"))):
        if len(found) > 1:
            raise InputError(f"{path}: several .glb files ({', '.join(glb.name for glb in found[:4])}"
                             f"{' ...' if len(found) > 4 else ''}) and none named {scene_id}.glb, an HM3D scene "
                             "folder's own; give the scene's file")
        if found:
            return found[0]
    for odd in sorted(path.glob("*.glb")):  # (the name of a .glb, but no regular file: say what it is)
        input_file(odd, "HM3D scene mesh")
    raise InputError(f"{path}: HM3D scene folder holds no .glb file")


def load_hm3d(path: str | Path, spec_text: str, *, geometry_only: bool = False,
              max_texture_size: int = 1024) -> Scene:
    """Read an HM3D scene (glTF, Y-up) and convert it to Z-up.

    HM3D's ``.basis.glb`` release stores Basis-Universal-compressed textures, which
    no Python library here decodes: such a file is refused, unless
    ``geometry_only=True``, which loads the geometry with grey materials and logs a
    warning.
    """
    glb = find_hm3d_glb(path)
    if glb.name.endswith(".basis.glb"):
        if not geometry_only:
            raise InputError(
                f"{glb}: Basis-compressed HM3D textures cannot be decoded; use the plain '.glb' release "
                "(hm3d-*-glb-v0.2) or add '?geometry_only=true' to load it without textures")
        log.warning("%s: loading geometry only (Basis-compressed textures are not decoded)", glb)
    scene = load_mesh_file(glb, spec_text, up="y", max_texture_size=max_texture_size,
                           geometry_only=geometry_only, source="hm3d")
    scene.metadata.name = glb.name.split(".")[0]
    scene.metadata.extra["hm3d_folder"] = str(glb.parent)
    scene.metadata.extra["geometry_only"] = bool(geometry_only)
    return scene

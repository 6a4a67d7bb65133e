"""The one scene type: a triangle mesh with per-triangle materials.

Every source (mesh files, HM3D, floor plans, procedural) produces a :class:`Scene`
in the world frame of docs/design.md: Z-up, metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError


@dataclass
class Material:
    """Surface appearance of a set of triangles.

    Attributes:
        name: free text.
        color: (3,) uint8 RGB used when there is no texture (and no vertex colours).
        texture: optional (H, W, 3) uint8 RGB image, sampled with the triangle's UVs
            (OpenGL convention, v up; wrap mode repeat, as glTF's default).
        use_vertex_colors: without a texture, interpolate the scene's vertex colours
            instead of using `color` (meshes with per-vertex colour, e.g. PLY).
    """

    name: str
    color: np.ndarray = field(default_factory=lambda: np.array([180, 180, 180], np.uint8))
    texture: np.ndarray | None = None
    use_vertex_colors: bool = False

    def __post_init__(self) -> None:
        self.color = np.asarray(self.color, dtype=np.uint8).reshape(3)
        if self.texture is not None:
            texture = np.asarray(self.texture)
            if texture.ndim == 2:
                texture = np.repeat(texture[..., None], 3, axis=-1)
            self.texture = np.ascontiguousarray(texture[..., :3], dtype=np.uint8)


@dataclass
class SceneMetadata:
    """Where a scene came from and what was done to it on load.

    Attributes:
        name: short name (file stem, ``procedural-7``...).
        source: ``mesh``, ``hm3d``, ``floorplan`` or ``procedural``.
        spec: the spec string it was loaded from.
        units: always ``"m"`` after loading (sources in other units are scaled).
        up_axis_conversion: ``"none"`` or ``"y-up to z-up"``.
        extra: source-specific facts (resolution, seed, room count, warnings...).
        explorable_seed: None, or (2,) / (3,) float64 world metres from the spec's ``?seed=x,y[,z]``:
            a point on the floor inside the building that the explorable space is grown from
            (:mod:`frontiernet.scenes.explorable`).
        explorable_bounds: None, or (2, 3) float64 world [min, max] corners (metres) from the spec's
            ``?bounds=xmin,ymin,zmin,xmax,ymax,zmax``: nothing outside the box is explorable.
    """

    name: str
    source: str
    spec: str
    units: str = "m"
    up_axis_conversion: str = "none"
    extra: dict = field(default_factory=dict)
    explorable_seed: np.ndarray | None = None
    explorable_bounds: np.ndarray | None = None


@dataclass(eq=False)  # identity semantics: scenes are hashable keys of per-scene caches
class Scene:
    """A triangle mesh with per-triangle material, in world coordinates (Z-up, metres).

    Attributes:
        vertices: (V, 3) float32 metres.
        triangles: (T, 3) int32 vertex indices.
        triangle_material: (T,) int32 index into `materials`.
        triangle_uvs: (T, 3, 2) float32 texture coordinates of each corner, or None
            when no material has a texture.
        vertex_colors: (V, 3) uint8, or None; used by materials with
            ``use_vertex_colors`` (PLY files with colours).
        materials: list of :class:`Material`.
        metadata: :class:`SceneMetadata`.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    triangle_material: np.ndarray
    materials: list[Material]
    metadata: SceneMetadata
    triangle_uvs: np.ndarray | None = None
    vertex_colors: np.ndarray | None = None

    def __post_init__(self) -> None:
        with np.errstate(over="ignore"):  # past float32's range: inf, which validate refuses in one line (numpy's
            self.vertices = np.ascontiguousarray(self.vertices, dtype=np.float32).reshape(-1, 3)  # warning came first)
        self.triangles = np.ascontiguousarray(self.triangles, dtype=np.int32).reshape(-1, 3)
        self.triangle_material = np.ascontiguousarray(self.triangle_material, dtype=np.int32).reshape(-1)
        if self.triangle_uvs is not None:
            self.triangle_uvs = np.ascontiguousarray(self.triangle_uvs, dtype=np.float32).reshape(-1, 3, 2)
        if self.vertex_colors is not None:
            self.vertex_colors = np.ascontiguousarray(self.vertex_colors, dtype=np.uint8).reshape(-1, 3)
        self.validate()

    def validate(self) -> None:
        """Raise :class:`InputError` (naming the scene spec) if the mesh is unusable."""
        where = self.metadata.spec
        if len(self.triangles) == 0 or len(self.vertices) == 0:
            raise InputError(f"{where}: the mesh is empty (no triangles)")
        if not np.isfinite(self.vertices).all():
            bad = int((~np.isfinite(self.vertices).all(axis=1)).sum())
            raise InputError(f"{where}: {bad} vertices are NaN or infinite")
        if self.triangles.min() < 0 or self.triangles.max() >= len(self.vertices):
            raise InputError(f"{where}: triangle indices point outside the vertex array")
        if len(self.triangle_material) != len(self.triangles):
            raise InputError(f"{where}: triangle_material has {len(self.triangle_material)} entries "
                             f"for {len(self.triangles)} triangles")
        if len(self.materials) == 0 or self.triangle_material.min() < 0 \
                or self.triangle_material.max() >= len(self.materials):
            raise InputError(f"{where}: triangle material ids point outside the material list")
        if self.triangle_uvs is not None and len(self.triangle_uvs) != len(self.triangles):
            raise InputError(f"{where}: triangle_uvs has the wrong length")
        if self.vertex_colors is not None and len(self.vertex_colors) != len(self.vertices):
            raise InputError(f"{where}: vertex_colors has the wrong length")
        if any(m.use_vertex_colors for m in self.materials) and self.vertex_colors is None:
            raise InputError(f"{where}: a material uses vertex colours but the mesh has none")
        extent = self.bounds[1] - self.bounds[0]
        if not (extent > 0).sum() >= 2:
            raise InputError(f"{where}: the mesh is degenerate (extent {extent.round(3).tolist()} m)")

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) float64 axis-aligned bounds [min, max] in metres."""
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)]).astype(np.float64)

    @property
    def name(self) -> str:
        return self.metadata.name

    @property
    def num_triangles(self) -> int:
        return len(self.triangles)

    def triangle_areas(self) -> np.ndarray:
        """(T,) float64 triangle areas in m^2."""
        v = self.vertices.astype(np.float64)[self.triangles]
        return 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)

    def to_trimesh(self):
        """The geometry as a ``trimesh.Trimesh`` (no materials), for analysis and export."""
        import trimesh

        return trimesh.Trimesh(self.vertices, self.triangles, process=False)

"""Build scenes out of boxes and meshes (floor plans and procedural scenes).

A plan drawn on a grid becomes boxes in two steps: :func:`mask_rectangles` covers a boolean
mask exactly with rectangles, :func:`rect_boxes` turns them into box corners in metres for
:meth:`MeshBuilder.add_boxes`.

Texture coordinates of boxes are world-space planar projections (a face whose normal
is along x gets ``uv = (y, z) / texture_size_m``...), so a tiled texture keeps a
constant physical scale across walls of any length.
"""

from __future__ import annotations

import numpy as np

from .scene import Material, Scene, SceneMetadata

# Unit cube corners and its 12 triangles, outward-facing (counter-clockwise seen from outside).
_CUBE_CORNERS = np.array(
    [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], np.float64
)
# face name -> (four corner indices counter-clockwise from outside, axis of normal)
_CUBE_FACES = {
    "-z": ((0, 3, 2, 1), 2), "+z": ((4, 5, 6, 7), 2),
    "-y": ((0, 1, 5, 4), 1), "+y": ((2, 3, 7, 6), 1),
    "-x": ((0, 4, 7, 3), 0), "+x": ((1, 2, 6, 5), 0),
}
ALL_FACES = tuple(_CUBE_FACES)
# in-plane axes used for planar UVs, per normal axis
_UV_AXES = {0: (1, 2), 1: (0, 2), 2: (0, 1)}


def mask_rectangles(mask: np.ndarray) -> np.ndarray:
    """Cover a boolean (H, W) mask exactly with axis-aligned rectangles.

    Horizontal runs of each row are merged with identical runs of the rows below.
    Returns (N, 4) int64 ``[row0, col0, row1, col1)`` (half-open).
    """
    mask = np.asarray(mask, bool)
    padded = np.pad(mask, ((0, 0), (1, 1))).astype(np.int8)
    changes = np.diff(padded, axis=1)
    run_rows, run_starts = np.nonzero(changes == 1)  # row-major order
    _, run_ends = np.nonzero(changes == -1)
    rectangles = []
    open_runs: dict[tuple[int, int], int] = {}  # (col0, col1) -> first row
    previous_row = -2
    split_at = np.flatnonzero(np.diff(run_rows)) + 1
    for rows, starts, ends in zip(np.split(run_rows, split_at), np.split(run_starts, split_at),
                                  np.split(run_ends, split_at)):
        if len(rows) == 0:
            continue
        row = int(rows[0])
        runs = set(zip(starts.tolist(), ends.tolist()))
        for key in list(open_runs):
            if row != previous_row + 1 or key not in runs:
                rectangles.append((open_runs.pop(key), key[0], previous_row + 1, key[1]))
        for key in runs:
            open_runs.setdefault(key, row)
        previous_row = row
    for key, first_row in open_runs.items():
        rectangles.append((first_row, key[0], previous_row + 1, key[1]))
    return np.asarray(rectangles, np.int64).reshape(-1, 4)


def rect_boxes(rects: np.ndarray, shape, resolution: float, z0: float, z1: float):
    """Rectangles [r0, c0, r1, c1) -> box corners (N, 3) lower, (N, 3) upper in world metres."""
    H = shape[0]
    lower = np.stack([rects[:, 1] * resolution, (H - rects[:, 2]) * resolution, np.full(len(rects), z0)], 1)
    upper = np.stack([rects[:, 3] * resolution, (H - rects[:, 0]) * resolution, np.full(len(rects), z1)], 1)
    return lower, upper



class MeshBuilder:
    """Accumulates triangles with materials and UVs, then builds a :class:`Scene`."""

    def __init__(self) -> None:
        self.materials: list[Material] = []
        self._material_index: dict[str, int] = {}
        self._vertices: list[np.ndarray] = []
        self._triangles: list[np.ndarray] = []
        self._triangle_material: list[np.ndarray] = []
        self._uvs: list[np.ndarray] = []
        self._num_vertices = 0

    def material(self, material: Material) -> int:
        """Register `material` (deduplicated by name) and return its id."""
        if material.name not in self._material_index:
            self._material_index[material.name] = len(self.materials)
            self.materials.append(material)
        return self._material_index[material.name]

    def add_boxes(self, lower: np.ndarray, upper: np.ndarray, material_id: int | np.ndarray,
                  texture_size_m: float = 1.0, faces: tuple[str, ...] = ALL_FACES) -> None:
        """Add axis-aligned boxes (vectorised).

        Args:
            lower, upper: (N, 3) corners in metres (upper > lower).
            material_id: one id or (N,) ids.
            texture_size_m: metres covered by one repeat of the texture.
            faces: which faces to emit (e.g. skip "-z" for boxes standing on a floor).
        """
        lower = np.asarray(lower, np.float64).reshape(-1, 3)
        upper = np.asarray(upper, np.float64).reshape(-1, 3)
        if len(lower) == 0:
            return
        material_id = np.broadcast_to(np.asarray(material_id, np.int32), (len(lower),))
        corners = lower[:, None, :] + _CUBE_CORNERS[None] * (upper - lower)[:, None, :]  # (N, 8, 3)
        for face in faces:
            quad, axis = _CUBE_FACES[face]
            quad_vertices = corners[:, quad, :]  # (N, 4, 3)
            u_axis, v_axis = _UV_AXES[axis]
            quad_uvs = quad_vertices[..., [u_axis, v_axis]] / texture_size_m  # (N, 4, 2)
            n = len(lower)
            vertices = quad_vertices.reshape(-1, 3)
            base = np.arange(n)[:, None] * 4
            triangles = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=0)
            uv = np.concatenate([quad_uvs[:, [0, 1, 2]], quad_uvs[:, [0, 2, 3]]], axis=0)
            self._vertices.append(vertices)
            self._triangles.append(triangles + self._num_vertices)
            self._triangle_material.append(np.concatenate([material_id, material_id]))
            self._uvs.append(uv.astype(np.float32))
            self._num_vertices += len(vertices)

    def add_box(self, lower, upper, material_id: int, texture_size_m: float = 1.0,
                faces: tuple[str, ...] = ALL_FACES) -> None:
        """Add one axis-aligned box; see :meth:`add_boxes`."""
        self.add_boxes(np.asarray(lower)[None], np.asarray(upper)[None], material_id, texture_size_m, faces)

    def add_oriented_box(self, center, size, yaw: float, material_id: int,
                         texture_size_m: float = 1.0, faces: tuple[str, ...] = ALL_FACES) -> None:
        """Add a box of (3,) `size` metres centred at `center`, rotated by `yaw` about +z."""
        count = len(self._vertices)
        size = np.asarray(size, np.float64)
        self.add_box(-size / 2, size / 2, material_id, texture_size_m, faces)
        c, s = np.cos(yaw), np.sin(yaw)
        R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
        for i in range(count, len(self._vertices)):
            self._vertices[i] = self._vertices[i] @ R.T + np.asarray(center, np.float64)

    @property
    def num_triangles(self) -> int:
        return int(sum(len(t) for t in self._triangles))

    def build(self, metadata: SceneMetadata) -> Scene:
        """The accumulated geometry as a :class:`Scene`."""
        has_texture = any(m.texture is not None for m in self.materials)
        return Scene(
            vertices=np.concatenate(self._vertices) if self._vertices else np.zeros((0, 3)),
            triangles=np.concatenate(self._triangles) if self._triangles else np.zeros((0, 3)),
            triangle_material=np.concatenate(self._triangle_material) if self._triangles else np.zeros(0),
            materials=self.materials or [Material("default")],
            metadata=metadata,
            triangle_uvs=np.concatenate(self._uvs) if has_texture and self._uvs else None,
        )

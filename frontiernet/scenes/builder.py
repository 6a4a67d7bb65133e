"""Build scenes out of boxes and meshes (floor plans and procedural scenes), with procedural textures.

A plan drawn on a grid becomes boxes in two steps: :func:`mask_rectangles` covers a boolean
mask exactly with rectangles, :func:`rect_boxes` turns them into box corners in metres for
:meth:`MeshBuilder.add_boxes`.

Texture coordinates of boxes are world-space planar projections (a face whose normal
is along x gets ``uv = (y, z) / texture_size_m``...), so a tiled texture keeps a
constant physical scale across walls of any length.

Materials get procedural surface textures (:func:`make_texture`, numpy only, seeded): each
generator returns an (S, S, 3) uint8 RGB image that tiles seamlessly (noise is built from
periodic octaves), so planar world-space UVs with wrap-around show no seams.
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


def mask_rectangles(mask: np.ndarray, origin: tuple[int, int] = (0, 0)) -> np.ndarray:
    """Cover a boolean (H, W) mask exactly with axis-aligned rectangles.

    Horizontal runs of each row are merged with identical runs of the rows below.
    Returns (N, 4) int64 ``[row0, col0, row1, col1)`` (half-open), shifted by `origin` (row, col):
    the mask a crop of a larger plan at `origin` gives the rectangles, in the same order, that the
    whole plan (zero outside the crop) gives.
    """
    mask = np.asarray(mask, bool)
    padded = np.pad(mask, ((0, 0), (1, 1))).astype(np.int8)
    changes = np.diff(padded, axis=1)
    run_rows, run_starts = np.nonzero(changes == 1)  # row-major order
    _, run_ends = np.nonzero(changes == -1)
    run_rows, run_starts, run_ends = run_rows + origin[0], run_starts + origin[1], run_ends + origin[1]
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


# ----------------------------------------------------------------------------- textures

def _periodic_noise(rng: np.random.Generator, size: int, octaves: int = 4) -> np.ndarray:
    """(size, size) float32 in [0, 1], tileable value noise (sum of upsampled random grids)."""
    import cv2

    out = np.zeros((size, size), np.float32)
    amplitude, total = 1.0, 0.0
    for octave in range(octaves):
        cells = 2 ** (octave + 2)
        grid = rng.random((cells, cells)).astype(np.float32)
        tiled = np.tile(grid, (3, 3))  # wrap so interpolation is periodic
        big = cv2.resize(tiled, (3 * size, 3 * size), interpolation=cv2.INTER_CUBIC)
        out += amplitude * big[size:2 * size, size:2 * size]
        total += amplitude
        amplitude *= 0.5
    out /= total
    return (out - out.min()) / max(float(out.max() - out.min()), 1e-6)


def _shade(base_color, intensity: np.ndarray) -> np.ndarray:
    """Modulate an RGB colour by an (S, S) intensity field around 1."""
    base = np.asarray(base_color, np.float32).reshape(1, 1, 3)
    return np.clip(base * intensity[..., None], 0, 255).astype(np.uint8)


def plaster(rng, base_color, size: int = 64) -> np.ndarray:
    """Painted wall: faint low-frequency mottling."""
    return _shade(base_color, 0.92 + 0.12 * _periodic_noise(rng, size, 3))


def paint(rng, base_color, size: int = 64) -> np.ndarray:
    """Smooth painted surface: very faint large-scale mottling (walls, ceilings)."""
    return _shade(base_color, 0.96 + 0.05 * _periodic_noise(rng, size, 2))


def wood(rng, base_color, size: int = 128) -> np.ndarray:
    """Floor boards: planks along u with grain and per-plank tone."""
    planks = int(rng.integers(4, 9))
    v = np.arange(size)[:, None] * planks // size
    tone = 0.8 + 0.35 * rng.random(planks)[v]
    u = np.arange(size)[None, :] / size
    grain = 0.9 + 0.1 * np.sin(2 * np.pi * (u * rng.integers(2, 6) + 0.3 * _periodic_noise(rng, size, 3)) * 4)
    seams = np.where((np.arange(size)[:, None] * planks) % size < planks, 0.6, 1.0)
    return _shade(base_color, tone * grain * seams)


def tiles(rng, base_color, size: int = 128) -> np.ndarray:
    """Square tiles with grout lines."""
    count = int(rng.integers(2, 6))
    step = size // count
    y, x = np.mgrid[:size, :size]
    grout = ((x % step) < 2) | ((y % step) < 2)
    tone = 0.9 + 0.15 * rng.random((count + 1, count + 1))[y // step, x // step]
    intensity = np.where(grout, 0.75, tone * (0.95 + 0.08 * _periodic_noise(rng, size, 2)))
    return _shade(base_color, intensity)


def carpet(rng, base_color, size: int = 64) -> np.ndarray:
    """Carpet: fine high-frequency speckle."""
    return _shade(base_color, 0.8 + 0.3 * rng.random((size, size)).astype(np.float32))


def wallpaper(rng, base_color, size: int = 128) -> np.ndarray:
    """Vertical stripes in two tones."""
    stripes = int(rng.integers(3, 10))
    u = np.arange(size)[None, :].repeat(size, 0)
    intensity = np.where((u * stripes // size) % 2 == 0, 1.0, 0.82) * (0.95 + 0.08 * _periodic_noise(rng, size, 2))
    return _shade(base_color, intensity)


def brick(rng, base_color, size: int = 128) -> np.ndarray:
    """Running-bond brick with mortar."""
    rows = int(rng.integers(6, 12))
    h = size // rows
    y, x = np.mgrid[:size, :size]
    row = y // h
    offset = (row % 2) * (size // 4)
    w = size // 2
    mortar = ((y % h) < 2) | (((x + offset) % w) < 2)
    tone = 0.85 + 0.3 * rng.random((size // h + 1, 4))[row, ((x + offset) // w) % 4]
    return _shade(base_color, np.where(mortar, 1.4, tone))


def concrete(rng, base_color, size: int = 64) -> np.ndarray:
    """Concrete: mid-frequency blotches."""
    return _shade(base_color, 0.8 + 0.35 * _periodic_noise(rng, size, 5))


def fabric(rng, base_color, size: int = 64) -> np.ndarray:
    """Woven upholstery: fine cross-hatch weave with soft mottling."""
    period = int(rng.choice([4, 8]))
    y, x = np.mgrid[:size, :size]
    weave = np.where(((x // (period // 2)) + (y // (period // 2))) % 2 == 0, 1.0, 0.88)
    return _shade(base_color, weave * (0.9 + 0.15 * _periodic_noise(rng, size, 3)))


def marble(rng, base_color, size: int = 128) -> np.ndarray:
    """Polished stone: bright base with thin dark veins (ridges of periodic noise)."""
    noise = _periodic_noise(rng, size, 5)
    veins = np.abs(np.sin(np.pi * 6 * noise))
    intensity = 0.97 - 0.3 * np.clip(1.0 - veins / 0.15, 0.0, 1.0) + 0.06 * _periodic_noise(rng, size, 2)
    return _shade(base_color, intensity)


def parquet(rng, base_color, size: int = 128) -> np.ndarray:
    """Parquet: square blocks of short planks, alternating direction, per-plank tone."""
    blocks, planks = 4, int(rng.choice([2, 4]))
    step = size // blocks
    y, x = np.mgrid[:size, :size]
    by, bx, ly, lx = y // step, x // step, y % step, x % step
    vertical = (by + bx) % 2 == 0
    plank = np.where(vertical, lx * planks // step, ly * planks // step)
    seam = np.where(vertical, (lx * planks) % step < planks, (ly * planks) % step < planks) | (lx < 1) | (ly < 1)
    tone = 0.8 + 0.3 * rng.random((blocks, blocks, planks))[by, bx, plank]
    return _shade(base_color, np.where(seam, 0.6, tone * (0.93 + 0.1 * _periodic_noise(rng, size, 3))))


TEXTURES = {
    "plaster": plaster, "paint": paint, "wood": wood, "tiles": tiles, "carpet": carpet,
    "wallpaper": wallpaper, "brick": brick, "concrete": concrete,
    "fabric": fabric, "marble": marble, "parquet": parquet,
}


def make_texture(kind: str, rng: np.random.Generator, base_color, size: int | None = None) -> np.ndarray:
    """Generate a texture of `kind` (a key of :data:`TEXTURES`) around `base_color` (RGB 0-255)."""
    generator = TEXTURES[kind]
    return generator(rng, base_color) if size is None else generator(rng, base_color, size)

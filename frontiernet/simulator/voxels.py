"""Voxelise a scene: occupied (surface) voxels, the explorable free interior, and the outside.

Frames and units: world frame Z-up, metres. A :class:`VoxelGrid` of shape (X, Y, Z)
covers ``origin + [0, shape) * voxel_size``; voxel ``(i, j, k)`` spans
``origin + [i, i+1) * voxel_size`` on x (likewise y, z) and its centre is
``origin + (i + 0.5) * voxel_size``.

Three classes of voxels:

* **occupied**: voxels a scene triangle intersects (exact triangle/box overlap test,
  separating-axis theorem, vectorised in numpy: thin walls are closed, no holes).
* **explorable**: the free interior, the volume an exploration run must discover
  (Vox@k in docs/design.md is a fraction of it).
* **outside**: everything else (the outside of the building, the inside of walls and
  closed furniture); neither occupied nor explorable.

Which free voxels are explorable is ``voxels.explorable`` in configs/sim.yaml: ``reachable``
follows what the robot can reach and see (the building's envelope seen from above, the
free-space component with the most navigable floor or the scene spec's ``?seed=``, cut by its
``?bounds=``); ``enclosed``, the rule the published benchmark used, is described here. Both
are :mod:`frontiernet.scenes.explorable`'s (:func:`~frontiernet.scenes.explorable.explorable_space`).

Under ``enclosed`` the interior is found per horizontal slice, so scenes without a ceiling (the shared
house) and buildings with open doors to the outside still give a sensible volume: a
free voxel is *outside* when a flood fill from the grid's lateral border reaches it,
where the flood only passes voxels farther than ``gap_closing_m / 2`` (in-plane) from
occupied ones and is then grown back by that radius, so openings narrower than
``gap_closing_m`` (doors, windows) seal the inside. The largest 6-connected component
of the remaining free voxels is the explorable volume (this drops closed cabinets and
wall interiors). The grid's z-range is the scene's bounds: there is no free space
above the scene's top.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy import ndimage

from ..errors import InputError, positive_number
from ..scenes import Scene
from ..scenes.explorable import EXPLORABLE_RULES, explorable_space

if TYPE_CHECKING:
    from omegaconf import DictConfig


@dataclass
class VoxelGrid:
    """A voxelised scene (world frame, Z-up, metres).

    Attributes:
        origin: (3,) float64, world position (metres) of the corner of voxel (0, 0, 0).
        voxel_size: edge length of a voxel in metres.
        occupied: (X, Y, Z) bool, voxels intersected by the scene's surface.
        explorable: (X, Y, Z) bool, the free interior (disjoint from `occupied`).
        enclosed: (X, Y, Z) bool or None, every free voxel inside the building's walls
            (a superset of `explorable`: also wall interiors and closed cabinets); tells
            "inside an obstacle" from "outside the building".
        seed: (3,) int64 voxel index the ``reachable`` rule grew `explorable` from (a navigable
            floor voxel), or None.
        floor_layer: layer index of the surface under the seed's walkable floor (the storey the
            ``reachable`` rule counts), or None (no seed).
    """

    origin: np.ndarray
    voxel_size: float
    occupied: np.ndarray
    explorable: np.ndarray
    enclosed: np.ndarray | None = None
    seed: np.ndarray | None = None
    floor_layer: int | None = None

    def __post_init__(self) -> None:
        self.origin = np.asarray(self.origin, np.float64).reshape(3)
        self.voxel_size = float(self.voxel_size)
        if self.occupied.shape != self.explorable.shape or self.occupied.ndim != 3:
            raise ValueError(f"occupied {self.occupied.shape} and explorable {self.explorable.shape} "
                             "must be equal 3D shapes")

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(int(n) for n in self.occupied.shape)  # type: ignore[return-value]

    @property
    def outside(self) -> np.ndarray:
        """(X, Y, Z) bool, voxels neither occupied nor explorable."""
        return ~(self.occupied | self.explorable)

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) float64 world [min, max] corners of the grid, metres."""
        return np.stack([self.origin, self.origin + np.asarray(self.shape) * self.voxel_size])

    @property
    def num_occupied(self) -> int:
        return int(np.count_nonzero(self.occupied))

    @property
    def num_explorable(self) -> int:
        return int(np.count_nonzero(self.explorable))

    @property
    def explorable_volume_m3(self) -> float:
        """Explorable volume in cubic metres."""
        return self.num_explorable * self.voxel_size ** 3

    def world_to_index(self, points: np.ndarray) -> np.ndarray:
        """(..., 3) world points (metres) -> (..., 3) int64 voxel indices (may be out of range; -1 if not finite)."""
        scaled = (np.asarray(points, np.float64) - self.origin) / self.voxel_size
        scaled = np.where(np.isfinite(scaled), scaled, -1.0)
        return np.floor(np.clip(scaled, -2.0**62, 2.0**62)).astype(np.int64)

    def index_to_world(self, index: np.ndarray) -> np.ndarray:
        """(..., 3) integer voxel indices -> (..., 3) float64 world positions of the voxel centres."""
        return self.origin + (np.asarray(index, np.float64) + 0.5) * self.voxel_size

    def in_grid(self, index: np.ndarray) -> np.ndarray:
        """(..., 3) indices -> (...,) bool, inside the grid."""
        index = np.asarray(index)
        return np.all((index >= 0) & (index < np.asarray(self.shape)), axis=-1)

    def _lookup(self, array: np.ndarray, points: np.ndarray) -> np.ndarray:
        index = self.world_to_index(points)
        inside = self.in_grid(index)
        out = np.zeros(index.shape[:-1], bool)
        i = index[inside]
        out[inside] = array[i[:, 0], i[:, 1], i[:, 2]]
        return out

    def is_explorable(self, points: np.ndarray) -> np.ndarray:
        """(..., 3) world points (metres) -> (...,) bool, in an explorable voxel (False off the grid)."""
        return self._lookup(self.explorable, points)

    def is_enclosed(self, points: np.ndarray) -> np.ndarray:
        """(..., 3) world points -> (...,) bool, in a free voxel enclosed by the building (explorable or not)."""
        return self._lookup(self.explorable if self.enclosed is None else self.enclosed, points)

    def is_occupied(self, points: np.ndarray) -> np.ndarray:
        """(..., 3) world points (metres) -> (...,) bool, in an occupied voxel (False off the grid)."""
        return self._lookup(self.occupied, points)

    def layer(self, z: float) -> int:
        """Index of the voxel layer holding height `z` (world metres), clipped to the grid."""
        return int(np.clip((z - self.origin[2]) / self.voxel_size, 0, self.shape[2] - 1))

    def column_clearance(self, k: int, band: int) -> np.ndarray:
        """(X, Y) float64 in-plane distance (metres) from each column that is explorable over the
        layers ``k - band .. k + band`` to the nearest column that is not (0 on those)."""
        free = self.explorable[:, :, max(k - band, 0):k + band + 1].all(axis=2)
        return ndimage.distance_transform_edt(free) * self.voxel_size

    def explorable_centres(self) -> np.ndarray:
        """(N, 3) float64 world centres of the explorable voxels (metres)."""
        return self.index_to_world(np.argwhere(self.explorable))




def voxels_config(conf: "DictConfig") -> "DictConfig":
    """The ``voxels`` section from `conf` (a whole sim config or the section)."""
    return conf["voxels"] if "voxels" in conf else conf


def _positive(conf, key: str, *, allow_zero: bool = False) -> float:
    return positive_number(conf[key], f"voxels.{key}", "metres", allow_zero=allow_zero)


def voxelize_scene(scene: "Scene", conf: "DictConfig") -> VoxelGrid:
    """Voxelise `scene` into occupied / explorable / outside voxels (see module docstring).

    Args:
        scene: a :class:`~frontiernet.scenes.Scene` (world frame, Z-up, metres).
        conf: the ``voxels`` section of ``configs/sim.yaml`` (or the whole sim config), as
            the run resolved it.
    Returns:
        A :class:`VoxelGrid` whose lateral extent is the scene bounds plus
        ``lateral_margin_m`` and whose z-range is the scene bounds.
    Raises:
        InputError: non-positive ``voxel_size`` (or other bad values), a grid larger than
            ``max_voxels``, or a scene with no explorable interior.
    """
    conf = voxels_config(conf)
    size = _positive(conf, "voxel_size")
    margin = _positive(conf, "lateral_margin_m", allow_zero=True)
    bounds = scene.bounds
    origin = bounds[0] - np.array([margin, margin, 0.0])
    extent = bounds[1] + np.array([margin, margin, 0.0]) - origin
    cells = np.floor(extent / size) + 1  # closed upper bound: a top face gets a layer (float: a scene of 1e30 m
    count = math.prod(float(n) for n in cells)  # overflows int64, with numpy's warning, and NumPy's product wraps)
    if not count <= int(conf.max_voxels):  # (inf too)
        shown = ", ".join(f"{int(n)}" if n < 1e15 else f"{n:.3g}" for n in cells)
        voxels = f"{count:,.0f}" if count < 1e15 else f"{count:.3g}"
        bare = math.prod(float(n) for n in np.floor((bounds[1] - bounds[0]) / size) + 1)
        advice = (f"voxels.lateral_margin_m {margin:g} m a side is what makes it so large: use a smaller margin"
                  if bare <= int(conf.max_voxels) else "check its scale (metres), or use a larger voxel size")
        raise InputError(f"{scene.metadata.spec}: voxel_size {size} m gives a ({shown}) grid "
                         f"({voxels} voxels > voxels.max_voxels {int(conf.max_voxels):,}) for a scene of "
                         f"{' x '.join(f'{v:.4g}' for v in bounds[1] - bounds[0])} m and a margin of "
                         f"{margin:g} m a side; {advice}")
    shape = cells.astype(np.int64)
    rule = conf.explorable
    if rule not in EXPLORABLE_RULES:
        raise InputError(f"voxels.explorable must be one of {', '.join(EXPLORABLE_RULES)}, got {rule!r}")
    occupied = surface_voxels(scene.vertices, scene.triangles, origin, size, tuple(shape.tolist()),
                              chunk=int(conf.chunk_candidates))
    meta = scene.metadata
    space = explorable_space(occupied, origin, size, conf, seed=meta.explorable_seed, box=meta.explorable_bounds,
                             where=meta.spec)
    interior, explorable, seed = space.enclosed, space.explorable, space.seed
    if not explorable.any():
        raise InputError(f"{meta.spec}: the scene has no explorable free space at voxel size "
                         f"{size} m (rule {rule}: no {'building envelope' if rule == 'reachable' else 'enclosed interior'})")
    return VoxelGrid(origin=origin, voxel_size=size, occupied=occupied, explorable=explorable, enclosed=interior,
                     seed=seed, floor_layer=space.floor_layer)


# ----------------------------------------------------------------------------- surfaces


def _split_jobs(lo: np.ndarray, hi: np.ndarray, tri: np.ndarray, chunk: int):
    """Split (triangle, inclusive index box) jobs until each box holds <= `chunk` voxels."""
    while True:
        counts = np.prod(hi - lo + 1, axis=1)
        big = counts > chunk
        if not big.any():
            return lo, hi, tri, counts
        blo, bhi = lo[big], hi[big]
        axis = np.argmax(bhi - blo, axis=1)
        rows = np.arange(len(blo))
        mid = (blo[rows, axis] + bhi[rows, axis]) // 2
        hi_a, lo_b = bhi.copy(), blo.copy()
        hi_a[rows, axis] = mid
        lo_b[rows, axis] = mid + 1
        lo = np.concatenate([lo[~big], blo, lo_b])
        hi = np.concatenate([hi[~big], hi_a, bhi])
        tri = np.concatenate([tri[~big], tri[big], tri[big]])


def surface_voxels(vertices: np.ndarray, triangles: np.ndarray, origin: np.ndarray, voxel_size: float,
                   shape: tuple[int, int, int], chunk: int = 4_000_000) -> np.ndarray:
    """Voxels intersected by triangles (exact triangle/box overlap, separating-axis theorem).

    Args:
        vertices: (V, 3) metres; triangles: (T, 3) vertex indices.
        origin: (3,) world corner of voxel (0, 0, 0); voxel_size: metres; shape: (X, Y, Z).
        chunk: triangle/voxel candidate pairs tested per batch (bounds memory, ~200 B each).
    Returns:
        (X, Y, Z) bool. Voxels are half-open: a face lying exactly on a voxel boundary
        marks the voxel above it (larger index) only. Parts outside the grid are dropped.
    """
    v = (np.asarray(vertices, np.float64) - np.asarray(origin, np.float64)) / voxel_size  # voxel units
    tris = v[np.asarray(triangles, np.int64)]  # (T, 3, 3)
    grid_max = np.asarray(shape) - 1
    lo = np.clip(np.floor(tris.min(axis=1)), 0, grid_max).astype(np.int64)
    hi = np.clip(np.floor(tris.max(axis=1)), 0, grid_max).astype(np.int64)
    keep = np.all(tris.max(axis=1) >= 0, axis=1) & np.all(tris.min(axis=1) < np.asarray(shape), axis=1)
    tri_ids = np.flatnonzero(keep)
    occupied = np.zeros(shape, bool)
    if len(tri_ids) == 0:
        return occupied
    # Per-triangle separating axes: the plane normal and the 9 edge x box-axis crosses,
    # in a frame local to each triangle's lowest voxel (small numbers: float32 is exact enough).
    tlo = lo[tri_ids]
    t = tris[tri_ids] - tlo[:, None, :]
    edges = np.stack([t[:, 1] - t[:, 0], t[:, 2] - t[:, 1], t[:, 0] - t[:, 2]], axis=1)  # (T, 3, 3)
    zero = np.zeros_like(edges[..., 0])
    crosses = [np.stack([zero, edges[..., 2], -edges[..., 1]], -1),   # e x (1, 0, 0)
               np.stack([-edges[..., 2], zero, edges[..., 0]], -1),   # e x (0, 1, 0)
               np.stack([edges[..., 1], -edges[..., 0], zero], -1)]   # e x (0, 0, 1)
    normal = np.cross(edges[:, 0], -edges[:, 2])[:, None, :]  # (T, 1, 3)
    axes = np.concatenate([normal] + crosses, axis=1)  # (T, 10, 3)
    axes /= np.maximum(np.abs(axes).max(axis=2, keepdims=True), 1e-300)  # scale-free, exact zeros kept
    proj = np.einsum("tad,tvd->tav", axes, t)  # (T, 10, 3) vertex projections
    radius = 0.5 * np.abs(axes).sum(axis=2)  # box half-extent projected on each axis
    eps = 1e-6 * (1.0 + np.abs(proj).max(axis=2))  # float32 rounding; << a voxel
    low = (proj.min(axis=2) - radius - eps).astype(np.float32).T.copy()  # (10, T)
    high = (proj.max(axis=2) + radius + eps).astype(np.float32).T.copy()
    axis_xyz = [axes[:, :, d].astype(np.float32).T.copy() for d in range(3)]  # 3 x (10, T)

    tlo32 = tlo.astype(np.int32)
    job_lo, job_hi, job_tri, counts = _split_jobs(tlo, hi[tri_ids], np.arange(len(tri_ids)), chunk)
    # Batches of consecutive jobs of about `chunk` candidates (at most 2 * chunk).
    group = (np.cumsum(counts) - counts) // chunk
    bounds = np.flatnonzero(np.diff(group)) + 1
    for sl in (slice(a, b) for a, b in zip(np.r_[0, bounds], np.r_[bounds, len(counts)])):
        c = counts[sl]
        job = np.repeat(np.arange(len(c), dtype=np.int32), c)
        local = np.arange(int(c.sum()), dtype=np.int32) - np.repeat((np.cumsum(c) - c).astype(np.int32), c)
        dims = (job_hi[sl] - job_lo[sl] + 1).astype(np.int32)
        nz, nyz = dims[:, 2][job], (dims[:, 1] * dims[:, 2])[job]
        ix = local // nyz
        rest = local - ix * nyz
        iy = rest // nz
        lo_job = job_lo[sl].astype(np.int32)
        cols = [ix + lo_job[:, 0][job], iy + lo_job[:, 1][job], rest - iy * nz + lo_job[:, 2][job]]
        tri = job_tri[sl].astype(np.int32)[job]
        # local voxel-centre coordinates (small: exact in float32)
        centre = [(cols[d] - tlo32[:, d][tri]).astype(np.float32) + np.float32(0.5) for d in range(3)]
        hit = None
        for a in range(10):
            p = axis_xyz[0][a][tri] * centre[0] + axis_xyz[1][a][tri] * centre[1] + axis_xyz[2][a][tri] * centre[2]
            keep = (p >= low[a][tri]) & (p <= high[a][tri])
            hit = keep if hit is None else hit & keep
            if a in (0, 3, 6) and np.count_nonzero(hit) < 0.7 * len(hit):  # compact when it pays
                tri, cols, centre = tri[hit], [x[hit] for x in cols], [x[hit] for x in centre]
                hit = None
        if hit is not None:
            cols = [x[hit] for x in cols]
        occupied[cols[0], cols[1], cols[2]] = True
    return occupied


"""Exact point-to-mesh distance without Open3D: a bounding-volume hierarchy searched by numba.

Embree's Python binding (the ``embree`` ray-cast backend, :mod:`.raycast`) casts rays but
has no closest-point query, and no library on a torch-only GPU node answers one (trimesh
and Open3D are not there). This module is that query: triangles sorted along a Morton
curve, grouped ``LEAF_SIZE`` to a leaf, under an implicit complete binary tree of
axis-aligned boxes (node ``k``'s children are ``2k`` and ``2k + 1``; leaves are the last
level). A query descends nearer child first and skips every box farther than the best
triangle found so far, so the answer is the exact minimum over all triangles (Ericson,
*Real-Time Collision Detection*, 5.1.5, for the point-triangle distance), in float64.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

LEAF_SIZE = 4
"""Triangles per leaf: small leaves prune more; 4 is the usual BVH choice for triangles."""

_FLAT = 1e-12
"""A triangle with |ab x ac|^2 <= _FLAT |ab|^2 |ac|^2 (its corners within 1e-6 rad of a line) is
measured as its three edges: Ericson's region tests divide by its area."""

_MORTON_BITS = 10  # per axis: a 1024^3 grid over the scene's bounds orders the triangles


@dataclass(frozen=True)
class TriangleTree:
    """The hierarchy of :func:`build_triangle_tree`.

    Attributes:
        corners: (T, 3, 3) float64 triangle corners (metres), in tree order.
        boxes: (2 * L, 6) float32 node boxes ``[min xyz, max xyz]``, heap-indexed from 1 (L leaves, a
            power of 2; an empty leaf's box is inverted, +inf / -inf, and never visited). Rounded
            outwards from float64, so a box holds its triangles exactly; float32 and both corners in
            one row put two siblings in one 64-byte cache line (the search is memory-bound).
    """

    corners: np.ndarray
    boxes: np.ndarray

    @property
    def num_leaves(self) -> int:
        return len(self.boxes) // 2


def _spread_bits(values: np.ndarray) -> np.ndarray:
    """(N,) integers < 2^10 -> their bits moved to every third position (Morton interleave)."""
    v = values.astype(np.uint64)
    v = (v | (v << np.uint64(16))) & np.uint64(0x030000FF)
    v = (v | (v << np.uint64(8))) & np.uint64(0x0300F00F)
    v = (v | (v << np.uint64(4))) & np.uint64(0x030C30C3)
    return (v | (v << np.uint64(2))) & np.uint64(0x09249249)


def build_triangle_tree(vertices: np.ndarray, triangles: np.ndarray) -> TriangleTree:
    """The tree over (V, 3) vertices (metres) and (T, 3) integer triangles (T >= 1)."""
    corners = np.asarray(vertices, np.float64)[np.asarray(triangles, np.int64)]  # (T, 3, 3)
    centres = corners.mean(1)
    lower, upper = centres.min(0), centres.max(0)
    cells = ((centres - lower) / np.maximum(upper - lower, 1e-12) * (2 ** _MORTON_BITS - 1)).astype(np.int64)
    codes = _spread_bits(cells[:, 0]) | (_spread_bits(cells[:, 1]) << np.uint64(1)) | (
        _spread_bits(cells[:, 2]) << np.uint64(2))
    corners = np.ascontiguousarray(corners[np.argsort(codes, kind="stable")])
    used = -(-len(corners) // LEAF_SIZE)
    leaves = 1 << max(int(used - 1).bit_length(), 0)
    box_min = np.full((2 * leaves, 3), np.inf)
    box_max = np.full((2 * leaves, 3), -np.inf)
    starts = np.arange(0, len(corners), LEAF_SIZE)
    box_min[leaves:leaves + used] = np.minimum.reduceat(corners.min(1), starts)
    box_max[leaves:leaves + used] = np.maximum.reduceat(corners.max(1), starts)
    level = leaves
    while level > 1:  # parents of the level [level, 2 level) are [level / 2, level)
        parents = np.arange(level // 2, level)
        box_min[parents] = np.minimum(box_min[2 * parents], box_min[2 * parents + 1])
        box_max[parents] = np.maximum(box_max[2 * parents], box_max[2 * parents + 1])
        level //= 2
    with np.errstate(invalid="ignore"):  # outwards, so never tighter; the empty leaves' infinities stay
        lower = np.where(np.isinf(box_min), box_min, np.nextafter(box_min.astype(np.float32), -np.inf))
        upper = np.where(np.isinf(box_max), box_max, np.nextafter(box_max.astype(np.float32), np.inf))
    return TriangleTree(corners, np.ascontiguousarray(np.concatenate([lower, upper], 1), np.float32))


def distance_to_triangles(tree: TriangleTree, points: np.ndarray) -> np.ndarray:
    """(N,) float64 unsigned distance (metres) from (N, 3) points to the nearest triangle of `tree`."""
    points = np.ascontiguousarray(np.asarray(points, np.float64).reshape(-1, 3))
    squared = np.empty(len(points), np.float64)
    _nearest_squared(points, tree.corners, tree.boxes, tree.num_leaves, LEAF_SIZE, squared)
    return np.sqrt(squared)


@numba.njit(cache=True, inline="always")
def _box_squared(px, py, pz, box):  # pragma: no cover - compiled
    gx = max(box[0] - px, 0.0, px - box[3])
    gy = max(box[1] - py, 0.0, py - box[4])
    gz = max(box[2] - pz, 0.0, pz - box[5])
    return gx * gx + gy * gy + gz * gz


@numba.njit(cache=True, inline="always")
def _ratio(numerator, denominator):  # pragma: no cover - compiled
    """numerator / denominator on an edge, 0 where the edge has no length (degenerate triangle)."""
    return numerator / denominator if denominator > 0.0 else 0.0


@numba.njit(cache=True)
def _triangle_squared(px, py, pz, t):  # pragma: no cover - compiled
    """Squared distance from (px, py, pz) to the triangle of the (3, 3) corners `t` (Ericson 5.1.5:
    the closest point's Voronoi region from barycentric dot products; scalars, no allocation)."""
    ax, ay, az = t[0, 0], t[0, 1], t[0, 2]
    abx, aby, abz = t[1, 0] - ax, t[1, 1] - ay, t[1, 2] - az
    acx, acy, acz = t[2, 0] - ax, t[2, 1] - ay, t[2, 2] - az
    apx, apy, apz = px - ax, py - ay, pz - az
    nx, ny, nz = aby * acz - abz * acy, abz * acx - abx * acz, abx * acy - aby * acx
    ab2, ac2 = abx * abx + aby * aby + abz * abz, acx * acx + acy * acy + acz * acz
    if nx * nx + ny * ny + nz * nz <= _FLAT * ab2 * ac2:  # no area (a repeated corner, collinear corners):
        return min(_segment_squared(px, py, pz, t[0], t[1]), _segment_squared(px, py, pz, t[1], t[2]),
                   _segment_squared(px, py, pz, t[0], t[2]))  # the region tests below assume a real triangle
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    # the closest point is a + v ab + w ac
    if d1 <= 0.0 and d2 <= 0.0:
        v, w = 0.0, 0.0  # vertex a
    else:
        bpx, bpy, bpz = px - t[1, 0], py - t[1, 1], pz - t[1, 2]
        d3 = abx * bpx + aby * bpy + abz * bpz
        d4 = acx * bpx + acy * bpy + acz * bpz
        cpx, cpy, cpz = px - t[2, 0], py - t[2, 1], pz - t[2, 2]
        d5 = abx * cpx + aby * cpy + abz * cpz
        d6 = acx * cpx + acy * cpy + acz * cpz
        vc, vb, va = d1 * d4 - d3 * d2, d5 * d2 - d1 * d6, d3 * d6 - d5 * d4
        if d3 >= 0.0 and d4 <= d3:
            v, w = 1.0, 0.0  # vertex b
        elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
            v, w = _ratio(d1, d1 - d3), 0.0  # edge ab
        elif d6 >= 0.0 and d5 <= d6:
            v, w = 0.0, 1.0  # vertex c
        elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
            v, w = 0.0, _ratio(d2, d2 - d6)  # edge ac
        elif va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
            w = _ratio(d4 - d3, (d4 - d3) + (d5 - d6))  # edge bc
            v = 1.0 - w
        else:
            denom = va + vb + vc
            v, w = vb / denom, vc / denom  # inside the face
    dx = apx - v * abx - w * acx
    dy = apy - v * aby - w * acy
    dz = apz - v * abz - w * acz
    return dx * dx + dy * dy + dz * dz


@numba.njit(cache=True)
def _segment_squared(px, py, pz, a, b):  # pragma: no cover - compiled
    """Squared distance from (px, py, pz) to the segment between the (3,) points a and b."""
    dx, dy, dz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    length = dx * dx + dy * dy + dz * dz
    s = 0.0 if length <= 0.0 else min(max(((px - a[0]) * dx + (py - a[1]) * dy + (pz - a[2]) * dz) / length, 0.0), 1.0)
    ex, ey, ez = px - a[0] - s * dx, py - a[1] - s * dy, pz - a[2] - s * dz
    return ex * ex + ey * ey + ez * ez


@numba.njit(parallel=True, cache=True)
def _nearest_squared(points, corners, boxes, leaves, leaf_size, out):  # pragma: no cover - compiled
    num_triangles = corners.shape[0]
    depth = 1
    while (1 << depth) < 2 * leaves:
        depth += 1
    for i in numba.prange(points.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        best = np.inf
        stack = np.empty(2 * depth + 2, np.int64)  # nodes to visit, with their box's squared distance
        gaps = np.empty(2 * depth + 2, np.float64)
        stack[0], gaps[0], top = 1, 0.0, 1
        while top > 0:
            top -= 1
            node = stack[top]
            if gaps[top] >= best:  # the box is farther than the nearest triangle found so far
                continue
            if node >= leaves:
                first = (node - leaves) * leaf_size
                for t in range(first, min(first + leaf_size, num_triangles)):
                    best = min(best, _triangle_squared(px, py, pz, corners[t]))
                continue
            left = _box_squared(px, py, pz, boxes[2 * node])
            right = _box_squared(px, py, pz, boxes[2 * node + 1])
            near, far = (2 * node, 2 * node + 1) if left <= right else (2 * node + 1, 2 * node)
            stack[top], gaps[top] = far, max(left, right)  # the farther child waits below the nearer one
            stack[top + 1], gaps[top + 1] = near, min(left, right)
            top += 2
        out[i] = best

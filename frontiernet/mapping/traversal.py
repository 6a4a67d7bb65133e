"""Voxel traversal along camera rays (Amanatides & Woo), compiled with numba.

One traversal, three kernels, and the update that applies a frame's marks:

* :func:`mark_traversed`: mark the voxels rays pass through (the observed voxels V_in
  of a view, in ``datagen``);
* :func:`mark_depth_rays`: walk the rays of a depth image and mark the voxels passed
  and the voxels holding the end points (the per-frame update of the occupancy map);
* :func:`frustum_volume`: integrate the volume of selected voxels inside virtual
  cameras' frusta up to occlusion (a frontier's gain, the known volume seen from it);
* :func:`apply_marks`: one frame's log-odds update of the occupancy map from the voxels
  :func:`mark_depth_rays` marked.

Conventions: a *box* is a sub-grid of a voxel grid given by the world position of its
corner, ``box_origin`` (3,) float64 metres, and the voxel size in metres; box arrays are
(X, Y, Z) and voxel ``(i, j, k)`` spans ``box_origin + [i, i+1) * voxel_size`` on x
(likewise y, z). Rays are ``origin + t * direction`` with world directions of unit
camera-frame z (``R_world_cam @ ((u - cx) / fx, (v - cy) / fy, 1)``), so ``t`` is the
z-depth in metres and a ray ends at ``t_end`` (its hit, or the sensor's max range).
Rays stop where they leave the box.
"""

from __future__ import annotations

import numba
import numpy as np

_INF = np.inf
_ENTRY_NUDGE_M = 1e-6
"""Rays starting outside the box begin this far (z-depth, metres) past their entry point,
so that rounding never puts the first voxel outside the box."""


@numba.njit(inline="always")
def _axis_setup(position: float, direction: float, index: int):
    """Step sign, parameter of the first boundary crossing and parameter per voxel on one axis."""
    if direction > 0.0:
        return 1, (index + 1.0 - position) / direction, 1.0 / direction
    if direction < 0.0:
        return -1, (index - position) / direction, -1.0 / direction
    return 0, _INF, _INF


@numba.njit(inline="always")
def _start(px, py, pz, dx, dy, dz):
    """Traversal state for a ray from (px, py, pz) along (dx, dy, dz), both in voxel units:
    (voxel index, step sign, next crossing parameter, parameter per voxel) per axis."""
    ix, iy, iz = int(np.floor(px)), int(np.floor(py)), int(np.floor(pz))
    sx, tx, ddx = _axis_setup(px, dx, ix)
    sy, ty, ddy = _axis_setup(py, dy, iy)
    sz, tz, ddz = _axis_setup(pz, dz, iz)
    return ix, iy, iz, sx, sy, sz, tx, ty, tz, ddx, ddy, ddz


@numba.njit(inline="always")
def _advance(ix, iy, iz, sx, sy, sz, tx, ty, tz, ddx, ddy, ddz):
    """Step into the next voxel across the nearest boundary; returns the new index and crossings."""
    if tx <= ty and tx <= tz:
        return ix + sx, iy, iz, tx + ddx, ty, tz
    if ty <= tz:
        return ix, iy + sy, iz, tx, ty + ddy, tz
    return ix, iy, iz + sz, tx, ty, tz + ddz


@numba.njit(inline="always")
def _inside(ix, iy, iz, shape):
    return 0 <= ix < shape[0] and 0 <= iy < shape[1] and 0 <= iz < shape[2]


@numba.njit(inline="always")
def _walk(px, py, pz, dx, dy, dz, end, end_is_hit, passed, ends):
    """Walk one ray (voxel units, see :func:`_start`) up to parameter `end`.

    Every voxel before the one holding the end point is set in `passed`; the end
    voxel is set in `ends` when `end_is_hit`, else in `passed`. Stops at the box border.
    Writers only ever store True, so rays may run in parallel.
    """
    ix, iy, iz, sx, sy, sz, tx, ty, tz, ddx, ddy, ddz = _start(px, py, pz, dx, dy, dz)
    shape = passed.shape
    while _inside(ix, iy, iz, shape):
        if min(tx, ty, tz) >= end:
            if end_is_hit:
                ends[ix, iy, iz] = True
            else:
                passed[ix, iy, iz] = True
            return
        passed[ix, iy, iz] = True
        ix, iy, iz, tx, ty, tz = _advance(ix, iy, iz, sx, sy, sz, tx, ty, tz, ddx, ddy, ddz)


@numba.njit(inline="always")
def _slab(position, direction, size, t_in, t_out):
    """(t_in, t_out) narrowed to where a ray (voxel units) is within [0, size) on one axis."""
    if direction == 0.0:
        if position < 0.0 or position >= size:
            return _INF, -_INF
        return t_in, t_out
    a, b = -position / direction, (size - position) / direction
    return max(t_in, min(a, b)), min(t_out, max(a, b))


@numba.njit(inline="always")
def _box_entry(px, py, pz, dx, dy, dz, shape):
    """Parameters (t_in, t_out) where a ray (voxel units) enters and leaves the box [0, shape)."""
    t_in, t_out = _slab(px, dx, shape[0], -_INF, _INF)
    t_in, t_out = _slab(py, dy, shape[1], t_in, t_out)
    return _slab(pz, dz, shape[2], t_in, t_out)


@numba.njit(cache=True, parallel=True)
def mark_traversed(origin, directions, t_end, box_origin, voxel_size, traversed):  # pragma: no cover
    """Set ``traversed[i, j, k] = True`` for every voxel of the box a ray passes through.

    Args:
        origin: (3,) float64 world ray origin (the camera centre, inside the box), metres.
        directions: (N, 3) float32 world directions (unit camera z).
        t_end: (N,) float32 ray ends (z-depth, metres); rays with t_end <= 0 are skipped.
        box_origin: (3,) float64 world corner of the box; voxel_size metres.
        traversed: (X, Y, Z) bool box array, updated in place.
    """
    px = (origin[0] - box_origin[0]) / voxel_size
    py = (origin[1] - box_origin[1]) / voxel_size
    pz = (origin[2] - box_origin[2]) / voxel_size
    for r in numba.prange(directions.shape[0]):
        end = t_end[r]
        if not end > 0.0:
            continue
        _walk(px, py, pz, directions[r, 0] / voxel_size, directions[r, 1] / voxel_size,
              directions[r, 2] / voxel_size, end, True, traversed, traversed)


@numba.njit(cache=True, parallel=True)
def mark_depth_rays(depth, fx, fy, cx, cy, stride, rotation, origin, max_range, invalid_is_free,
                    box_origin, voxel_size, passed, hit, skip, hit_range, free_fraction, far):  # pragma: no cover
    """Walk the ray of every `stride`-th pixel of a depth image; mark voxels passed and hit.

    A pixel with depth in (0, hit_range] ends in a hit: its end voxel is set in `hit`,
    the voxels before it in `passed`. Depth in (hit_range, max_range] is free up to one voxel
    (in z) before it, with no hit (a surface too far to place, but nothing nearer). Depth beyond
    `max_range` (+inf included) is free up to `max_range`, with no hit; invalid depth (NaN,
    <= 0) likewise when `invalid_is_free`, else the pixel is skipped. A ray without a hit is
    free only up to `free_fraction` of its finite depth (1: as above): an uncertain depth
    may lie beyond its surface. With a `far` array (not (0, 0, 0)), depth in (hit_range,
    max_range] ends in a weak hit instead: its end voxel is set in `far`, the voxels before it
    in `passed`. Pixels set in `skip` are
    skipped whatever their depth. The camera may lie outside the box: rays then start where they
    enter it.

    Args:
        depth: (H, W) float32 z-depth, metres.
        fx, fy, cx, cy: intrinsics, pixels (pixel centres at integer coordinates).
        stride: pixels (rows and columns 0, stride, 2 * stride, ...).
        rotation: (3, 3) float64 ``R_world_cam``; origin: (3,) float64 world camera centre.
        max_range: metres (z-depth); invalid_is_free: bool; hit_range: metres (z-depth), <=
            max_range (equal: every depth in range is a hit); free_fraction: in (0, 1].
        box_origin: (3,) float64 world corner of the box; voxel_size: metres.
        passed, hit: (X, Y, Z) bool box arrays, updated in place (set only, never cleared).
        skip: (H, W) bool pixels not integrated, or a (0, 0) array for none.
    """
    H, W = depth.shape
    any_skip = skip.shape[0] > 0
    weak_far = far.shape[0] > 0
    shape = passed.shape
    px = (origin[0] - box_origin[0]) / voxel_size
    py = (origin[1] - box_origin[1]) / voxel_size
    pz = (origin[2] - box_origin[2]) / voxel_size
    for row in numba.prange((H + stride - 1) // stride):
        v = row * stride
        ry = (v - cy) / fy
        for u in range(0, W, stride):
            if any_skip and skip[v, u]:
                continue
            z = depth[v, u]
            is_hit = 0.0 < z <= hit_range
            is_far = weak_far and hit_range < z <= max_range
            if is_hit or is_far:
                end = z
            elif z <= max_range and z > 0.0:  # beyond hit_range: free short of the surface
                end = z - voxel_size
            elif z > max_range or invalid_is_free:
                end = max_range
            else:
                continue
            if not (is_hit or is_far) and free_fraction < 1.0 and 0.0 < z < np.inf:
                end = min(end, free_fraction * z)
            rx = (u - cx) / fx
            dx = (rotation[0, 0] * rx + rotation[0, 1] * ry + rotation[0, 2]) / voxel_size
            dy = (rotation[1, 0] * rx + rotation[1, 1] * ry + rotation[1, 2]) / voxel_size
            dz = (rotation[2, 0] * rx + rotation[2, 1] * ry + rotation[2, 2]) / voxel_size
            t_in, t_out = _box_entry(px, py, pz, dx, dy, dz, shape)
            if t_out <= max(t_in, 0.0) or t_in >= end:
                continue
            shift = max(t_in + _ENTRY_NUDGE_M, 0.0)
            _walk(px + shift * dx, py + shift * dy, pz + shift * dz, dx, dy, dz, end - shift, is_hit or is_far,
                  passed, far if is_far else hit)


@numba.njit(cache=True, parallel=True)
def frustum_volume(origins, rotations, camera_directions, max_depth, focal_px, box_origin,
                   voxel_size, passable, counted, volumes):  # pragma: no cover
    """Volume (m^3) of the `counted` voxels each virtual camera sees, integrated along its rays.

    Each ray stands for one pixel of a pinhole camera with focal length `focal_px`; a
    pixel's footprint at depth z is (z / f)^2, so a ray segment [z0, z1] inside a
    counted voxel adds (z1^3 - z0^3) / (3 f^2) cubic metres. A ray continues while its
    voxel is `passable` and stops at the first one that is not (it is not counted
    either), at the box border or at `max_depth`. Summed over the pixels this is the
    frustum's counted volume up to occlusion, independent of the ray resolution.

    Args:
        origins: (V, 3) float64 world camera centres, metres (inside the box, else 0).
        rotations: (V, 3, 3) float64 ``R_world_cam``.
        camera_directions: (R, 3) float64 camera-frame directions with unit z.
        max_depth: metres (z-depth); focal_px: the virtual camera's focal length, pixels.
        box_origin: (3,) float64 world corner of the box; voxel_size: metres.
        passable: (X, Y, Z) bool box array, voxels rays pass through.
        counted: (X, Y, Z) bool box array, voxels whose volume is summed.
        volumes: (V,) float64, written.
    """
    shape = passable.shape
    scale = 1.0 / (3.0 * focal_px * focal_px)
    for v in numba.prange(origins.shape[0]):
        px = (origins[v, 0] - box_origin[0]) / voxel_size
        py = (origins[v, 1] - box_origin[1]) / voxel_size
        pz = (origins[v, 2] - box_origin[2]) / voxel_size
        total = 0.0
        for r in range(camera_directions.shape[0]):
            cx, cy, cz = camera_directions[r, 0], camera_directions[r, 1], camera_directions[r, 2]
            dx = (rotations[v, 0, 0] * cx + rotations[v, 0, 1] * cy + rotations[v, 0, 2] * cz) / voxel_size
            dy = (rotations[v, 1, 0] * cx + rotations[v, 1, 1] * cy + rotations[v, 1, 2] * cz) / voxel_size
            dz = (rotations[v, 2, 0] * cx + rotations[v, 2, 1] * cy + rotations[v, 2, 2] * cz) / voxel_size
            ix, iy, iz, sx, sy, sz, tx, ty, tz, ddx, ddy, ddz = _start(px, py, pz, dx, dy, dz)
            t = 0.0
            while _inside(ix, iy, iz, shape) and passable[ix, iy, iz]:
                t_next = min(tx, ty, tz, max_depth)
                if counted[ix, iy, iz]:
                    total += t_next * t_next * t_next - t * t * t
                if t_next >= max_depth:
                    break
                t = t_next
                ix, iy, iz, tx, ty, tz = _advance(ix, iy, iz, sx, sy, sz, tx, ty, tz, ddx, ddy, ddz)
        volumes[v] = total * scale


@numba.njit(cache=True, parallel=True)
def apply_marks(log_odds, observed, lo, passed, hit, l_hit, l_miss, l_min, l_max, far, l_far_max):  # pragma: no cover
    """One frame's update over a box at offset `lo` (3,) int64 of the (X, Y, Z) map arrays:
    `hit` voxels get `l_hit`, other `passed` ones `l_miss`, clamped to [l_min, l_max]
    (float32 log-odds); other `far` voxels (a (0, 0, 0) array: none) get `l_hit` but rise no
    higher than `l_far_max` (weak hits), and passed wins over them. Returns the number of voxels
    observed for the first time."""
    newly = 0
    any_far = far.shape[0] > 0
    for i in numba.prange(passed.shape[0]):
        gi = lo[0] + i
        for j in range(passed.shape[1]):
            gj = lo[1] + j
            for k in range(passed.shape[2]):
                gk = lo[2] + k
                if hit[i, j, k]:
                    delta = l_hit
                elif passed[i, j, k]:
                    delta = l_miss
                elif any_far and far[i, j, k]:
                    value = log_odds[gi, gj, gk]
                    if value < l_far_max:
                        log_odds[gi, gj, gk] = min(value + l_hit, l_far_max)
                    if not observed[gi, gj, gk]:
                        observed[gi, gj, gk] = True
                        newly += 1
                    continue
                else:
                    continue
                log_odds[gi, gj, gk] = min(max(log_odds[gi, gj, gk] + delta, l_min), l_max)
                if not observed[gi, gj, gk]:
                    observed[gi, gj, gk] = True
                    newly += 1
    return newly

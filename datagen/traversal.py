"""Voxel traversal along camera rays (Amanatides & Woo), compiled with numba.

Two kernels share one traversal: mark the voxels rays pass through (V_in), and
integrate the unobserved free volume inside a virtual camera's frustum (the gain of a
frontier voxel). A third finds the frontier voxels near each pixel's ray (F_p and the
per-pixel gain).

Conventions: a *box* is a sub-grid of a :class:`~frontiernet.simulator.voxels.VoxelGrid`
given by the world position of its corner, ``box_origin`` (3,) metres, and the voxel
size; box arrays are (X, Y, Z). Rays are ``origin + t * direction`` with directions of
unit camera-frame z (``((u - cx) / fx, (v - cy) / fy, 1)`` rotated into the world), so
``t`` is the z-depth in metres and a ray ends at ``t_end`` (its hit, or the sensor's
max range).
"""

from __future__ import annotations

import numba
import numpy as np

_INF = np.inf


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


@numba.njit(cache=True, parallel=True)
def mark_traversed(origin, directions, t_end, box_origin, voxel_size, traversed):  # pragma: no cover
    """Set ``traversed[i, j, k] = True`` for every voxel of the box a ray passes through.

    Args:
        origin: (3,) float64 world ray origin (the camera centre), metres.
        directions: (N, 3) float32 world directions (unit camera z).
        t_end: (N,) float32 ray ends (z-depth, metres); rays with t_end <= 0 are skipped.
        box_origin: (3,) float64 world corner of the box; voxel_size metres.
        traversed: (X, Y, Z) bool box array, updated in place.
    """
    shape = traversed.shape
    px = (origin[0] - box_origin[0]) / voxel_size
    py = (origin[1] - box_origin[1]) / voxel_size
    pz = (origin[2] - box_origin[2]) / voxel_size
    for r in numba.prange(directions.shape[0]):
        end = t_end[r]
        if not end > 0.0:
            continue
        dx = directions[r, 0] / voxel_size
        dy = directions[r, 1] / voxel_size
        dz = directions[r, 2] / voxel_size
        ix, iy, iz, sx, sy, sz, tx, ty, tz, ddx, ddy, ddz = _start(px, py, pz, dx, dy, dz)
        while _inside(ix, iy, iz, shape):
            traversed[ix, iy, iz] = True  # benign race: every writer stores True
            if min(tx, ty, tz) >= end:
                break
            ix, iy, iz, tx, ty, tz = _advance(ix, iy, iz, sx, sy, sz, tx, ty, tz, ddx, ddy, ddz)


@numba.njit(cache=True)
def max_gain_near_rays(centres_cam, gains, t_end, fx, fy, cx, cy, t_near, r_ray, out):  # pragma: no cover
    """``out[v, u]`` = largest gain of the frontier voxels within `r_ray` of pixel (u, v)'s ray.

    A pixel's *visible segment* runs from depth `t_near` (a near clipping plane: points
    around the camera centre are close to every ray) to its end ``t_end[v, u]``; a voxel
    counts when its centre lies within `r_ray` metres of that segment (per-pixel ray
    casting, as the paper does). The loop runs over voxels: each tests the pixels inside
    the image bounding box of its r_ray-sphere, which visits far fewer pixels than
    traversing every pixel's ray through the voxel grid.

    Args:
        centres_cam: (M, 3) float64 frontier voxel centres in the camera frame, metres.
        gains: (M,) float64 their gains (>= 0).
        t_end: (H, W) float32 ray ends (z-depth, metres).
        fx, fy, cx, cy: intrinsics, pixels. t_near, r_ray: metres.
        out: (H, W) float32, updated in place (initialise to -1: no frontier near).
    """
    H, W = t_end.shape
    r2 = r_ray * r_ray
    for m in range(centres_cam.shape[0]):
        x, y, z = centres_cam[m, 0], centres_cam[m, 1], centres_cam[m, 2]
        if z + r_ray < t_near:
            continue  # every visible point has depth >= t_near, farther than r_ray from here
        near_z = max(z - r_ray, t_near)
        far_z = z + r_ray
        u0 = cx + fx * min((x - r_ray) / near_z, (x - r_ray) / far_z)
        u1 = cx + fx * max((x + r_ray) / near_z, (x + r_ray) / far_z)
        v0 = cy + fy * min((y - r_ray) / near_z, (y - r_ray) / far_z)
        v1 = cy + fy * max((y + r_ray) / near_z, (y + r_ray) / far_z)
        g = gains[m]
        for v in range(max(int(np.ceil(v0)), 0), min(int(np.floor(v1)), H - 1) + 1):
            dy = (v - cy) / fy
            for u in range(max(int(np.ceil(u0)), 0), min(int(np.floor(u1)), W - 1) + 1):
                if out[v, u] >= g:
                    continue
                dx = (u - cx) / fx
                t = (x * dx + y * dy + z) / (dx * dx + dy * dy + 1.0)
                t = min(max(t, t_near), t_end[v, u])
                ex, ey, ez = x - t * dx, y - t * dy, z - t
                if ex * ex + ey * ey + ez * ez <= r2:
                    out[v, u] = g


@numba.njit(cache=True, parallel=True)
def frustum_unobserved_volume(origins, rotations, camera_directions, max_depth, focal_px, box_origin,
                              voxel_size, free, observed, volumes):  # pragma: no cover
    """Unobserved free volume (m^3) each virtual camera sees, integrated along its rays.

    Each ray stands for one pixel of a pinhole camera with focal length `focal_px`; a
    pixel's footprint at depth z is (z / f)^2, so a ray segment [z0, z1] inside an
    unobserved free voxel adds (z1^3 - z0^3) / (3 f^2) cubic metres. A ray stops at the
    first voxel that is not free (a surface, a wall interior, outside the building) or
    at `max_depth`. Summed over the pixels this is the frustum's unobserved free volume
    up to occlusion, independent of the ray resolution (no voxel is counted twice).

    Args:
        origins: (V, 3) float64 world camera centres, metres.
        rotations: (V, 3, 3) float64 ``R_world_cam``.
        camera_directions: (R, 3) float64 camera-frame directions with unit z.
        max_depth: metres (z-depth); focal_px: the virtual camera's focal length, pixels.
        free: (X, Y, Z) bool box array, explorable voxels.
        observed: (X, Y, Z) bool box array, V_in.
        volumes: (V,) float64, written.
    """
    shape = free.shape
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
            while _inside(ix, iy, iz, shape) and free[ix, iy, iz]:
                t_next = min(tx, ty, tz, max_depth)
                if not observed[ix, iy, iz]:
                    total += t_next * t_next * t_next - t * t * t
                if t_next >= max_depth:
                    break
                t = t_next
                ix, iy, iz, tx, ty, tz = _advance(ix, iy, iz, sx, sy, sz, tx, ty, tz, ddx, ddy, ddz)
        volumes[v] = total * scale

"""Frontier voxels near each pixel's ray (F_p and the per-pixel gain), compiled with numba.

The voxel traversals of the ground truth (V_in, a frontier's gain) live in the library,
:mod:`frontiernet.mapping.traversal`, shared with the occupancy map.
"""

from __future__ import annotations

import numba
import numpy as np


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

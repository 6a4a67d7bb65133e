"""One Open3D ``RaycastingScene`` per :class:`~frontiernet.scenes.Scene`, built once.

All ray queries of a scene (camera rendering, voxel classification, collision
distance) share it: the BVH build is the expensive part.
"""

from __future__ import annotations

import weakref

import numpy as np
import open3d as o3d

from ..scenes import Scene

_CACHE: "weakref.WeakKeyDictionary[Scene, o3d.t.geometry.RaycastingScene]" = weakref.WeakKeyDictionary()


def raycasting_scene(scene: Scene) -> o3d.t.geometry.RaycastingScene:
    """The scene's ``RaycastingScene`` (one geometry, id 0; primitive ids = triangle indices)."""
    cached = _CACHE.get(scene)
    if cached is None:
        cached = o3d.t.geometry.RaycastingScene()
        cached.add_triangles(o3d.core.Tensor(scene.vertices), o3d.core.Tensor(scene.triangles.astype(np.uint32)))
        _CACHE[scene] = cached
    return cached


def cast_rays(scene: Scene, rays: np.ndarray) -> dict[str, np.ndarray]:
    """Cast (..., 6) float32 rays ``[origin xyz, direction xyz]`` (world frame, metres).

    Returns numpy views of Open3D's answer: ``t_hit`` (...,) float32 in units of the
    direction's length (inf = no hit), ``primitive_ids`` (...,) uint32 triangle index
    (``INVALID_ID`` = no hit), ``primitive_uvs`` (..., 2) barycentrics of corners 1 and 2,
    ``primitive_normals`` (..., 3) unit face normals (winding order, not oriented).
    """
    rays = np.ascontiguousarray(rays, np.float32)
    answer = raycasting_scene(scene).cast_rays(o3d.core.Tensor.from_numpy(rays))
    return {key: value.numpy() for key, value in answer.items()}


def distance_to_surface(scene: Scene, points: np.ndarray) -> np.ndarray:
    """(N,) float32 unsigned distance (metres) from (N, 3) points to the nearest triangle."""
    query = o3d.core.Tensor(np.ascontiguousarray(points, np.float32).reshape(-1, 3))
    return raycasting_scene(scene).compute_distance(query).numpy()


INVALID_ID = o3d.t.geometry.RaycastingScene.INVALID_ID

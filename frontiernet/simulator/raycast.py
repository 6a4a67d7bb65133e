"""Ray queries against a :class:`~frontiernet.scenes.Scene`: one interface, two engines.

* ``open3d``: Open3D's ``RaycastingScene`` (Embree inside; a wheel of hundreds of MB).
* ``embree``: Intel Embree 4 through ``embreex`` (the binding trimesh uses, a ~15 MB wheel),
  for machines without Open3D (typical GPU nodes). It has no closest-point query, so its
  :meth:`RayCaster.distance_to_surface` is the exact search of :mod:`.closest_point`.

Both answer :func:`cast_rays` with the same arrays (float32 rays, robust Embree
traversal in both; on 200 views of the shared house the hit masks agree on every pixel,
the hit distances within 0.004 mm, and the triangle ids except where two triangles lie
in one plane, docs/datagen.md). The engine is chosen by
``raycast.backend`` of ``configs/sim.yaml``: ``auto`` takes Open3D when it can be
imported, else Embree. A process selects its config's engine with :func:`select_backend`
before it casts (:func:`~frontiernet.simulator.world.build_world` does); casting with none
selected is a programming error.

All ray queries of a scene (camera rendering, pose checks, collision distance) share one
engine per scene, built once: the BVH build is the expensive part.
"""

from __future__ import annotations

import importlib
import math
import os
import weakref
from abc import ABC, abstractmethod
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np

from ..errors import InputError
from ..scenes import Scene

BACKENDS = ("open3d", "embree")
"""Ray-cast engines, in the order ``auto`` tries them."""

_MODULES = {"open3d": "open3d", "embree": "embreex"}  # backend -> the module it needs
_INSTALL = {"open3d": "pip install 'open3d>=0.19,<0.20'", "embree": "pip install embreex"}

INVALID_ID = np.uint32(0xFFFFFFFF)
"""``primitive_ids`` of a ray that hits nothing (Open3D's ``RaycastingScene.INVALID_ID``)."""

MIN_RAYS_PER_THREAD = 4096
"""Embree casts are split over threads only in chunks of at least this many rays: such a chunk
takes ~1 ms (0.25 us a ray on the shared house), far above a thread pool's hand-off (tens of us);
pose checks and collision queries cast fewer and stay on the calling thread."""


class RayCaster(ABC):
    """One scene's ray-cast engine (built once per scene and backend by :func:`ray_caster`)."""

    name: str

    @abstractmethod
    def cast_rays(self, rays: np.ndarray) -> dict[str, np.ndarray]:
        """(N, 6) float32 rays -> the answer of :func:`cast_rays` for them (each array N rows)."""

    @abstractmethod
    def distance_to_surface(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) float32 points -> (N,) float32 unsigned distance (metres) to the nearest triangle."""


class Open3DRayCaster(RayCaster):
    """Open3D's ``RaycastingScene``: one geometry, id 0; primitive ids = triangle indices."""

    name = "open3d"

    def __init__(self, scene: Scene) -> None:
        import open3d as o3d

        self._o3d = o3d
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(o3d.core.Tensor(scene.vertices), o3d.core.Tensor(scene.triangles.astype(np.uint32)))
        self.cast_rays(np.zeros((1, 6), np.float32))  # builds the BVH now (Open3D builds on first use)

    def cast_rays(self, rays: np.ndarray) -> dict[str, np.ndarray]:
        answer = self.scene.cast_rays(self._o3d.core.Tensor.from_numpy(rays))
        return {key: answer[key].numpy() for key in ("t_hit", "primitive_ids", "primitive_uvs", "primitive_normals")}

    def distance_to_surface(self, points: np.ndarray) -> np.ndarray:
        return self.scene.compute_distance(self._o3d.core.Tensor(points)).numpy()


class EmbreeRayCaster(RayCaster):
    """Embree 4 through ``embreex``: a robust scene (watertight traversal, as Open3D builds it);
    casts split over ``numba.get_num_threads()`` threads (embreex releases the GIL), so a datagen
    worker's thread share applies to it as to the numba kernels."""

    name = "embree"

    def __init__(self, scene: Scene) -> None:
        from embreex import mesh_construction, rtcore_scene

        from .closest_point import build_triangle_tree

        self.scene = rtcore_scene.EmbreeScene()
        mesh_construction.TriangleMesh(self.scene, np.ascontiguousarray(scene.vertices, np.float32),
                                       np.ascontiguousarray(scene.triangles, np.int32))
        self._cast(np.zeros((1, 6), np.float32), np.empty(1, np.float32))  # builds the BVH now (on first use else)
        self._vertices, self._triangles = scene.vertices, scene.triangles
        self._tree = None
        self._build_tree = build_triangle_tree

    def _cast(self, rays: np.ndarray, t_hit: np.ndarray) -> dict:
        """embreex's answer for (n, 6) rays; writes the hit distances into `t_hit` (n,) float32."""
        t_hit.fill(np.inf)  # Open3D's tfar (embreex's default is 1e37); a miss keeps it
        return self.scene.run(np.ascontiguousarray(rays[:, :3]), np.ascontiguousarray(rays[:, 3:]), dists=t_hit,
                              output=1)

    def cast_rays(self, rays: np.ndarray) -> dict[str, np.ndarray]:
        n = len(rays)
        answer = {"t_hit": np.empty(n, np.float32), "primitive_ids": np.empty(n, np.uint32),
                  "primitive_uvs": np.empty((n, 2), np.float32), "primitive_normals": np.empty((n, 3), np.float32)}

        def cast(chunk: slice) -> None:
            found = self._cast(rays[chunk], answer["t_hit"][chunk])
            _open3d_layout(found["primID"], found["u"], found["v"], found["Ng"], answer["primitive_ids"][chunk],
                           answer["primitive_uvs"][chunk], answer["primitive_normals"][chunk])

        chunks = max(1, min(numba.get_num_threads(), n // MIN_RAYS_PER_THREAD))
        step = math.ceil(n / chunks) if n else 1
        parts = [slice(i, min(i + step, n)) for i in range(0, n, step)]
        if len(parts) == 1:
            cast(parts[0])
        else:
            list(_thread_pool().map(cast, parts))
        return answer

    def distance_to_surface(self, points: np.ndarray) -> np.ndarray:
        from .closest_point import distance_to_triangles

        if self._tree is None:  # built on the first query: rendering alone never needs it
            self._tree = self._build_tree(self._vertices, self._triangles)
        return distance_to_triangles(self._tree, points).astype(np.float32)


@numba.njit(nogil=True, cache=True)
def _open3d_layout(prim, u, v, normal, ids, uvs, normals):  # pragma: no cover - compiled
    """embreex's per-ray answer as Open3D gives it: uint32 ids (a miss: INVALID_ID), barycentrics and
    unit geometric normals ((v1 - v0) x (v2 - v0), as Open3D's), 0 where nothing is hit (embreex
    leaves the previous ray's values there)."""
    for i in range(prim.shape[0]):
        if prim[i] < 0:
            ids[i] = 0xFFFFFFFF
            uvs[i, 0] = uvs[i, 1] = 0.0
            normals[i, 0] = normals[i, 1] = normals[i, 2] = 0.0
            continue
        ids[i] = prim[i]
        uvs[i, 0], uvs[i, 1] = u[i], v[i]
        length = np.sqrt(normal[i, 0] ** 2 + normal[i, 1] ** 2 + normal[i, 2] ** 2)
        scale = 1.0 / length if length > 0 else 0.0
        for c in range(3):
            normals[i, c] = normal[i, c] * scale


_ENGINES = {"open3d": Open3DRayCaster, "embree": EmbreeRayCaster}
_CACHE: "weakref.WeakKeyDictionary[Scene, dict[str, RayCaster]]" = weakref.WeakKeyDictionary()
_SELECTED: list[str] = []  # this process's backend once chosen by select_backend
_POOL: list[ThreadPoolExecutor] = []
os.register_at_fork(after_in_child=_POOL.clear)  # a forked child has none of the parent's threads


def _thread_pool() -> ThreadPoolExecutor:
    if not _POOL:
        _POOL.append(ThreadPoolExecutor(max_workers=os.cpu_count() or 1, thread_name_prefix="embree"))
    return _POOL[0]


def _importable(backend: str) -> bool:
    try:
        importlib.import_module(_MODULES[backend])
    except (ImportError, OSError):  # absent, or a shared library it links is missing
        return False
    return True


def resolve_backend(name: str) -> str:
    """``open3d`` or ``embree`` for a ``raycast.backend`` value (``auto``: the first importable).

    Raises:
        InputError: an unknown name, or an engine that cannot be imported here.
    """
    name = str(name)
    if name == "auto":
        for backend in BACKENDS:
            if _importable(backend):
                return backend
        raise InputError("raycast.backend=auto: neither open3d nor embreex can be imported; "
                         f"install one ({_INSTALL['embree']}, the smaller)")
    if name not in BACKENDS:
        raise InputError(f"raycast.backend '{name}' is unknown; valid: auto, {', '.join(BACKENDS)}")
    if not _importable(name):
        raise InputError(f"raycast.backend={name}: {_MODULES[name]} cannot be imported here ({_INSTALL[name]}, "
                         "or choose raycast.backend=auto)")
    return name


def select_backend(name: str) -> str:
    """Make `name` (a ``raycast.backend`` value) this process's engine; returns the resolved name."""
    backend = resolve_backend(name)
    _SELECTED[:] = [backend]
    return backend


def active_backend() -> str:
    """This process's engine, the one :func:`select_backend` chose.

    Raises:
        RuntimeError: none was selected (the caller forgot its config's ``raycast.backend``).
    """
    if not _SELECTED:
        raise RuntimeError("no ray-cast engine selected in this process: call select_backend(sim.raycast.backend) "
                           "first (build_world does)")
    return _SELECTED[0]


def ray_caster(scene: Scene, backend: str | None = None) -> RayCaster:
    """The scene's engine of `backend` (``open3d``, ``embree``, ``auto``; None: :func:`active_backend`),
    built on first use and kept as long as the scene lives."""
    backend = active_backend() if backend is None else resolve_backend(backend)
    engines = _CACHE.setdefault(scene, {})
    if backend not in engines:
        engines[backend] = _ENGINES[backend](scene)
    return engines[backend]


def cast_rays(scene: Scene, rays: np.ndarray, backend: str | None = None) -> dict[str, np.ndarray]:
    """Cast (..., 6) float32 rays ``[origin xyz, direction xyz]`` (world frame, metres).

    Returns ``t_hit`` (...,) float32 in units of the direction's length (inf = no hit),
    ``primitive_ids`` (...,) uint32 triangle index (:data:`INVALID_ID` = no hit),
    ``primitive_uvs`` (..., 2) barycentrics of corners 1 and 2, ``primitive_normals`` (..., 3)
    unit face normals (winding order, not oriented); uvs and normals are 0 where nothing is hit.
    `backend`: see :func:`ray_caster`.
    """
    rays = np.ascontiguousarray(rays, np.float32)
    shape = rays.shape[:-1]
    answer = ray_caster(scene, backend).cast_rays(rays.reshape(-1, 6))
    return {key: value.reshape(*shape, *value.shape[1:]) for key, value in answer.items()}


def distance_to_surface(scene: Scene, points: np.ndarray, backend: str | None = None) -> np.ndarray:
    """(N,) float32 unsigned distance (metres) from (N, 3) points to the nearest triangle."""
    points = np.ascontiguousarray(points, np.float32).reshape(-1, 3)
    return ray_caster(scene, backend).distance_to_surface(points)

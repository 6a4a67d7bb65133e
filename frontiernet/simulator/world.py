"""The simulated world of a run: a scene, its voxel grid and the camera's renderer, built one way.

:func:`build_world` is where a scene spec becomes what the simulator needs, from the command's one
config: its sim sections (``configs/sim.yaml`` as the run resolved it, or any config holding its
sections, as datagen's does) and its scenes section (``configs/scenes.yaml``, the scene sources'
options). It makes ``raycast.backend`` this process's ray-cast engine, loads the scene
(:func:`~frontiernet.scenes.load_scene` with the scenes section), voxelises it (``voxels``) and
builds the renderer of ``camera``, with its background colour (``camera.background``).
:func:`load_world_config` is that config for a command that needs nothing else (``render``,
``scene``, the perf benchmarks).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from omegaconf import OmegaConf

from ..config import load_config, merge_user
from ..scenes import Scene, load_scene
from ..timing import Stopwatch
from .camera import PinholeCamera, Renderer
from .raycast import select_backend
from .voxels import VoxelGrid, voxelize_scene


@dataclass
class World:
    """A scene and what the simulator built from it.

    Attributes:
        scene: the scene (world frame, Z-up, metres).
        voxels: its voxel grid (occupied / explorable / outside), or None when not asked for.
        renderer: the camera's renderer (RGB, z-depth, normals, hit mask), or None when not asked for.
        raycast_backend: this process's ray-cast engine, ``open3d`` or ``embree``.
        seconds: wall time of each step taken, seconds: ``load`` (not when given a Scene),
            ``voxelize``, ``renderer``.
    """

    scene: Scene
    voxels: VoxelGrid | None
    renderer: Renderer | None
    raycast_backend: str
    seconds: dict[str, float] = field(default_factory=dict)


def load_world_config(user_file=None, overrides=(), names=("sim",)):
    """``configs/sim.yaml`` (or the shipped configs `names`, merged in order, such as datagen's
    ``("sim", "datagen")``) with ``configs/scenes.yaml`` as section ``scenes``, then the user's
    YAML `user_file` and ``key=value`` `overrides` on top: what :func:`build_world` reads
    (``build_world(spec, conf, conf.scenes)``), resolved once at a command's top.

    Raises:
        InputError: an unreadable file, an unknown key or a value of the wrong kind.
    """
    conf = OmegaConf.merge(load_config(tuple(names)), {"scenes": load_config("scenes")})
    return merge_user(conf, user_file, overrides, layout={"": names, "scenes": "scenes"})


def build_world(scene: str | Scene, sim_conf, scenes_conf=None, *, voxels: bool = True,
                renderer: bool = True) -> World:
    """The world of `scene` under `sim_conf`, in this order: engine, scene, voxels, renderer.

    Args:
        scene: a scene spec (``procedural:3``, a mesh file, ...; see :mod:`frontiernet.scenes`)
            or a loaded :class:`~frontiernet.scenes.Scene`.
        sim_conf: a config with the sections ``raycast`` (``backend``), ``voxels`` and ``camera``
            of ``configs/sim.yaml`` (a section left out is not read when its part is not built).
        scenes_conf: the command's scenes config (``configs/scenes.yaml`` as it resolved it: one
            section per scene source); needed for a spec, not read for a loaded scene.
        voxels: voxelise the scene (``sim_conf.voxels``).
        renderer: build the renderer of ``sim_conf.camera`` (size, focal length, range, background).
    Raises:
        InputError: an unknown or unavailable ray-cast engine, a scene that does not load, bad
            voxel or camera settings.
    """
    if not isinstance(scene, Scene) and scenes_conf is None:
        raise TypeError("build_world: a scene spec needs scenes_conf, the command's scenes config")
    backend = select_backend(sim_conf.raycast.backend)
    camera = PinholeCamera.from_config(sim_conf.camera) if renderer else None  # checked before the scene loads
    stopwatch = Stopwatch()
    if not isinstance(scene, Scene):
        with stopwatch("load"):
            scene = load_scene(scene, scenes_conf)
    grid = None
    if voxels:
        with stopwatch("voxelize"):
            grid = voxelize_scene(scene, sim_conf.voxels)
    rendering = None
    if renderer:
        with stopwatch("renderer"):
            rendering = Renderer(scene, camera, sim_conf.camera.background)
    return World(scene, grid, rendering, backend, stopwatch.seconds)

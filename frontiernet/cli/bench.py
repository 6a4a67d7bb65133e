"""``frontiernet bench``: benchmarks of hot paths, as ratios to a baseline in the same run.

Machines are noisy and absolute times drift, so every figure is also given relative
to a baseline measured alongside it. ``bench render``: the full render (RGB + depth +
normals + hit mask) against a bare Open3D ``cast_rays`` of the same rays (goal <= 1.5x),
plus scene loading and voxelisation, expressed in the same unit.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from ..config import load_config

HOUSE = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "scenes" / "aws_small_house.glb"
"""The shared textured house next to a checkout (``../shared/data``), the default benchmark scene."""


BENCH_GROUP = "frontiernet.bench"
"""Entry point group of benchmarks added by packages built on the library."""


def default_bench_scene(spec: str | None) -> str:
    """`spec`, else the shared house when it is there, else ``procedural:0``."""
    return spec or (str(HOUSE) if HOUSE.is_file() else "procedural:0")


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("bench", help="benchmarks (ratios to a same-run baseline)",
                                   description=__doc__.split("\n\n")[0])
    actions = parser.add_subparsers(dest="action", metavar="BENCHMARK", required=True,
                                    parser_class=type(parser))
    render = actions.add_parser("render", help="render time per frame vs a bare cast_rays")
    render.add_argument("--scene", default=None,
                        help=f"scene spec (default: {HOUSE} when present, else procedural:0)")
    render.add_argument("--repeats", type=int, default=20, help="timed repetitions (median is reported)")
    render.add_argument("--batch", type=int, default=8, help="poses per batched render")
    render.add_argument("--json", action="store_true", help="print JSON only")
    render.set_defaults(func=run_render)
    from .main import plugin_commands

    for module in plugin_commands(BENCH_GROUP):  # e.g. deploy's `bench inference`
        module.add_parser(actions)


def median_seconds(function, repeats: int, warmup: int = 2) -> float:
    """Median wall time of `function()` over `repeats` runs after `warmup` runs."""
    for _ in range(warmup):
        function()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def run_render(args) -> int:
    import open3d as o3d

    from ..scenes import load_scene
    from ..simulator.camera import PinholeCamera, Renderer
    from ..simulator.poses import sample_poses
    from ..simulator.raycast import raycasting_scene
    from ..simulator.voxels import voxelize_scene

    spec = default_bench_scene(args.scene)
    sim = load_config("sim")
    start = time.perf_counter()
    scene = load_scene(spec)
    load_s = time.perf_counter() - start
    start = time.perf_counter()
    raycasting_scene(scene)
    bvh_s = time.perf_counter() - start
    start = time.perf_counter()
    voxels = voxelize_scene(scene, sim.voxels)
    voxel_s = time.perf_counter() - start
    renderer = Renderer(scene, PinholeCamera.from_config(sim.camera))
    poses = sample_poses(scene, voxels, max(args.batch, 1), 0, sim.poses)
    rays = o3d.core.Tensor.from_numpy(renderer.rays(poses[:1]))
    batch_rays = o3d.core.Tensor.from_numpy(renderer.rays(poses))
    rcs = raycasting_scene(scene)
    cast = median_seconds(lambda: rcs.cast_rays(rays), args.repeats)
    render = median_seconds(lambda: renderer.render(poses[0]), args.repeats)
    cast_batch = median_seconds(lambda: rcs.cast_rays(batch_rays), max(args.repeats // 4, 3)) / len(poses)
    render_batch = median_seconds(lambda: renderer.render_batch(poses), max(args.repeats // 4, 3)) / len(poses)
    result = {
        "scene": spec, "triangles": scene.num_triangles,
        "resolution": [renderer.camera.width, renderer.camera.height],
        "cast_rays_ms": round(cast * 1e3, 2),
        "render_ms": round(render * 1e3, 2),
        "render_over_cast": round(render / cast, 3),
        "batch": len(poses),
        "batched_cast_rays_ms_per_frame": round(cast_batch * 1e3, 2),
        "batched_render_ms_per_frame": round(render_batch * 1e3, 2),
        "batched_render_over_cast": round(render_batch / cast_batch, 3),
        "load_s": round(load_s, 3), "load_in_casts": round(load_s / cast, 1),
        "bvh_build_s": round(bvh_s, 3),
        "voxelize_s": round(voxel_s, 3), "voxelize_in_casts": round(voxel_s / cast, 1),
        "explorable_m3": round(float(voxels.explorable_volume_m3), 2),
    }
    if args.json:
        print(json.dumps(result))
        return 0
    print(f"bench render: {spec} ({scene.num_triangles} triangles), "
          f"{renderer.camera.width}x{renderer.camera.height}, median of {args.repeats}")
    print(f"  bare cast_rays        {result['cast_rays_ms']:8.2f} ms   1.00x (baseline)")
    print(f"  render (rgb+depth+n)  {result['render_ms']:8.2f} ms   {result['render_over_cast']:.2f}x   goal <= 1.5x")
    print(f"  batched x{len(poses)} per frame  {result['batched_render_ms_per_frame']:8.2f} ms   "
          f"{result['batched_render_over_cast']:.2f}x of a batched cast")
    print(f"  scene load            {load_s * 1e3:8.0f} ms   {result['load_in_casts']:.1f} casts")
    print(f"  voxelisation          {voxel_s * 1e3:8.0f} ms   {result['voxelize_in_casts']:.1f} casts "
          f"({result['explorable_m3']} m^3 explorable)")
    return 0

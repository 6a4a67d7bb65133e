"""Benchmarks of hot paths, as ratios to a baseline measured in the same run (``frontiernet bench
render|map|explore``).

Machines are noisy and absolute times drift, so every figure is also given relative to a
baseline measured alongside it. :func:`bench_render`: the full render (RGB + depth + normals +
hit mask) against a bare ``cast_rays`` of the same rays and ray-cast engine (goal <= 1.5x), plus
scene loading and voxelisation, expressed in the same unit. :func:`bench_map`: the occupancy
map's update per frame (ray strides 1, 2, 4) and one known-volume query for many frontier
views, against a render of the same frames (goal: update < 1x). :func:`bench_explore`: each
stage of an exploration step against the render of the same run.

Each returns its figures as a JSON-ready dict (times in milliseconds or seconds, as the key
says); printing them is the command line's. :func:`median_seconds` times anything the same way
(``bench inference``), :func:`median_seconds_interleaved` several things in turns
(``bench inference --encoders``).
"""

from __future__ import annotations

import logging
import os
import time
from pathlib import Path

import numpy as np

from ..config import load_config
from ..errors import InputError

log = logging.getLogger(__name__)

CHECKOUT = Path(__file__).resolve().parents[2]
"""The folder that holds the ``frontiernet`` package: relative ``perf.scene`` paths start here."""


def default_bench_scene(spec: str | None) -> str:
    """`spec`, else ``perf.scene`` of configs/bench.yaml when that file is there, else (with a
    warning naming the missing file) ``perf.fallback_scene``. An empty `spec` is refused (``--scene ''``: not
    the default)."""
    if spec is not None:
        if not str(spec).strip():
            raise InputError("--scene '': an empty scene spec (leave --scene out for the default scene)")
        return spec
    conf = load_config("bench").perf
    path = Path(os.path.normpath(CHECKOUT / Path(conf.scene).expanduser()))  # an absolute one stays
    if path.is_file():
        return str(path)
    log.warning("benchmark scene %s (perf.scene of configs/bench.yaml) not found; using %s (--scene chooses one)",
                path, conf.fallback_scene)
    return str(conf.fallback_scene)


def median_seconds(function, repeats: int, warmup: int = 2) -> float:
    """Median wall time (seconds) of `function()` over `repeats` runs after `warmup` runs."""
    return median_seconds_interleaved({"function": function}, repeats, warmup)["function"]


def median_seconds_interleaved(functions: dict, repeats: int, warmup: int = 2) -> dict:
    """Median wall time (seconds) of each of `functions` (name -> callable), timed in turns (one run
    of each per round, `repeats` rounds after `warmup`), so that a machine's load drifting during
    the run weighs on all of them alike: their ratios are what to read on a busy machine."""
    for _ in range(warmup):
        for function in functions.values():
            function()
    times = {name: [] for name in functions}
    for _ in range(repeats):
        for name, function in functions.items():
            start = time.perf_counter()
            function()
            times[name].append(time.perf_counter() - start)
    return {name: float(np.median(values)) for name, values in times.items()}


def median_each(function, items: list) -> tuple[float, list]:
    """Median wall time (seconds) of `function(item)` over `items`, and the results."""
    times, results = [], []
    for item in items:
        start = time.perf_counter()
        results.append(function(item))
        times.append(time.perf_counter() - start)
    return float(np.median(times)), results


def bench_render(spec: str | None, repeats: int, batch: int, raycast: str | None = None) -> dict:
    """Render and bare ray-cast times of one scene, single and batched, with scene loading, BVH
    build and voxelisation; `raycast` selects the engine (None: sim.yaml's raycast.backend).

    Returns ``scene``, ``triangles``, ``raycast_backend``, ``resolution`` [W, H], ``cast_rays_ms``,
    ``render_ms``, ``render_over_cast``, ``batch`` and the ``batched_*`` figures per frame,
    ``load_s``, ``bvh_build_s``, ``voxelize_s`` (and the first and last in casts), ``explorable_m3``.
    """
    from omegaconf import OmegaConf

    from ..simulator.poses import sample_poses
    from ..simulator.raycast import ray_caster
    from ..simulator.world import build_world, load_world_config

    spec = default_bench_scene(spec)
    sim = load_world_config()
    if raycast:
        sim = OmegaConf.merge(sim, {"raycast": {"backend": raycast}})
    world = build_world(spec, sim, sim.scenes)
    scene, voxels, renderer = world.scene, world.voxels, world.renderer
    load_s, voxel_s = world.seconds["load"], world.seconds["voxelize"]
    start = time.perf_counter()
    caster = ray_caster(scene)  # the world's engine (raycast, else sim.yaml's raycast.backend)
    bvh_s = time.perf_counter() - start
    poses = sample_poses(scene, voxels, max(batch, 1), 0, sim.poses)
    rays = renderer.rays(poses[:1]).reshape(-1, 6)
    batch_rays = renderer.rays(poses).reshape(-1, 6)
    cast = median_seconds(lambda: caster.cast_rays(rays), repeats)
    render = median_seconds(lambda: renderer.render(poses[0]), repeats)
    cast_batch = median_seconds(lambda: caster.cast_rays(batch_rays), max(repeats // 4, 3)) / len(poses)
    render_batch = median_seconds(lambda: renderer.render_batch(poses), max(repeats // 4, 3)) / len(poses)
    return {
        "scene": spec, "triangles": scene.num_triangles, "raycast_backend": world.raycast_backend,
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


def bench_map(spec: str | None, frames: int, views: int) -> dict:
    """Occupancy-map update per frame (ray strides 1, 2, 4) and one ``visible_known_volume`` call
    for `views` frontier views, against a render of the same `frames` frames.

    Returns ``scene``, ``resolution`` [W, H], ``frames``, ``render_ms``, per stride
    ``integrate_stride{s}_ms`` and ``integrate_stride{s}_over_render``, ``integrate_edges_ms`` and
    ``_over_render`` (the explore stride, as for monocular depth: depth edges and oblique pixels left out), ``views``,
    ``visible_known_volume_ms`` and ``_over_render``, ``known_m3`` (after the stride-4 frames).
    """
    from omegaconf import OmegaConf

    from ..mapping import OccupancyMap
    from ..simulator.poses import sample_poses
    from ..simulator.world import build_world, load_world_config

    spec = default_bench_scene(spec)
    sim, explore = load_world_config(), load_config("explore")
    world = build_world(spec, sim, sim.scenes)
    scene, voxels, renderer = world.scene, world.voxels, world.renderer
    poses = sample_poses(scene, voxels, max(frames, 1), 0, sim.poses)
    renderer.render(poses[0])  # warm-up
    render, rendered = median_each(renderer.render, list(poses))
    result = {"scene": spec, "resolution": [renderer.camera.width, renderer.camera.height], "frames": len(poses),
              "render_ms": round(render * 1e3, 2)}
    for stride in (1, 2, 4):
        conf = OmegaConf.merge(explore.map, {"ray_stride_px": stride})
        OccupancyMap.like(voxels, conf).integrate(rendered[0].depth, rendered[0].K, poses[0])  # warm-up (compile)
        occupancy = OccupancyMap.like(voxels, conf)
        update, _ = median_each(lambda frame, occupancy=occupancy: occupancy.integrate(frame.depth, frame.K,
                                                                                       frame.T_world_cam), rendered)
        result[f"integrate_stride{stride}_ms"] = round(update * 1e3, 2)
        result[f"integrate_stride{stride}_over_render"] = round(update / render, 3)
    edges = OccupancyMap.like(voxels, explore.map)  # the explore stride, monocular: depth edges and oblique pixels out
    update, _ = median_each(lambda frame: edges.integrate(frame.depth, frame.K, frame.T_world_cam, True), rendered)
    result.update({"integrate_edges_ms": round(update * 1e3, 2), "integrate_edges_over_render": round(update / render, 3)})
    view = explore.tracking.gain_view
    frontier_views = sample_poses(scene, voxels, max(views, 1), 1, sim.poses)
    query = median_seconds(lambda: occupancy.visible_known_volume(frontier_views, int(view.width_px),
                                                                  float(view.focal_px), float(view.max_depth_m)), 5)
    result.update({"views": len(frontier_views), "visible_known_volume_ms": round(query * 1e3, 2),
                   "visible_known_volume_over_render": round(query / render, 3),
                   "known_m3": round(occupancy.known_volume_m3, 2)})
    return result


def bench_explore(spec: str | None, method: str, steps: int, depth: str | None = None, model=None,
                  overrides=()) -> dict:
    """Explore `steps` steps with `method` (no video; `model`: its model file, as ``explore --model``,
    None: the shipped one; `overrides`: ``key=value`` words over the run config, as ``explore``
    takes them) on depth source `depth` (None: ``run.depth`` of configs/explore.yaml,
    ground truth; ``emulated``: the monocular emulation, whose cost is the ``depth`` stage) and give
    each stage's mean time per step as a ratio to the render of the same run; goal: perception +
    anchoring >= 5 Hz at 320 px on 2 cores, map update below one render.

    Returns ``scene``, ``method``, ``depth``, ``steps`` (taken), ``mean_ms`` and ``over_render`` per
    stage, ``step_ms_without_motion``, ``image_to_frontiers_hz``.
    """
    import tempfile

    from ..exploration.run import load_run_config, main

    spec = default_bench_scene(spec)
    conf = load_run_config(None, overrides)
    with tempfile.TemporaryDirectory() as out:
        record = main(conf, spec, out, method=method, model=model, depth=depth, max_steps=steps, video=False,
                      progress=False)
    timing = record["timing"]
    mean = timing["mean_ms"]
    return {"scene": spec, "method": method, "depth": record["depth"], "steps": record["steps"], "mean_ms": mean,
            "over_render": {k: round(v / max(mean["render"], 1e-9), 3) for k, v in mean.items()},
            "step_ms_without_motion": timing["step_ms_without_motion"],
            "image_to_frontiers_hz": timing["image_to_frontiers_hz"]}


def bench_explore_against(spec: str | None, against: str, method: str, steps: int, depth: str | None = None,
                          model=None, overrides=()) -> dict:
    """:func:`bench_explore` on `against` (the baseline, run first) and on `spec`, side by side: how a
    step's cost grows with the scene (issue 55: a 60 x 60 m floor within 1.5x of a 10 x 10 m one).

    Returns ``scene`` and ``against`` (each :func:`bench_explore`'s result), ``step_ratio`` (the
    scene's ``step_ms_without_motion`` over the baseline's) and ``stage_ratio`` (each stage's mean
    over the baseline's; None where the baseline's is below 0.01 ms).
    """
    base = bench_explore(against, method, steps, depth, model, overrides)
    result = bench_explore(spec, method, steps, depth, model, overrides)
    ratio = {stage: (round(ms / base["mean_ms"][stage], 2) if base["mean_ms"].get(stage, 0.0) >= 0.01 else None)
             for stage, ms in result["mean_ms"].items()}
    return {"scene": result, "against": base, "stage_ratio": ratio,
            "step_ratio": round(result["step_ms_without_motion"] / max(base["step_ms_without_motion"], 1e-9), 2)}

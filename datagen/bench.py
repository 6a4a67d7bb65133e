"""The datagen benchmark: one ground-truth view in units of one depth render, same run.

A view's cost is the median over views of the whole pipeline (render, V_in, frontier
voxels, gain views, projection, image labels); the baseline is the median time of a
bare depth render (Open3D ``cast_rays`` of the same view's rays). Views per second per
core runs the pipeline single-threaded (numba with one thread), as a datagen worker does.
"""

from __future__ import annotations

import os
import resource
import time

import numpy as np


def bench_ground_truth(spec: str | None = None, views: int = 20) -> dict:
    """Time `views` ground-truth views of a scene; returns the figures as a dict."""
    import numba

    from frontiernet.cli.bench import default_bench_scene
    from frontiernet.errors import InputError
    from frontiernet.scenes import load_scene
    from frontiernet.simulator.poses import sample_poses
    from frontiernet.simulator.raycast import cast_rays
    from frontiernet.simulator.voxels import voxelize_scene

    from .config import load_datagen_config
    from .ground_truth import GroundTruthGenerator

    if views < 1:
        raise InputError(f"--views must be a positive integer, got {views}")
    spec = default_bench_scene(spec)
    conf = load_datagen_config()
    start = time.perf_counter()
    scene = load_scene(spec)
    voxels = voxelize_scene(scene, conf.voxels)
    generator = GroundTruthGenerator(scene, voxels, conf)
    setup_s = time.perf_counter() - start
    poses = sample_poses(scene, voxels, views, 0, conf.poses)
    rng = np.random.default_rng(0)
    generator(poses[0], rng)  # compile and warm caches
    renders, totals, stages = [], [], {}
    for T in poses:
        rays = generator.renderer.rays(T[None]).reshape(-1, 6)
        t0 = time.perf_counter()
        cast_rays(scene, rays)
        renders.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        truth = generator(T, rng)
        totals.append(time.perf_counter() - t0)
        for stage, seconds in truth.timings.items():
            stages.setdefault(stage, []).append(seconds)
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        t0 = time.perf_counter()
        count = min(views, 10)
        for T in poses[:count]:
            generator(T, rng)
        single = (time.perf_counter() - t0) / count
    finally:
        numba.set_num_threads(threads)
    render = float(np.median(renders))
    view = float(np.median(totals))
    camera = generator.camera
    return {
        "scene": spec, "resolution": [camera.width, camera.height], "views": views,
        "render_ms": render * 1e3, "view_ms": view * 1e3, "view_in_renders": view / render,
        "stages_ms": {stage: float(np.median(values)) * 1e3 for stage, values in stages.items()},
        "views_per_second_per_core": 1.0 / single, "threads": threads, "cores": os.cpu_count(),
        "setup_s": setup_s, "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
    }

"""The datagen benchmark: one ground-truth view in units of one depth render, per ray-cast engine.

A view's cost is the median over views of the whole pipeline (render, V_in, frontier
voxels, gain views, projection, image labels); the render is the median time of a bare
``cast_rays`` of the same view's rays. Every ray-cast engine that can be imported here
(:data:`frontiernet.simulator.raycast.BACKENDS`) is timed on the same views, view by view
in turn, and given as ratios to the first one's bare cast (the baseline: Open3D when
present). Views per second per core runs the pipeline single-threaded (numba, and so
Embree's casts, with one thread), as a datagen worker does; Open3D's casts use every core
whatever numba's setting. The engines' answers are compared on the same rays: hit-mask
pixels that differ, the largest hit-distance difference, and the rays that hit another triangle
at that distance (two triangles in one plane, where either answer is right).
"""

from __future__ import annotations

import os
import resource
import time

import numpy as np

DISTANCE_QUERIES = 1024
"""Points of the timed ``distance_to_surface`` call: one round of pose sampling (``poses.batch_size``)."""


def _engines(backends: list[str] | None) -> list[str]:
    """The engines to time: those given, else every one that can be imported (at least one)."""
    from frontiernet.errors import InputError
    from frontiernet.simulator.raycast import BACKENDS, resolve_backend

    if backends:
        return [resolve_backend(name) for name in dict.fromkeys(backends)]
    found = []
    for name in BACKENDS:
        try:
            found.append(resolve_backend(name))
        except InputError:
            continue
    return found or [resolve_backend("auto")]  # none: auto's error says what to install


def bench_ground_truth(spec: str | None = None, views: int = 20, backends: list[str] | None = None) -> dict:
    """Time `views` ground-truth views of a scene per engine; returns the figures as a dict.

    The top-level ``render_ms``, ``view_ms``, ``view_in_renders``, ``stages_ms`` and
    ``views_per_second_per_core`` are the baseline engine's; ``backends`` holds each engine's.
    """
    import numba

    from frontiernet.benchmark.perf import default_bench_scene
    from frontiernet.errors import InputError
    from frontiernet.simulator.poses import sample_poses
    from frontiernet.simulator.raycast import INVALID_ID, cast_rays, distance_to_surface, ray_caster, select_backend
    from frontiernet.simulator.world import build_world

    from .config import load_datagen_config
    from .ground_truth import GroundTruthGenerator

    if views < 1:
        raise InputError(f"--views must be a positive integer, got {views}")
    engines = _engines(backends)
    spec = default_bench_scene(spec)
    conf = load_datagen_config()
    start = time.perf_counter()
    world = build_world(spec, conf, conf.scenes)
    scene, voxels = world.scene, world.voxels
    generator = GroundTruthGenerator(scene, voxels, conf, renderer=world.renderer)
    setup_s = time.perf_counter() - start
    free = np.random.default_rng(0).choice(np.flatnonzero(voxels.explorable), DISTANCE_QUERIES)
    points = voxels.index_to_world(np.stack(np.unravel_index(free, voxels.shape), axis=1))  # as pose sampling asks
    builds = {}
    for name in engines:
        start = time.perf_counter()
        ray_caster(scene, name)
        builds[name] = time.perf_counter() - start
    select_backend(engines[0])
    poses = sample_poses(scene, voxels, views, 0, conf.poses)
    figures = {}
    for name in engines:
        select_backend(name)
        generator(poses[0], np.random.default_rng(0))  # compile and warm caches
        start = time.perf_counter()
        distance_to_surface(scene, points, name)  # builds Embree's closest-point tree on first use
        tree = time.perf_counter() - start
        figures[name] = {"build_s": builds[name] + tree, "renders": [], "totals": [], "stages": {}, "distance": []}
    mismatched, worst_mm, hits, other_triangle = 0, 0.0, 0, 0
    rng = np.random.default_rng(0)
    for T in poses:  # engines in turn on each view: drifting machine load affects them alike
        rays = generator.renderer.rays(T[None]).reshape(-1, 6)
        answers = []
        for name in engines:
            numbers = figures[name]
            select_backend(name)
            t0 = time.perf_counter()
            answers.append(cast_rays(scene, rays))
            numbers["renders"].append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            truth = generator(T, rng)
            numbers["totals"].append(time.perf_counter() - t0)
            for stage, seconds in truth.timings.items():
                numbers["stages"].setdefault(stage, []).append(seconds)
            t0 = time.perf_counter()
            distance_to_surface(scene, points)
            numbers["distance"].append(time.perf_counter() - t0)
        first = answers[0]["primitive_ids"] != INVALID_ID
        for other in answers[1:]:
            hit = other["primitive_ids"] != INVALID_ID
            mismatched += int((hit != first).sum())
            both = hit & first
            hits += int(both.sum())
            other_triangle += int((both & (other["primitive_ids"] != answers[0]["primitive_ids"])).sum())
            if both.any():
                worst_mm = max(worst_mm, float(np.abs(other["t_hit"][both] - answers[0]["t_hit"][both]).max()) * 1e3)
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        count = min(views, 10)
        for name in engines:
            figures[name]["single_s"] = 0.0
        for T in poses[:count]:  # engines in turn on each view, as above
            for name in engines:
                select_backend(name)
                t0 = time.perf_counter()
                generator(T, rng)
                figures[name]["single_s"] += (time.perf_counter() - t0) / count
    finally:
        numba.set_num_threads(threads)
    baseline = float(np.median(figures[engines[0]]["renders"]))
    base_single = figures[engines[0]]["single_s"]
    results = {}
    for name in engines:
        numbers = figures[name]
        render, view = float(np.median(numbers["renders"])), float(np.median(numbers["totals"]))
        results[name] = {
            "render_ms": render * 1e3, "render_over_baseline": render / baseline,
            "view_ms": view * 1e3, "view_in_renders": view / render, "view_in_baseline_renders": view / baseline,
            "stages_ms": {stage: float(np.median(values)) * 1e3 for stage, values in numbers["stages"].items()},
            "views_per_second_per_core": 1.0 / numbers["single_s"],
            "views_per_second_per_core_over_baseline": base_single / numbers["single_s"],
            "distance_ms": float(np.median(numbers["distance"])) * 1e3, "build_s": numbers["build_s"],
        }
    camera = generator.camera
    base = results[engines[0]]
    return {
        "scene": spec, "resolution": [camera.width, camera.height], "views": views, "baseline": engines[0],
        "render_ms": base["render_ms"], "view_ms": base["view_ms"], "view_in_renders": base["view_in_renders"],
        "stages_ms": base["stages_ms"], "views_per_second_per_core": base["views_per_second_per_core"],
        "backends": results,
        "agreement": {"compared": engines[1:] and f"{', '.join(engines[1:])} vs {engines[0]}",
                      "hit_mask_mismatched_pixels": mismatched, "pixels": views * len(rays) * (len(engines) - 1),
                      "max_hit_distance_difference_mm": worst_mm, "common_hits": hits,
                      "common_hits_on_another_triangle": other_triangle},
        "distance_queries": DISTANCE_QUERIES, "threads": threads, "cores": os.cpu_count(), "setup_s": setup_s,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
    }

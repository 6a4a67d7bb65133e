"""``frontiernet bench``: benchmarks of hot paths, as ratios to a baseline in the same run.

Machines are noisy and absolute times drift, so every figure is also given relative
to a baseline measured alongside it. ``bench render``: the full render (RGB + depth +
normals + hit mask) against a bare ``cast_rays`` of the same rays and ray-cast engine (goal
<= 1.5x), plus scene loading and voxelisation, expressed in the same unit. ``bench map``: the
occupancy map's update per frame (ray strides 1, 2, 4) and one known-volume query for
many frontier views, against a render of the same frames (goal: update < 1x).
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
    parser = subparsers.add_parser("bench", help="the exploration benchmark (--scenes ...), or a hot-path "
                                                 "benchmark (ratios to a same-run baseline)",
                                   description=__doc__.split("\n\n")[0],
                                   allow_abbrev=False)  # `bench map --scene` is not --scenes abbreviated
    _exploration_options(parser)
    actions = parser.add_subparsers(dest="action", metavar="BENCHMARK", required=False,
                                    parser_class=type(parser))
    parser.set_defaults(func=run_exploration_benchmark)
    render = _scene_bench(actions, "render", "render time per frame vs a bare cast_rays", run_render)
    render.add_argument("--repeats", type=int, default=20, help="timed repetitions (median is reported)")
    render.add_argument("--batch", type=int, default=8, help="poses per batched render")
    render.add_argument("--raycast", choices=("auto", "open3d", "embree"),
                        help="ray-cast engine (default: raycast.backend of configs/sim.yaml)")
    occupancy = _scene_bench(actions, "map", "occupancy map update per frame vs a render", run_map)
    occupancy.add_argument("--frames", type=int, default=20, help="frames rendered and integrated (median is reported)")
    occupancy.add_argument("--views", type=int, default=50, help="frontier views of one visible_known_volume call")
    explore = _scene_bench(actions, "explore", "cost of one exploration step by stage vs a render", run_explore)
    explore.add_argument("--method", default="frontiernet", help="exploration method (see `frontiernet explore -h`)")
    explore.add_argument("--steps", type=int, default=60, help="steps explored (means over them are reported)")
    from .main import plugin_commands

    for module in plugin_commands(BENCH_GROUP):  # e.g. deploy's `bench inference`
        module.add_parser(actions)


def _exploration_options(parser) -> None:
    """``frontiernet bench --scenes ... --methods ...``: every method on the same scenes, starts and budget."""
    group = parser.add_argument_group("exploration benchmark (docs/benchmark.md)")
    group.add_argument("--scenes", nargs="+", metavar="SPEC",
                       help="scene specs; ranges (procedural:1000-1009), globs and folders of scenes expand")
    group.add_argument("--methods", default="frontiernet,classic",
                       help="comma-separated methods (default frontiernet,classic; see `frontiernet explore -h`)")
    group.add_argument("--starts", type=int, default=3, help="start poses per scene (sampled once, shared)")
    group.add_argument("--scene-starts", action="store_true",
                       help="use the start positions a scene ships first (KTH plan folders: MapEx's)")
    group.add_argument("--repeats", type=int, default=3, help="runs per start and method (seeds seed..seed+R-1)")
    group.add_argument("--max-steps", type=int, help="step budget (default: configs/explore.yaml run.max_steps)")
    group.add_argument("--out", help="output folder (resumable: finished runs are not redone)")
    group.add_argument("--report", action="store_true",
                       help="with --out only: rebuild results.csv, table.md and the plots from the runs finished "
                            "so far, running nothing (safe while the benchmark runs)")
    group.add_argument("--pack", action="store_true",
                       help="with --out only: move the finished runs' metrics.json into one compressed file per "
                            "scene and method (runs/<scene>/<method>.jsonl.gz), which --report and a resumed "
                            "benchmark read; runs nothing (before --report when both are given)")
    group.add_argument("--workers", type=int, default=1, help="parallel runs")
    group.add_argument("--backend", default="local", help="local (processes) or ray")
    group.add_argument("--seed", type=int, help="seed of the start poses and runs (default: run.seed)")
    group.add_argument("--model", help="model file of the learned methods (default: the shipped model)")
    group.add_argument("--depth", help="depth source of every run (default: run.depth)")
    group.add_argument("--config", help="YAML overriding configs/explore.yaml, and sim.yaml and depth.yaml under "
                                        "sections sim: and depth:")
    group.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                       help="config overrides, e.g. planner.clearance_m=0.3 depth.emulated.scale_per_frame=false")


def run_exploration_benchmark(args) -> int:
    from ..benchmark import main, pack, report
    from ..errors import InputError
    from ..exploration.run import load_run_config

    if args.pack:
        if not args.out:
            raise InputError("--pack needs --out DIR, the benchmark folder")
        packed = pack(args.out)
        print(f"bench: packed {packed['runs']} run(s) into {len(packed['packs'])} file(s); "
              f"{packed['packed']} runs packed in {args.out}/runs")
        if not args.report:
            return 0
    if args.report:
        if not args.out:
            raise InputError("--report needs --out DIR, the benchmark folder")
        result = report(args.out)
        print(Path(result["table"]).read_text())
        print(f"bench: report of {len(result['rows'])} finished runs ({result['pending']} not yet): {result['results']}, "
              f"{result['table']}, {len(result['plots'])} coverage plot(s) in {args.out}")
        return 0
    if not args.scenes:  # (a benchmark subcommand sets its own func)
        raise InputError("give a benchmark (render, map, explore, ...) or --scenes for the exploration benchmark")
    if not args.out:
        raise InputError("the exploration benchmark needs --out DIR")
    conf = load_run_config(args.config, args.set)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    result = main(conf, args.scenes, methods, args.out, starts=args.starts, repeats=args.repeats,
                  max_steps=args.max_steps, workers=args.workers, backend=args.backend, seed=args.seed,
                  model=args.model, depth=args.depth, scene_starts=args.scene_starts, progress=True)
    failed = sum(row["status"] != "done" for row in result["rows"])
    copies = sum(bool(row["copy_of"]) for row in result["rows"])
    copied = f", {copies} identical repeats taken from repeat 0" if copies else ""
    print(Path(result["table"]).read_text())
    print(f"bench: {len(result['rows'])} runs ({failed} failed{copied}) in {result['wall_s']} s; "
          f"{result['results']}, {result['table']}, {len(result['plots'])} coverage plot(s) in {args.out}")
    return 0


def _scene_bench(actions, name: str, help_text: str, func):
    """A benchmark subcommand with the options every scene benchmark takes (--scene, --json)."""
    parser = actions.add_parser(name, help=help_text)
    parser.add_argument("--scene", default=None,
                        help=f"scene spec (default: {HOUSE} when present, else procedural:0)")
    parser.add_argument("--json", action="store_true", help="print JSON only")
    parser.set_defaults(func=func)
    return parser


def counts(**options: int) -> None:
    """InputError naming the first option (``--name``) of `options` that is not an integer >= 1."""
    from ..errors import whole_number

    for name, value in options.items():
        whole_number(value, f"--{name}", 1)


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


def median_each(function, items: list) -> tuple[float, list]:
    """Median wall time of `function(item)` over `items`, and the results."""
    times, results = [], []
    for item in items:
        start = time.perf_counter()
        results.append(function(item))
        times.append(time.perf_counter() - start)
    return float(np.median(times)), results


def run_render(args) -> int:
    from ..scenes import load_scene
    from ..simulator.camera import PinholeCamera, Renderer
    from ..simulator.poses import sample_poses
    from ..simulator.raycast import active_backend, ray_caster, select_backend
    from ..simulator.voxels import voxelize_scene

    counts(repeats=args.repeats, batch=args.batch)
    if args.raycast:
        select_backend(args.raycast)
    spec = default_bench_scene(args.scene)
    sim = load_config("sim")
    start = time.perf_counter()
    scene = load_scene(spec)
    load_s = time.perf_counter() - start
    start = time.perf_counter()
    caster = ray_caster(scene)  # sim.yaml's raycast.backend
    bvh_s = time.perf_counter() - start
    start = time.perf_counter()
    voxels = voxelize_scene(scene, sim.voxels)
    voxel_s = time.perf_counter() - start
    renderer = Renderer(scene, PinholeCamera.from_config(sim.camera))
    poses = sample_poses(scene, voxels, max(args.batch, 1), 0, sim.poses)
    rays = renderer.rays(poses[:1]).reshape(-1, 6)
    batch_rays = renderer.rays(poses).reshape(-1, 6)
    cast = median_seconds(lambda: caster.cast_rays(rays), args.repeats)
    render = median_seconds(lambda: renderer.render(poses[0]), args.repeats)
    cast_batch = median_seconds(lambda: caster.cast_rays(batch_rays), max(args.repeats // 4, 3)) / len(poses)
    render_batch = median_seconds(lambda: renderer.render_batch(poses), max(args.repeats // 4, 3)) / len(poses)
    result = {
        "scene": spec, "triangles": scene.num_triangles, "raycast_backend": active_backend(),
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
    print(f"  bare cast_rays ({result['raycast_backend']:6s}) {result['cast_rays_ms']:5.2f} ms   1.00x (baseline)")
    print(f"  render (rgb+depth+n)  {result['render_ms']:8.2f} ms   {result['render_over_cast']:.2f}x   goal <= 1.5x")
    print(f"  batched x{len(poses)} per frame  {result['batched_render_ms_per_frame']:8.2f} ms   "
          f"{result['batched_render_over_cast']:.2f}x of a batched cast")
    print(f"  scene load            {load_s * 1e3:8.0f} ms   {result['load_in_casts']:.1f} casts")
    print(f"  voxelisation          {voxel_s * 1e3:8.0f} ms   {result['voxelize_in_casts']:.1f} casts "
          f"({result['explorable_m3']} m^3 explorable)")
    return 0


def run_map(args) -> int:
    from omegaconf import OmegaConf

    from ..mapping import OccupancyMap
    from ..scenes import load_scene
    from ..simulator.camera import PinholeCamera, Renderer
    from ..simulator.poses import sample_poses
    from ..simulator.voxels import voxelize_scene

    counts(frames=args.frames, views=args.views)
    spec = default_bench_scene(args.scene)
    sim, explore = load_config("sim"), load_config("explore")
    scene = load_scene(spec)
    voxels = voxelize_scene(scene, sim.voxels)
    renderer = Renderer(scene, PinholeCamera.from_config(sim.camera))
    poses = sample_poses(scene, voxels, max(args.frames, 1), 0, sim.poses)
    renderer.render(poses[0])  # warm-up
    render, frames = median_each(renderer.render, list(poses))
    result = {"scene": spec, "resolution": [renderer.camera.width, renderer.camera.height], "frames": len(poses),
              "render_ms": round(render * 1e3, 2)}
    for stride in (1, 2, 4):
        conf = OmegaConf.merge(explore.map, {"ray_stride_px": stride})
        OccupancyMap.like(voxels, conf).integrate(frames[0].depth, frames[0].K, poses[0])  # warm-up (compile)
        occupancy = OccupancyMap.like(voxels, conf)
        update, _ = median_each(lambda frame, occupancy=occupancy: occupancy.integrate(frame.depth, frame.K,
                                                                                       frame.T_world_cam), frames)
        result[f"integrate_stride{stride}_ms"] = round(update * 1e3, 2)
        result[f"integrate_stride{stride}_over_render"] = round(update / render, 3)
    view = explore.tracking.gain_view
    views = sample_poses(scene, voxels, max(args.views, 1), 1, sim.poses)
    query = median_seconds(lambda: occupancy.visible_known_volume(views, int(view.width_px), float(view.focal_px),
                                                                  float(view.max_depth_m)), 5)
    result.update({"views": len(views), "visible_known_volume_ms": round(query * 1e3, 2),
                   "visible_known_volume_over_render": round(query / render, 3),
                   "known_m3": round(occupancy.known_volume_m3, 2)})
    if args.json:
        print(json.dumps(result))
        return 0
    print(f"bench map: {spec}, {renderer.camera.width}x{renderer.camera.height}, median of {len(poses)} frames")
    rows = [("render (rgb+depth+n)", render, "(baseline)")]
    for stride in (1, 2, 4):
        default = " (config)" if stride == int(explore.map.ray_stride_px) else ""
        seconds = result[f"integrate_stride{stride}_ms"] / 1e3
        rows.append((f"map update, stride {stride}{default}", seconds, "goal < 1x"))
    rows.append((f"visible_known_volume x{len(views)}", query,
                 f"({view.width_px} px views, {result['known_m3']} m^3 known)"))
    for label, seconds, note in rows:
        print(f"  {label:<30s}{seconds * 1e3:8.2f} ms   {seconds / render:5.2f}x   {note}")
    return 0


def run_explore(args) -> int:
    """Explore `--steps` steps (no video) and report each stage's mean time per step as a ratio
    to the render of the same run; goal: perception + anchoring >= 5 Hz at 320 px on 2 cores,
    map update below one render."""
    import tempfile

    from ..exploration.run import main

    counts(steps=args.steps)
    spec = default_bench_scene(args.scene)
    with tempfile.TemporaryDirectory() as out:
        record = main(load_config("explore"), spec, out, method=args.method, max_steps=args.steps, video=False,
                      progress=False)
    timing = record["timing"]
    mean = timing["mean_ms"]
    result = {"scene": spec, "method": args.method, "steps": record["steps"], "mean_ms": mean,
              "over_render": {k: round(v / max(mean["render"], 1e-9), 3) for k, v in mean.items()},
              "step_ms_without_motion": timing["step_ms_without_motion"],
              "image_to_frontiers_hz": timing["image_to_frontiers_hz"]}
    if args.json:
        print(json.dumps(result))
        return 0
    print(f"bench explore: {spec}, {args.method}, {record['steps']} steps, mean per step")
    for stage, ms in mean.items():
        print(f"  {stage:<12} {ms:8.2f} ms   {result['over_render'][stage]:6.2f}x of a render")
    print(f"  step without motion {timing['step_ms_without_motion']:.1f} ms; image to 3D frontiers "
          f"(perception + anchoring) {timing['image_to_frontiers_hz']} Hz   goal >= 5 Hz")
    return 0

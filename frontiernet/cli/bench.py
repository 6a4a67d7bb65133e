"""``frontiernet bench``: benchmarks of hot paths, as ratios to a baseline in the same run.

``bench render``, ``bench map`` and ``bench explore`` parse their options here and print the
figures of :mod:`frontiernet.benchmark.perf`, which measures them (what each compares is said
there); ``bench --scenes ...`` is the exploration benchmark (:mod:`frontiernet.benchmark`).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..registry import Registry
from . import options
from .parser import one_line

BENCH_ACTIONS = Registry("bench action", "frontiernet.bench")
"""Benchmarks added by packages built on the library (``deploy``'s ``bench inference``): modules
with ``add_parser(actions)``; ``render``, ``map`` and ``explore`` are this module's own."""


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("bench", help="the exploration benchmark (--scenes ...), or a hot-path "
                                                 "benchmark (ratios to a same-run baseline)",
                                   description=__doc__.split("\n\n")[0],
                                   allow_abbrev=False)  # `bench map --scene` is not --scenes abbreviated
    _exploration_options(parser)
    # what a hot-path benchmark refuses when given before it (it would drop it: _Benchmarks)
    parser.set_defaults(own_option_defaults=options.option_defaults(parser._actions))
    actions = parser.add_subparsers(dest="action", metavar="BENCHMARK", required=False,
                                    parser_class=type(parser), action=_Benchmarks)
    parser.set_defaults(func=run_exploration_benchmark)
    render = scene_benchmark(actions, "render", "render time per frame vs a bare cast_rays", run_render)
    render.add_argument("--repeats", type=int, default=20, help="timed repetitions (median is reported)")
    render.add_argument("--batch", type=int, default=8, help="poses per batched render")
    render.add_argument("--raycast", choices=("auto", "open3d", "embree"),
                        help="ray-cast engine (default: raycast.backend of configs/sim.yaml)")
    occupancy = scene_benchmark(actions, "map", "occupancy map update per frame vs a render", run_map)
    occupancy.add_argument("--frames", type=int, default=20, help="frames rendered and integrated (median is reported)")
    occupancy.add_argument("--views", type=int, default=50, help="frontier views of one visible_known_volume call")
    explore = scene_benchmark(actions, "explore", "cost of one exploration step by stage vs a render", run_explore)
    explore.add_argument("--method", default="frontiernet", help="exploration method (see `frontiernet explore -h`)")
    explore.add_argument("--steps", type=int, default=60, help="steps explored (means over them are reported)")
    explore.add_argument("--depth", help="depth source: gt (default: run.depth of configs/explore.yaml) or emulated "
                                         "(the monocular emulation's cost is the depth stage)")
    explore.add_argument("--against", metavar="SPEC",
                         help="a baseline scene explored first the same way: each stage's cost on --scene as a "
                              "ratio to it (how a step's cost grows with the building; e.g. a 60 m floor against a "
                              "10 m one, tests/bench/grid_floor.py)")
    explore.add_argument("--model", type=options.input_path("model file"),
                         help="the method's model file, as explore --model takes it (a FrontierNet model, or "
                              "seer's and mapex's predictor; default: the shipped one)")
    options.config_overrides(explore, "mapex.predictor=runs/mapex/predictor.safetensors planner.clearance_m=0.3")
    for module in BENCH_ACTIONS.load_all():  # e.g. deploy's `bench inference`
        module.add_parser(actions)


class _Benchmarks(options.Subcommands):
    """bench's hot-path benchmarks (render, map, explore, and those of packages: inference, train), which
    read none of the exploration benchmark's options: one given before a benchmark's name is refused as the
    command line is read (``bench --methods classic explore`` timed frontiernet; ``bench --depth emulated
    explore`` ground truth), naming the benchmark's own option to give after its name where it has one."""

    def __call__(self, parser, namespace, values, option_string=None):
        super().__call__(parser, namespace, values, option_string)
        message = options.options_before_subcommand(namespace, "bench")
        if message:
            parser.error(message)


def _exploration_options(parser) -> None:
    """``frontiernet bench --scenes ... --methods ...``: every method on the same scenes, starts and budget."""
    group = parser.add_argument_group("exploration benchmark (docs/benchmark.md)")
    options.scene_specs(group)
    group.add_argument("--methods", default="frontiernet,classic",
                       help="comma-separated methods (default frontiernet,classic; see `frontiernet explore -h`)")
    group.add_argument("--starts", type=int, default=3, help="start poses per scene (sampled once, shared)")
    group.add_argument("--scene-starts", action="store_true",
                       help="use the start positions a scene ships first (KTH plan folders: MapEx's)")
    group.add_argument("--repeats", type=int, default=3, help="runs per start and method (seeds seed..seed+R-1)")
    group.add_argument("--max-steps", type=int,
                       help="one fixed step budget for every scene (default: scene-sized budgets, the paper's "
                            "protocol: configs/bench.yaml budget, from each scene's explorable floor area)")
    group.add_argument("--out", type=options.output_path,
                       help="output folder (resumable: finished runs are not redone)")
    group.add_argument("--report", action="store_true",
                       help="with --out only: rebuild results.csv, table.md, table_readme.md (the README's results "
                            "table) and the plots from the runs finished so far, running nothing (safe while the "
                            "benchmark runs)")
    group.add_argument("--pack", action="store_true",
                       help="with --out only: move the finished runs' metrics.json into one compressed file per "
                            "scene and method (runs/<scene>/<method>.jsonl.gz), which --report and a resumed "
                            "benchmark read; runs nothing (before --report when both are given)")
    group.add_argument("--redo-changed", action="store_true",
                       help="resume a benchmark whose settings changed only where some of its runs alone read "
                            "them (map.monocular_*, a source's depth.* section: that source's runs; a method's "
                            "own section, nbvp.*, omniscient.*: that method's runs): those runs are discarded "
                            "and run again, the others kept")
    options.parallel(group)
    group.add_argument("--seed", type=int, help="seed of the start poses and runs (default: run.seed)")
    options.model_option(group, what="model file of the learned methods")
    group.add_argument("--depth", help="depth source of every run (default: run.depth), or a comma list of "
                                       "sources, e.g. gt,emulated: every run once per source, from the same "
                                       "starts and seeds, with the monocular penalty in table.md")
    options.config_file(group, options.EXPLORE_CONFIG)
    options.config_overrides(group, "planner.clearance_m=0.3 depth.emulated.scale_per_frame=false", option=True)
    # what --pack and --report, which read the folder alone, refuse (they would ignore it)
    parser.set_defaults(run_option_defaults=options.option_defaults(group._group_actions,
                                                                    skip=("out", "pack", "report")))


def _refuse_run_options(args, what: str) -> None:
    """InputError naming the first option of a benchmark run given to `what` (``--pack``, ``--report``)."""
    from ..errors import InputError

    given = options.given_options(args, args.run_option_defaults)
    if given:
        raise InputError(f"{what} reads the benchmark folder (--out) alone, so {given[0]} would "
                         "be ignored; leave it out (the folder's plan.json holds the run's settings)")


def _refuse_bench_yaml_keys(overrides) -> None:
    """InputError naming a ``--set`` key of configs/bench.yaml (``budget.*``, ``report.*``...): the benchmark
    reads that file itself, and ``--set`` changes the runs' config (was "unknown config key 'budget'")."""
    from ..config import load_config
    from ..errors import InputError

    own = set(load_config("bench"))
    for item in overrides:
        key = item.split("=", 1)[0].strip()
        if key.split(".")[0] in own:
            raise InputError(f"--set {item}: {key} is a setting of configs/bench.yaml, which the benchmark reads "
                             "itself (--set and --config set the runs' config: configs/explore.yaml and its sections); "
                             "edit that file" + (", or fix one budget for every scene with --max-steps N"
                                                 if key.startswith("budget") else ""))


def run_exploration_benchmark(args) -> int:
    from ..benchmark import main, pack, report
    from ..benchmark.readme_table import write_readme_table
    from ..errors import InputError
    from ..exploration.run import load_run_config

    if args.pack or args.report:
        _refuse_run_options(args, "--pack" if args.pack else "--report")
    if args.pack:
        if not args.out:
            raise InputError("--pack needs --out DIR, the benchmark folder")
        packed = pack(args.out)
        rewritten = f", {len(packed['rewritten'])} older pack(s) rewritten in today's form" if packed["rewritten"] else ""
        print(f"bench: packed {packed['runs']} run(s) into {len(packed['packs'])} file(s){rewritten}; "
              f"{packed['packed']} runs packed in {args.out}/runs; the plan in {packed['plan']}")
        if not args.report:
            return 0
    if args.report:
        if not args.out:
            raise InputError("--report needs --out DIR, the benchmark folder")
        result = report(args.out)
        readme = write_readme_table(args.out, result["rows"])  # the pages' results table (docs/benchmark.md)
        print(Path(result["table"]).read_text())
        written = f"{result['table']}, {readme}" if readme else result["table"]
        print(f"bench: report of {len(result['rows'])} finished runs ({result['pending']} not yet): {result['results']}, "
              f"{written}, {len(result['plots'])} coverage plot(s) in {args.out}")
        return 0
    if not args.scenes:  # (a benchmark subcommand sets its own func)
        raise InputError("give a benchmark (render, map, explore, ...) or --scenes for the exploration benchmark")
    if not args.out:
        raise InputError("the exploration benchmark needs --out DIR")
    _refuse_bench_yaml_keys(args.set)
    options.refuse_contradictions(args.set, {"run.seed": (f"--seed {args.seed}", args.seed),
                                             "run.depth": (f"--depth {args.depth}", args.depth)})
    conf = load_run_config(args.config, args.set)
    if conf.run.max_steps != load_run_config().run.max_steps:  # (set by --config or --set: read by no run here)
        raise InputError(f"run.max_steps={conf.run.max_steps}: the benchmark gives each scene its budget "
                         "(configs/bench.yaml budget), or one fixed budget with --max-steps N; use that instead")
    methods = [m.strip() for m in args.methods.split(",")]  # (an empty item is refused by main, as --depth's)
    if args.redo_changed:  # (a typo in --out started a new benchmark without a word: as datagen --resume says)
        from ..benchmark.store import plan_file

        if plan_file(args.out) is None:
            print(f"bench: note: --redo-changed: {args.out} holds no benchmark yet (no plan.json), so there is "
                  "nothing to redo; starting a new one")
    result = main(conf, args.scenes, methods, args.out, starts=args.starts, repeats=args.repeats,
                  max_steps=args.max_steps, workers=args.workers, backend=args.backend, seed=args.seed,
                  model=args.model, depth=args.depth, scene_starts=args.scene_starts,
                  redo_changed=args.redo_changed, progress=True)
    failed = sum(row["status"] != "done" for row in result["rows"])
    copies = sum(bool(row["copy_of"]) for row in result["rows"])
    copied = f", {copies} identical repeats taken from repeat 0" if copies else ""
    print(Path(result["table"]).read_text())
    print(f"bench: {len(result['rows'])} runs ({failed} failed{copied}) in {result['wall_s']} s; "
          f"{result['results']}, {result['table']}, {len(result['plots'])} coverage plot(s) in {args.out}")
    if failed:  # the others' results are written; exit 1 says not all ran (their errors: OUT/failed/)
        print(f"frontiernet bench: {failed} of {len(result['rows'])} runs failed; their errors are in "
              f"{one_line(str(Path(args.out) / 'failed'))}/", file=sys.stderr)
        return 1
    return 0


def scene_benchmark(actions, name: str, help_text: str, func):
    """A benchmark subcommand with the options every benchmark of one scene takes (--scene,
    --json), run by `func`; also ``datagen bench``'s."""
    parser = actions.add_parser(name, help=help_text)
    options.benchmark_scene(parser)
    options.json_only(parser)
    parser.set_defaults(func=func)
    return parser


COUNT_LIMITS = {"batch": 1024, "frames": 10_000, "views": 10_000, "repeats": 10_000}
"""The largest count each hot-path benchmark option takes (``--steps``: the run's ``MAX_STEPS``): a render
batch of 1,024 poses is already past where batching pays, and 10,000 timed repetitions past where a median
moves; more is a typo, which would otherwise run until killed or fail late for want of camera poses."""


def counts(**options: int) -> None:
    """InputError naming the first option (``--name``) of `options` that is not an integer in [1, its limit]
    (:data:`COUNT_LIMITS`)."""
    from ..errors import whole_number
    from ..exploration.run import MAX_STEPS

    for name, value in options.items():
        whole_number(value, f"--{name}", 1, COUNT_LIMITS.get(name, MAX_STEPS))


def run_render(args) -> int:
    from ..benchmark.perf import bench_render

    counts(repeats=args.repeats, batch=args.batch)
    result = bench_render(args.scene, args.repeats, args.batch, args.raycast)
    if args.json:
        print(json.dumps(result))
        return 0
    width, height = result["resolution"]
    print(f"bench render: {result['scene']} ({result['triangles']} triangles), {width}x{height}, "
          f"median of {args.repeats}")
    print(f"  bare cast_rays ({result['raycast_backend']:6s}) {result['cast_rays_ms']:5.2f} ms   1.00x (baseline)")
    print(f"  render (rgb+depth+n)  {result['render_ms']:8.2f} ms   {result['render_over_cast']:.2f}x   goal <= 1.5x")
    print(f"  batched x{result['batch']} per frame  {result['batched_render_ms_per_frame']:8.2f} ms   "
          f"{result['batched_render_over_cast']:.2f}x of a batched cast")
    print(f"  scene load            {result['load_s'] * 1e3:8.0f} ms   {result['load_in_casts']:.1f} casts")
    print(f"  voxelisation          {result['voxelize_s'] * 1e3:8.0f} ms   {result['voxelize_in_casts']:.1f} casts "
          f"({result['explorable_m3']} m^3 explorable)")
    return 0


def run_map(args) -> int:
    from ..benchmark.perf import bench_map
    from ..config import load_config

    counts(frames=args.frames, views=args.views)
    result = bench_map(args.scene, args.frames, args.views)
    if args.json:
        print(json.dumps(result))
        return 0
    width, height = result["resolution"]
    print(f"bench map: {result['scene']}, {width}x{height}, median of {result['frames']} frames")
    explore = load_config("explore")
    configured = int(explore.map.ray_stride_px)
    rows = [("render (rgb+depth+n)", result["render_ms"], 1.0, "(baseline)")]
    for stride in (1, 2, 4):
        default = " (config)" if stride == configured else ""
        rows.append((f"map update, stride {stride}{default}", result[f"integrate_stride{stride}_ms"],
                     result[f"integrate_stride{stride}_over_render"], "goal < 1x"))
    rows.append((f"map update, stride {configured}, edges", result["integrate_edges_ms"],
                 result["integrate_edges_over_render"], "depth edges left out (monocular depth)"))
    rows.append((f"visible_known_volume x{result['views']}", result["visible_known_volume_ms"],
                 result["visible_known_volume_over_render"],
                 f"({explore.tracking.gain_view.width_px} px views, {result['known_m3']} m^3 known)"))
    for label, ms, ratio, note in rows:
        print(f"  {label:<30s}{ms:8.2f} ms   {ratio:5.2f}x   {note}")
    return 0


def run_explore(args) -> int:
    """Explore ``--steps`` steps and print each stage's mean time per step as a ratio to the render
    of the same run (:func:`~frontiernet.benchmark.perf.bench_explore`)."""
    from ..benchmark.perf import bench_explore, bench_explore_against
    from .explore import model_contradictions

    counts(steps=args.steps)
    options.refuse_contradictions(args.overrides, model_contradictions(args.method, args.model, args.depth))
    if args.against is not None:
        return _print_explore_against(bench_explore_against(args.scene, args.against, args.method, args.steps,
                                                            args.depth, args.model, args.overrides), args)
    result = bench_explore(args.scene, args.method, args.steps, args.depth, args.model, args.overrides)
    if args.json:
        print(json.dumps(result))
        return 0
    print(f"bench explore: {result['scene']}, {args.method}, {result['depth']} depth, {result['steps']} steps, "
          f"mean per step")
    for stage, ms in result["mean_ms"].items():
        print(f"  {stage:<12} {ms:8.2f} ms   {result['over_render'][stage]:6.2f}x of a render")
    print(f"  step without motion {result['step_ms_without_motion']:.1f} ms; image to 3D frontiers "
          f"(perception + anchoring) {result['image_to_frontiers_hz']} Hz   goal >= 5 Hz")
    return 0


def _print_explore_against(result: dict, args) -> int:
    """``bench explore --against``: both scenes' stage costs and their ratios."""
    if args.json:
        print(json.dumps(result))
        return 0
    scene, base = result["scene"], result["against"]
    print(f"bench explore: {args.method}, {scene['depth']} depth: {scene['scene']} ({scene['steps']} steps) against "
          f"{base['scene']} ({base['steps']} steps), mean per step")
    for stage, ms in scene["mean_ms"].items():
        ratio = result["stage_ratio"][stage]
        print(f"  {stage:<12} {ms:8.2f} ms against {base['mean_ms'].get(stage, 0.0):8.2f} ms   "
              f"{'-' if ratio is None else f'{ratio:.2f}x'}")
    print(f"  step without motion {scene['step_ms_without_motion']:.1f} ms against {base['step_ms_without_motion']:.1f} ms:"
          f" {result['step_ratio']:.2f}x   goal <= 1.5x")
    return 0

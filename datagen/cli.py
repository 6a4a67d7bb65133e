"""``frontiernet datagen``: make a dataset, look at it, time it.

Registered with the ``frontiernet`` command through the ``frontiernet.commands`` entry
point (``frontiernet`` itself never imports ``datagen``).

  frontiernet datagen --scenes SPEC [SPEC ...] --views-per-scene N --out DIR
                      [--workers W] [--backend local|ray] [--seed S] [--resume] [--config FILE]
  frontiernet datagen preview DIR [--n 16] [--out DIR/preview]
  frontiernet datagen bench [--scene SPEC] [--views N] [--raycast ENGINE ...]
  frontiernet datagen consistency --scenes SPEC [SPEC ...] [--views-per-scene N] [--json FILE [--force]]
  frontiernet mapgen --scenes SPEC [SPEC ...] --out DIR [...]   (datagen/mapgen_cli.py)
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from frontiernet.cli import options
from frontiernet.cli.bench import scene_benchmark


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "datagen", help="generate training data (frontier distance fields, gain classes) from scenes",
        description="Generate a sharded FrontierNet dataset from scenes (docs/design.md section 3). "
                    "Subcommands: 'preview DIR' draws contact sheets, 'bench' times one view, "
                    "'consistency' measures how well the gain labels agree with themselves.")
    options.scene_specs(parser)
    parser.add_argument("--views-per-scene", type=int, metavar="N", help="views per scene")
    parser.add_argument("--out", metavar="DIR", type=options.output_path, help="dataset folder")
    options.parallel(parser)
    options.dataset_run(parser)
    options.config_file(parser, "configs/sim.yaml and configs/datagen.yaml, and scenes.yaml under section scenes:")
    options.config_overrides(parser, "writer.shard_size=16", option=True)
    options.no_progress(parser)
    parser.set_defaults(func=run_generate)
    # what the actions refuse when given before them (they would drop it: options.Subcommands)
    parser.set_defaults(own_option_defaults=options.option_defaults(parser._actions))
    actions = parser.add_subparsers(dest="action", metavar="ACTION", parser_class=type(parser),
                                    action=options.Subcommands)
    preview = actions.add_parser("preview", help="contact sheets of samples (RGB, depth, F_p, F_d, F, D, gain)")
    preview.add_argument("dataset", metavar="DIR", type=options.input_path("dataset"),
                         help="dataset folder (or one shard .zip)")
    preview.add_argument("--n", type=int, default=16, help="number of samples (spread over the dataset)")
    preview.add_argument("--out", metavar="DIR", type=options.output_path, help="where to write (default: DIR/preview)")
    preview.set_defaults(func=run_preview)
    bench = scene_benchmark(actions, "bench", "cost of one ground-truth view in depth renders, views/s per core",
                            run_bench)
    bench.add_argument("--views", type=int, default=20, help="views to time (default 20)")
    bench.add_argument("--raycast", nargs="+", metavar="ENGINE", choices=("open3d", "embree"),
                       help="ray-cast engines to time, the first is the baseline (default: every one importable)")
    consistency = actions.add_parser(
        "consistency", help="the gain labels' own agreement (resampled gain, nearby views): the ceiling of any Dice",
        description="Label views as datagen does, then label each view again with a different random "
                    "generator (the gain is measured at sampled frontier voxels) and label a view a small step "
                    "away (configs/label_consistency.yaml); report the Dice between the labelings, computed "
                    "as frontiernet evaluate computes a model's.")
    options.scene_specs(consistency, required=True)
    consistency.add_argument("--views-per-scene", type=int, default=24, metavar="N",
                             help="views per scene (default 24)")
    consistency.add_argument("--seed", type=int, default=0, help="run seed (default 0)")
    options.config_file(consistency, "configs/sim.yaml, datagen.yaml and label_consistency.yaml")
    options.config_overrides(consistency, "consistency.translation_m=0.2", option=True)
    options.json_file(consistency, "the figures (confusion matrices too)")
    consistency.add_argument("--force", action="store_true", help="replace the --json file if it exists (refused without it)")
    consistency.set_defaults(func=run_consistency)
    from .mapgen_cli import add_parser as add_mapgen_parser

    add_mapgen_parser(subparsers)  # frontiernet mapgen: the map predictors' data (docs/mapprediction.md)


def _refuse_options_before(args) -> None:
    """InputError naming the options of ``frontiernet datagen`` given before the action `args.action`
    (``datagen --scenes S preview DIR``: dropped without a word before;
    :class:`~frontiernet.cli.options.Subcommands`)."""
    from frontiernet.errors import InputError

    message = options.options_before_subcommand(args, "datagen")
    if message:
        raise InputError(message)


def run_generate(args) -> int:
    from frontiernet.errors import InputError

    from .config import load_datagen_config
    from .generate import generate
    from .summary import failed_scenes_exit

    missing = [flag for flag, value in (("--scenes", args.scenes), ("--views-per-scene", args.views_per_scene),
                                        ("--out", args.out)) if value is None]
    if missing:
        raise InputError(f"missing {', '.join(missing)} (see frontiernet datagen --help)")
    conf = load_datagen_config(args.config, args.set)
    summary = generate(args.scenes, args.views_per_scene, args.out, conf, seed=args.seed, workers=args.workers,
                       backend=args.backend, resume=args.resume, progress=not args.no_progress)
    print_summary(summary, Path(args.out))
    return failed_scenes_exit(summary["failed_scenes"], "datagen",
                              f"no view was made of it, the other scenes' views are in {args.out}")


def print_summary(summary: dict, out: Path) -> None:
    """Print a run's summary in a few lines (the full one is in out/summary.json)."""
    hist = summary["gain_class_pixels"]
    gain_pixels = sum(hist[1:]) if hist else 0
    shares = " ".join(f"{100 * c / gain_pixels:.1f}" for c in hist[1:]) if gain_pixels else "-"
    print(f"datagen: {summary['views']} views of {summary['scenes']} scene(s) in {out} "
          f"({summary['shards']}/{summary['shards_planned']} shards)")
    print(f"  this run: {summary['views_this_run']} views in {summary['seconds']:.1f} s "
          f"({summary['views_per_second']:.2f} views/s)")
    print(f"  views with frontier pixels {100 * summary['frontier_view_fraction']:.1f} %, frontier pixels "
          f"{100 * summary['frontier_pixel_ratio']:.2f} % of all, {summary['candidates_per_view']:.2f} "
          "candidates per view")
    print(f"  gain classes 1-{max(len(hist) - 1, 1)} (% of gain pixels): {shares}")
    for failure in summary["failed_scenes"]:  # (the first is also the error line on stderr: run_generate)
        print(f"  failed: {failure['scene']}: {failure['error']}")
    if summary["views"] and not summary["frontier_pixel_ratio"]:  # (a model learns no frontier from it)
        print(f"datagen: warning: no view of {out} has a frontier pixel: nothing to learn frontiers from (are the "
              "ground_truth settings, the camera or the scenes what you meant?)", file=sys.stderr)


def run_preview(args) -> int:
    from frontiernet.errors import InputError

    from .dataset import open_dataset
    from .preview import write_previews

    _refuse_options_before(args)
    if args.n < 1:
        raise InputError(f"--n must be a positive integer, got {args.n}")
    dataset = open_dataset(args.dataset)
    if len(dataset) == 0:  # (was "no samples yet" of a dataset whose shards were deleted too)
        from .generate import missing_shards

        missing = missing_shards(Path(args.dataset), dataset.info) if Path(args.dataset).is_dir() else []
        raise InputError(f"{args.dataset}: the dataset has no samples" + (
            f": the {len(missing)} shard(s) its dataset.json plans are not in {Path(args.dataset) / 'shards'} "
            "(deleted, or a run that has made none yet)" if missing else " yet"))
    root = Path(args.dataset)
    out = Path(args.out) if args.out else (root if root.is_dir() else root.parent) / "preview"
    max_depth = float(dataset.records[0].get("max_depth", 3.5))
    paths = write_previews(dataset, out, n=args.n, max_depth=max_depth, truncation_px=dataset.truncation_px)
    print(f"datagen preview: {len(paths)} contact sheet(s) in {out}")
    return 0


def run_bench(args) -> int:
    from frontiernet.cli.bench import counts
    from frontiernet.errors import InputError

    from .bench import bench_ground_truth

    _refuse_options_before(args)
    counts(views=args.views)  # (100000 ran for hours)
    twice = [name for index, name in enumerate(args.raycast or []) if name in args.raycast[:index]]
    if twice:
        raise InputError(f"--raycast names {twice[0]} twice: each engine is timed once (the first against the "
                         "others), give each at most once")
    result = bench_ground_truth(args.scene, args.views, args.raycast)
    if args.json:
        print(json.dumps(result))
        return 0
    base = result["baseline"]
    print(f"bench datagen: {result['scene']}, {result['resolution'][0]}x{result['resolution'][1]}, "
          f"{result['views']} views (median per view); baseline: a bare {base} cast_rays")
    for name, figures in result["backends"].items():
        render = figures["render_ms"]
        print(f"  [{name}] ray cast (depth render) {render:8.1f} ms   {figures['render_over_baseline']:.2f}x")
        print(f"  [{name}] ground-truth view       {figures['view_ms']:8.1f} ms   "
              f"{figures['view_in_baseline_renders']:.2f}x   ({figures['view_in_renders']:.2f}x its own cast; "
              "goal < 10x)")
        for stage, ms in figures["stages_ms"].items():
            print(f"      {stage:<22} {ms:8.1f} ms   {ms / render:.2f}x its cast")
        print(f"  [{name}] distance_to_surface x{result['distance_queries']} {figures['distance_ms']:6.2f} ms; "
              f"engine build {figures['build_s']:.2f} s")
        print(f"  [{name}] views per second per core {figures['views_per_second_per_core']:.2f}   "
              f"{figures['views_per_second_per_core_over_baseline']:.2f}x")
    agreement = result["agreement"]
    if agreement["compared"]:
        print(f"  {agreement['compared']}: {agreement['hit_mask_mismatched_pixels']} of {agreement['pixels']} "
              f"pixels differ in the hit mask; hit distances within "
              f"{agreement['max_hit_distance_difference_mm']:.4f} mm; "
              f"{agreement['common_hits_on_another_triangle']} hits on another (coplanar) triangle")
    print(f"  {result['threads']} thread(s) on {result['cores']} core(s); scene setup (load, voxels, generator) "
          f"{result['setup_s']:.2f} s; peak memory of this process {result['peak_rss_mb']:.0f} MB")
    return 0


def scene_paths(specs) -> list[str]:
    """The files or folders that scene specs name (``floorplan:plan.png?resolution=0.05``: ``plan.png``), where
    they exist: the inputs an output must not replace."""
    import os

    paths = []
    for spec in specs or ():
        text = str(spec).split("?", 1)[0]
        paths += [path for path in (text, text.split(":", 1)[-1]) if path and os.path.exists(path)]
    return paths


def run_consistency(args) -> int:
    from rich.progress import Progress

    from frontiernet.io import check_not_an_input, check_output_file, write_json

    from .consistency import format_consistency, label_consistency, load_consistency_config

    _refuse_options_before(args)
    if args.json:
        check_not_an_input(args.json, [(args.config, "the config file"),
                                       *((path, "a scene") for path in scene_paths(args.scenes))], "--json")
        check_output_file(args.json, args.force, writable="--json")  # (a folder: now, not after the labelling)
    conf = load_consistency_config(args.config, args.set)
    with Progress(transient=True) as bar:
        task = bar.add_task("labelling", total=None)
        result = label_consistency(args.scenes, args.views_per_scene, conf, seed=args.seed,
                                   progress=lambda done, total: bar.update(task, completed=done, total=total))
    print(format_consistency(result))
    if args.json:
        write_json(args.json, result)
    return 0

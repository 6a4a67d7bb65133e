"""``frontiernet mapgen``: its parser (registered by :mod:`datagen.cli`) and runner; the work is
:mod:`datagen.mapgen`'s, imported when the command runs (every ``frontiernet`` start builds the parser).

  frontiernet mapgen --scenes SPEC [SPEC ...] --out DIR [--workers W] [--backend local|ray] [--seed S]
                     [--resume] [--config FILE] [--set KEY=VALUE ...] [--no-progress]
"""

from __future__ import annotations

import sys

from frontiernet.cli import options
from frontiernet.errors import InputError


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "mapgen", help="generate map-prediction data (partial maps along exploration runs, true occupancy)",
        description="Explore each scene with the runs of configs/mapgen.yaml and keep the robot's map every "
                    "few steps, with the scene's true voxels: the data of the map predictors "
                    "(docs/mapprediction.md). Writes DIR/dataset.json, DIR/shards/*.zip, DIR/summary.json.")
    options.scene_specs(parser, required=True)
    parser.add_argument("--out", required=True, metavar="DIR", type=options.output_path, help="dataset folder")
    options.parallel(parser)
    options.dataset_run(parser)
    options.config_file(parser, "configs/mapgen.yaml and configs/explore.yaml (with its sections sim:, depth:, "
                                "scenes:)")
    options.config_overrides(parser, "mapgen.max_steps=200 mapgen.snapshot_every_steps=20", option=True)
    options.no_progress(parser)
    parser.set_defaults(func=run_mapgen)


def run_mapgen(args) -> int:
    from .mapgen import generate_maps, load_mapgen_config

    conf = load_mapgen_config(args.config, args.set)
    summary = generate_maps(args.scenes, args.out, conf, seed=args.seed, workers=args.workers, backend=args.backend,
                            resume=args.resume, progress=not args.no_progress)
    print(f"mapgen: {summary['snapshots']} snapshots ({summary['frontier_pieces']} frontier pieces) of "
          f"{summary['runs']}/{summary['runs_planned']} runs, {summary['scenes']} scene(s) in {args.out}")
    print(f"  this session: {summary['runs_this_session']} runs in {summary['seconds']:.0f} s"
          + (f" ({summary['seconds_per_run']:.1f} s per run)" if summary["seconds_per_run"] else ""))
    for failure in summary["failed_scenes"]:  # (the first is also the error line on stderr)
        print(f"  failed: {failure['scene']}: {failure['error']}")
    failed = summary["failed_scenes"]
    if not failed:
        return 0
    others = f" (and {len(failed) - 1} more scene(s), listed above and in summary.json)" if len(failed) > 1 else ""
    text = (f"{failed[0]['scene']}: {failed[0]['error']}{others}; the other runs are in {args.out}: fix it and rerun "
            f"with --resume, or leave it out (with another --out)")
    if all(failure["bad_input"] for failure in failed):
        raise InputError(text)
    print(f"frontiernet mapgen: failed: {text}", file=sys.stderr)  # a fault of ours in a scene: exit 1
    return 1

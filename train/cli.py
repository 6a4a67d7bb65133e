"""``frontiernet train`` and ``frontiernet evaluate`` (registered through the
``frontiernet.commands`` entry point; ``frontiernet`` itself never imports ``train``).

  frontiernet train --config configs/train.yaml [key=value ...] [--resume [CKPT]]
  frontiernet evaluate MODEL --data DIR [--scenes SPEC ...] [--all] [--max-samples N] [--json FILE [--force]]
  frontiernet train --config configs/train_seer.yaml | train_mapex.yaml data.path=DIR   (map predictors)
  frontiernet mapeval PREDICTOR --data DIR [--json FILE]                               (train/mapeval.py)
"""

from __future__ import annotations

import json

from frontiernet.cli import options


def add_parser(subparsers) -> None:
    train = subparsers.add_parser(
        "train", help="train FrontierNet on a datagen dataset (Lightning)",
        description="Train FrontierNet (configs/model.yaml + configs/train.yaml). Outputs in <out>/<name>/: "
                    "checkpoints/last.ckpt and best.ckpt, metrics.csv, model.safetensors, summary.json.")
    options.config_file(train, "configs/train.yaml (and model.*)")
    options.config_overrides(train, "data.path=DIR trainer.max_epochs=2 model.network.inputs=rgb")
    train.add_argument("--resume", nargs="?", const="last", metavar="CKPT",
                       type=options.optional_input_path("checkpoint", "--resume"),
                       help="continue the run's last checkpoint (or the given one)")
    options.no_progress(train)
    train.set_defaults(func=run_train)

    evaluate = subparsers.add_parser(
        "evaluate", help="Table II metrics of a model on a dataset (held-out scenes)",
        description="Distance-field error (px), gain Dice and frontier precision/recall next to the "
                    "depth-discontinuity baseline, on the model's held-out scenes by default.")
    options.model_file(evaluate)
    evaluate.add_argument("--data", required=True, metavar="DIR", type=options.input_path("dataset folder"),
                          help="a frontiernet datagen dataset")
    evaluate.add_argument("--scenes", nargs="+", metavar="SPEC", help="evaluate on these scenes")
    evaluate.add_argument("--all", action="store_true", help="evaluate on every scene of the dataset")
    evaluate.add_argument("--max-samples", type=int, metavar="N", help="at most N views (evenly spread)")
    evaluate.add_argument("--size", type=int, metavar="PX", help="resolution (default: the model's, 320)")
    evaluate.add_argument("--depth", default="ground_truth", metavar="SOURCE",
                          help="depth prior for the model and the F_d baseline: ground_truth or gt (default), "
                               "emulated (monocular-like) or another source of configs/depth.yaml")
    evaluate.add_argument("--workers", type=int, default=0, metavar="W",
                          help="processes decoding the dataset (default 0: in this process)")
    options.json_file(evaluate, "the metrics")
    evaluate.add_argument("--force", action="store_true", help="replace the --json file if it exists (refused without it)")
    evaluate.set_defaults(func=run_evaluate)
    from .mapeval import add_parser as add_mapeval_parser

    add_mapeval_parser(subparsers)  # frontiernet mapeval: the map predictors' quality (docs/mapprediction.md)


def run_train(args) -> int:
    from .mapprediction import is_map_config, run_map_train

    if is_map_config(args.config):  # configs/train_seer.yaml, train_mapex.yaml: a map predictor (docs/mapprediction.md)
        return run_map_train(args)
    from .config import load_train_config
    from .main import main

    conf = load_train_config(args.config, args.overrides)
    out = main(conf, resume=args.resume, progress=not args.no_progress)
    summary = json.loads((out / "summary.json").read_text())
    print(f"trained {summary['steps']} steps ({summary['epochs']} epochs) in {summary['seconds_this_session']:.0f} s "
          f"on {summary['hardware']}")
    print(f"model: {out / 'model.safetensors'}  (frontiernet evaluate {out / 'model.safetensors'} "
          f"--data {conf.data.path})")
    return 0


def run_evaluate(args) -> int:
    from frontiernet.depth import check_depth_files, known_source
    from frontiernet.errors import InputError, cpu_count_option, whole_number
    from frontiernet.io import check_not_an_input, check_output_file, write_json
    from frontiernet.model.files import torch_model_file
    from frontiernet.model.predictor import input_size

    if args.max_samples is not None:
        whole_number(args.max_samples, "--max-samples", 1)
    cpu_count_option(args.workers, "--workers", 0)
    if args.size is not None:
        input_size(args.size, "--size")
    if args.all and args.scenes:
        raise InputError("--all and --scenes exclude each other: give one")
    if args.scenes:  # ('' was refused after the data load, "scene(s) not in the dataset: "; a repeat counted twice)
        empty = next((index for index, scene in enumerate(args.scenes) if not scene.strip()), None)
        if empty is not None:
            raise InputError(f"--scenes: an empty scene spec (item {empty + 1} of the {len(args.scenes)} given); give "
                             "the dataset's scene specs as separate words, e.g. --scenes procedural:3 procedural:4")
        from .evaluate import expand_scene_ranges

        args.scenes = expand_scene_ranges(dict.fromkeys(scene.strip() for scene in args.scenes))  # (procedural:3-4)
    if args.json:
        # never over an input (the dataset's own dataset.json was replaced), nor over a file without --force
        check_not_an_input(args.json, [(args.model, "the model file"), (args.data, "the dataset (--data)")], "--json")
        check_output_file(args.json, args.force, writable="--json")  # (a folder: now, not after the evaluation)
    from frontiernet.config import load_config

    # (an unknown one was refused after the data load; its options are configs/depth.yaml's, as evaluate reads them)
    check_depth_files(known_source(args.depth, "--depth"), load_config("depth"))
    torch_model_file(args.model)  # before the data load
    from rich.progress import Progress

    from .evaluate import evaluate, format_report

    with Progress(transient=True) as bar:
        task = bar.add_task("evaluating", total=None)
        result = evaluate(args.model, args.data, scenes=args.scenes, all_scenes=args.all,
                          max_samples=args.max_samples, size=args.size, depth=args.depth, workers=args.workers,
                          progress=lambda done, total: bar.update(task, completed=done, total=total))
    print(format_report(result))
    if args.json:
        write_json(args.json, result)
    return 0

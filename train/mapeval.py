"""``frontiernet mapeval``: a map predictor's quality on held-out scenes, beside the two simple predictions
(:mod:`frontiernet.mapprediction.quality`), per source of scenes (procedural, KTH plans, ...).

For every snapshot of a ``frontiernet mapgen`` dataset (scenes the predictor was neither trained nor
validated on), the unknown cells within ``--radius-m`` (3 m) of a frontier are scored: for a ``seer``
predictor in the crops around the snapshot's largest frontier pieces (as it is used), for a ``mapex``
predictor over the whole top-down map. The simple predictions see what the predictor sees (the crop, or
the top-down map). A mapex ensemble's variance is summarised where its mean is right and where it is
wrong (MapEx explores where the variance is high: it should be high where the mean is wrong).

  frontiernet mapeval PREDICTOR --data DIR [--max-snapshots N] [--crops-per-snapshot N] [--radius-m R]
                      [--threads T] [--json FILE]
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from frontiernet.cli import options

PREDICTIONS = ("predictor", "unknown=free", "continue wall")


def scene_source(spec: str) -> str:
    """The source a scene is reported under: ``procedural``, ``kth`` (a KTH / MapEx floor-plan folder), or
    its spec's source (``mesh``, ``hm3d``, ``floorplan``)."""
    from frontiernet.scenes.spec import parse_spec

    parsed = parse_spec(spec)
    if parsed.source == "floorplan" and (Path(parsed.argument) / "valid_space.npy").is_file():
        return "kth"
    return parsed.source


def evaluate_maps(predictor_path, data, *, max_snapshots: int | None = None, crops_per_snapshot: int | None = None,
                  radius_m: float = 3.0, progress=None) -> dict:
    """Scores per source and prediction (module docstring); a JSON-able dict. `crops_per_snapshot`: a seer
    predictor's (None: 4).

    Raises:
        InputError: a predictor file that does not load, `crops_per_snapshot` given for a mapex predictor
            (which scores the whole top-down map), a dataset of another map resolution (its ``voxel_size``),
            no held-out snapshot.
    """
    from datagen.mapshards import check_voxel_size, open_map_dataset, read_map_dataset_info
    from frontiernet.errors import InputError
    from frontiernet.mapprediction import (band_layers, confusion, crop_corner, load_predictor, near_frontier,
                                           predict_free, predict_wall, states_from_masks, take_crop, topdown_labels,
                                           topdown_states, truth_labels)
    from frontiernet.mapping.occupancy import UNKNOWN
    from frontiernet.mapprediction.encodings import IGNORE

    predictor = load_predictor(predictor_path)
    if crops_per_snapshot is not None and predictor.kind != "seer":
        raise InputError(f"--crops-per-snapshot applies to seer predictors, and {predictor_path} is a "
                         f"{predictor.kind} predictor (scored over the whole top-down map): leave it out")
    crops_per_snapshot = 4 if crops_per_snapshot is None else crops_per_snapshot
    check_voxel_size(read_map_dataset_info(data), data, predictor.spec.voxel_size,
                     f"the predictor's voxel_size ({predictor_path})")
    if radius_m < predictor.spec.voxel_size:  # (no unknown cell lies nearer a frontier than one cell: a table of NaN)
        raise InputError(f"--radius-m {radius_m:g}: less than one map cell ({predictor.spec.voxel_size:g} m), so no "
                         f"unknown cell is that near a frontier; give at least {predictor.spec.voxel_size:g}")
    dataset = open_map_dataset(data)
    seen = set(predictor.info.get("train_scenes", [])) | set(predictor.info.get("val_scenes", []))
    held = [i for i, (shard, _) in enumerate(dataset.snapshots) if dataset.metas[shard]["scene"] not in seen]
    if not held:
        raise InputError(f"{data}: every scene of the dataset was seen in training; evaluate on other scenes")
    if max_snapshots and len(held) > max_snapshots:
        held = [held[int(i)] for i in np.linspace(0, len(held) - 1, int(max_snapshots))]
    counts: dict[str, dict[str, np.ndarray]] = {}
    variance = {}  # source -> [sum where right, count right, sum where wrong, count wrong]
    voxel, threshold = predictor.spec.voxel_size, predictor.occupied_threshold
    labels_of: dict[int, np.ndarray] = {}
    crops = 0
    for done, index in enumerate(held):
        shard, record = dataset.snapshots[index]
        meta = dataset.metas[shard]
        source = scene_source(meta["scene"])
        if shard not in labels_of:
            labels_of.clear()
            labels_of[shard] = truth_labels(*dataset.truth(shard))
        states, labels = states_from_masks(*dataset.masks(index)), labels_of[shard]
        per_source = counts.setdefault(source, {name: np.zeros(4, np.int64) for name in PREDICTIONS})
        if predictor.kind == "seer":
            pieces = sorted(record["frontiers"], key=lambda piece: -piece[2])[:crops_per_snapshot]
            for x, y, _ in pieces:
                corner = crop_corner(meta["origin"], voxel, (x, y), predictor.spec.crop_shape, record["floor_z"])
                crop = take_crop(states, corner, predictor.spec.crop_shape, np.int8(UNKNOWN))
                truth = take_crop(labels, corner, predictor.spec.crop_shape, np.uint8(IGNORE))
                region = near_frontier(crop, voxel, radius_m, truth)
                guesses = (predictor.predict_crop_states(crop, voxel) > threshold, predict_free(crop),
                           predict_wall(crop, voxel, radius_m))
                for name, guess in zip(PREDICTIONS, guesses):
                    per_source[name] += confusion(guess, truth, region)
                crops += 1
        else:
            k0, k1 = band_layers(meta["origin"][2], voxel, meta["shape"][2], record["position"][2],
                                 predictor.spec.band_m)
            top, truth = topdown_states(states, k0, k1), topdown_labels(labels, k0, k1)
            region = near_frontier(top, voxel, radius_m, truth)
            mean, var = predictor.predict_topdown_states(top, voxel)
            guesses = (mean > threshold, predict_free(top), predict_wall(top, voxel, radius_m))
            for name, guess in zip(PREDICTIONS, guesses):
                per_source[name] += confusion(guess, truth, region)
            right = (guesses[0] == (truth == 1)) & region
            wrong = region & ~right
            sums = variance.setdefault(source, np.zeros(4))
            sums += [var[right].sum(), right.sum(), var[wrong].sum(), wrong.sum()]
        if progress is not None:
            progress(done + 1, len(held))
    return _report(predictor, predictor_path, data, counts, variance, held, dataset, seen, crops, radius_m)


def _report(predictor, predictor_path, data, counts, variance, held, dataset, seen, crops, radius_m) -> dict:
    from frontiernet.mapprediction import scores

    totals = {name: sum((c[name] for c in counts.values()), np.zeros(4, np.int64)) for name in PREDICTIONS}
    rows = {source: {name: scores(c[name]) for name in PREDICTIONS} for source, c in sorted(counts.items())}
    rows["all"] = {name: scores(totals[name]) for name in PREDICTIONS}
    result = {"predictor": str(predictor_path), "kind": predictor.kind, "members": predictor.spec.members,
              "data": str(data), "radius_m": radius_m, "occupied_threshold": predictor.occupied_threshold,
              "snapshots": len(held), "crops": crops,
              "scenes": sorted({dataset.metas[dataset.snapshots[i][0]]["scene"] for i in held}),
              "scenes_skipped_as_seen": sorted(set(dataset.scenes) & seen), "scores": rows}
    if variance:
        result["variance"] = {source: {"where_right": s[0] / s[1] if s[1] else math.nan,
                                       "where_wrong": s[2] / s[3] if s[3] else math.nan}
                              for source, s in sorted(variance.items())}
    return result


def format_report(result: dict) -> str:
    what = f"{result['crops']} crops of " if result["kind"] == "seer" else ""
    skipped = len(result["scenes_skipped_as_seen"])
    lines = [f"mapeval: {result['kind']} predictor {result['predictor']} on {result['data']}: {what}"
             f"{result['snapshots']} snapshots of {len(result['scenes'])} held-out scene(s)"
             + (f" ({skipped} seen in training skipped)" if skipped else ""),
             f"unknown cells within {result['radius_m']} m of a frontier; occupied above p = "
             f"{result['occupied_threshold']}",
             f"{'source':<11} {'prediction':<14} {'cells':>10} {'accuracy':>9} {'IoU occ':>8} {'IoU free':>9} "
             f"{'mIoU':>6}"]
    for source, row in result["scores"].items():
        for name, s in row.items():
            lines.append(f"{source:<11} {name:<14} {s['cells']:>10} {s['accuracy']:>9.3f} {s['iou_occupied']:>8.3f} "
                         f"{s['iou_free']:>9.3f} {s['miou']:>6.3f}")
    for source, v in result.get("variance", {}).items():
        lines.append(f"{source:<11} ensemble variance: {v['where_right']:.4f} where the mean is right, "
                     f"{v['where_wrong']:.4f} where it is wrong")
    return "\n".join(lines)


def add_parser(subparsers) -> None:
    """``frontiernet mapeval`` (registered by :mod:`train.cli`)."""
    parser = subparsers.add_parser(
        "mapeval", help="a map predictor's accuracy and IoU near frontiers on held-out scenes, with two baselines",
        description="Score a map predictor (frontiernet train --config configs/train_seer.yaml or train_mapex.yaml) "
                    "on a frontiernet mapgen dataset of scenes it never saw: the unknown space within 3 m of a "
                    "frontier, beside 'unknown = free' and 'continue the nearest wall', per source of scenes "
                    "(docs/mapprediction.md).")
    parser.add_argument("predictor", metavar="PREDICTOR", type=options.input_path("predictor file"),
                        help="predictor file (predictor.safetensors) or checkpoint (.ckpt)")
    parser.add_argument("--data", required=True, metavar="DIR", type=options.input_path("dataset folder"),
                        help="a frontiernet mapgen dataset")
    parser.add_argument("--max-snapshots", type=int, metavar="N", help="at most N snapshots (evenly spread)")
    parser.add_argument("--crops-per-snapshot", type=int, metavar="N",
                        help="seer: crops around the N largest frontier pieces of a snapshot (default 4)")
    parser.add_argument("--radius-m", type=float, default=3.0, help="scored: unknown cells this near a frontier (default 3)")
    parser.add_argument("--threads", type=int, metavar="T", help="torch threads (default: torch's)")
    options.json_file(parser, "the scores")
    parser.add_argument("--force", action="store_true", help="replace the --json file if it exists (refused without it)")
    parser.set_defaults(func=run_mapeval)


def run_mapeval(args) -> int:
    from frontiernet.errors import InputError, positive_number, whole_number
    from frontiernet.io import check_not_an_input, check_output_file, write_json

    import os

    for value, name, most in ((args.max_snapshots, "--max-snapshots", 10_000_000),
                              (args.threads, "--threads", 4 * (os.cpu_count() or 1))):
        if value is not None:
            whole_number(value, name, 1, most)
    if args.crops_per_snapshot is not None:
        whole_number(args.crops_per_snapshot, "--crops-per-snapshot", 1, 1000)
    if positive_number(args.radius_m, "--radius-m", "metres") > 100:
        raise InputError(f"--radius-m must be at most 100 metres, got {args.radius_m}")
    if args.json:
        check_not_an_input(args.json, [(args.predictor, "the predictor file"), (args.data, "the dataset (--data)")],
                           "--json")
        check_output_file(args.json, args.force, writable="--json")  # (a missing folder was found after the scoring)
    if args.threads:
        import torch

        torch.set_num_threads(args.threads)
    from rich.progress import Progress

    with Progress(transient=True) as bar:
        task = bar.add_task("scoring", total=None)
        result = evaluate_maps(args.predictor, args.data, max_snapshots=args.max_snapshots,
                               crops_per_snapshot=args.crops_per_snapshot, radius_m=args.radius_m,
                               progress=lambda done, total: bar.update(task, completed=done, total=total))
    print(format_report(result))
    if args.json:
        write_json(args.json, _plain(result))
    return 0


def _plain(value):
    """`value` with NaN as None (strict JSON)."""
    if isinstance(value, dict):
        return {key: _plain(item) for key, item in value.items()}
    if isinstance(value, list):
        return [_plain(item) for item in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value

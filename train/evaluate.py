"""``evaluate(model, data)``: the paper's Table II metrics of a model on a dataset, with baselines.

Metrics (see :mod:`train.metrics`): distance-field error in pixels, gain Dice, and the frontier
mask's precision/recall next to the raw depth-discontinuity mask F_d. Baselines for the gain
head: predicting the most frequent class everywhere (class 0), and an oracle-band baseline
that is given the labelled frontier band and fills it with the most frequent non-zero class.
"""

from __future__ import annotations

import logging
import os
import warnings
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import DataLoader

from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.frontiers.gain import labels_gain_definition
from frontiernet.model import load_model

from .data import TrainingSamples, gain_bins_mismatch, open_training_data
from .metrics import FrontierMetrics, GainDice
from .transforms import network_batch

log = logging.getLogger(__name__)
TORCH_WORKER_WARNING = r"This DataLoader will create \d+ worker processes in total"
"""The start of torch's warning (four lines on stderr, printed twice) when a loader has more workers than the cores
this process may use: :func:`evaluate` says it in one line of its own instead."""


def usable_cores() -> int:
    """The CPU cores this process may run on (its affinity, as torch counts them; else the machine's)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def expand_scene_ranges(specs) -> list[str]:
    """``evaluate --scenes`` with procedural seed ranges expanded as datagen's ``--scenes`` expands them
    (``procedural:3-4``: procedural:3 and procedural:4; a malformed one refused, naming it), before the data is
    read; duplicates dropped. Patterns (``*``, ``[``) are kept: they match the dataset's scenes
    (:func:`pick_scenes`)."""
    from frontiernet.scenes.spec import expand_specs

    out = []
    for spec in specs:
        body = spec.partition("?")[0]
        seeds = body[len("procedural:"):] if body.startswith("procedural:") else ""
        out += expand_specs([spec]) if "-" in seeds.lstrip("-") or "," in seeds else [spec]
    return list(dict.fromkeys(out))


def pick_scenes(specs, available: list[str], data) -> list[str]:
    """The scenes of dataset `data` (its scene specs `available`) that ``--scenes`` `specs` name: a spec as the
    dataset records it, or a pattern with ``*`` or ``[`` (``procedural:*``) matched against them (datagen expands
    one on the file system: here the dataset's scenes are what there is). InputError naming the spec that names
    none."""
    import fnmatch

    held = ", ".join(available[:4]) + (f" and {len(available) - 4} more" if len(available) > 4 else "")
    chosen, unknown = [], []
    for spec in specs:
        if spec not in available and any(mark in spec.partition("?")[0] for mark in "*["):
            matches = [scene for scene in available if fnmatch.fnmatchcase(scene, spec)]
            if not matches:
                raise InputError(f"{data}: --scenes {spec!r}: the pattern matches none of the dataset's scenes "
                                 f"({held})")
            chosen += matches
        elif spec in available:
            chosen.append(spec)
        else:
            unknown.append(spec)
    if unknown:
        raise InputError(f"{data}: scene(s) not in the dataset: {', '.join(unknown)} (it holds {held})")
    return list(dict.fromkeys(chosen))


def evaluate(model_path: str | Path | None, data: str | Path, scenes=None, all_scenes: bool = False,
             max_samples: int | None = None, batch_size: int = 8, size: int | None = None,
             depth: str = "ground_truth", progress=None, workers: int = 0) -> dict:
    """Table II metrics of the model on the dataset's held-out scenes.

    Args:
        model_path: model file or training checkpoint (None: the shipped model).
        scenes: scenes to evaluate on; default: the validation scenes recorded in the model
            file (its training run's held-out split), else every scene (``all_scenes``).
        size: evaluation resolution (default: the model's inference size, 320).
        depth: the depth prior given to the model and to the F_d baseline: a source of
            ``configs/depth.yaml`` (``ground_truth``, ``emulated`` monocular, ...).
        progress: optional callable ``progress(done, total)``.
        workers: loader processes decoding the dataset (0: in this process).
    Returns:
        dict of metrics (``df_error_px``, ``gain_dice``, ``frontier_precision`` ...), the
        baselines under ``baselines`` and what was evaluated under ``evaluated``.
    """
    dataset = open_training_data(data)  # first: a bad dataset is refused before the model loads
    model, conf = load_model(model_path)
    trained_on = labels_gain_definition(conf["labels"])
    if trained_on != dataset.gain_definition:
        raise InputError(f"{data}: holds gain labels of definition {dataset.gain_definition}, but the model "
                         f"({model_path or 'shipped'}) was trained on {trained_on}; its gain Dice would compare "
                         f"other volumes")
    if (differs := gain_bins_mismatch(conf["labels"], dataset)) is not None:
        raise InputError(f"{data}: the model ({model_path or 'shipped'}) has gain classes of {differs}; its gain "
                         f"Dice would compare other classes")
    recorded = list(conf.get("info", {}).get("val_scenes") or [])
    if scenes:
        chosen = pick_scenes(scenes, list(dataset.scenes), data)
    elif not all_scenes and recorded:
        chosen = [scene for scene in recorded if scene in set(dataset.scenes)]
        if not chosen:
            raise InputError(f"{data}: holds none of the model's held-out scenes ({', '.join(recorded[:3])} ...); "
                             f"pass --all or --scenes")
    else:
        chosen = list(dataset.scenes)
    try:
        subset = dataset.subset(dataset.indices_for_scenes(chosen))
    except (KeyError, ValueError) as error:
        raise InputError(f"{data}: {error}") from None
    if max_samples and len(subset) > max_samples:
        picked = np.linspace(0, len(subset) - 1, int(max_samples)).round().astype(int)
        subset = subset.subset(sorted(set(picked.tolist())))
    size = int(size or conf["inference"]["size"])
    from frontiernet.depth import depth_source_name, make_depth_source

    depth = depth_source_name(depth)
    source = None if depth == "ground_truth" else make_depth_source(depth, load_config("depth"))
    samples = TrainingSamples(subset, conf, size, depth_source=source)
    labels = conf["labels"]
    K = int(labels["num_classes"])
    metrics = FrontierMetrics(labels)
    zero_dice, band_dice = GainDice(K, labels["truncation_px"]), GainDice(K, labels["truncation_px"])
    band_counts = torch.zeros(K, dtype=torch.float64)
    if int(workers) > usable_cores():  # (a legal count, up to 4 per core: one line, not torch's four twice)
        log.warning("--workers %d: more loader processes than the %d CPU cores this process may use; they share "
                    "them", int(workers), usable_cores())
    with warnings.catch_warnings():  # (torch warns as the loader is made and as its workers start)
        warnings.filterwarnings("ignore", message=TORCH_WORKER_WARNING, category=UserWarning)
        loader = iter(DataLoader(samples, batch_size=batch_size, shuffle=False, num_workers=int(workers)))
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")  # the network on the GPU if there is one
    model = model.to(device)
    done = 0
    with torch.inference_mode():
        batches = []
        for batch in loader:
            batch = network_batch(batch, conf)
            distance, logits = (output.float().cpu() for output in model(batch["image"].to(device)))
            metrics.update(distance, logits, batch)
            zero_dice.update(torch.zeros_like(batch["gain_class"]), batch["gain_class"], batch["distance"],
                             batch["frontier"])
            band_counts += torch.bincount(batch["gain_class"].reshape(-1), minlength=K).double()
            batches.append((batch["gain_class"], batch["distance"], batch["frontier"]))
            done += len(batch["image"])
            if progress:
                progress(done, len(samples))
        most_frequent = int(band_counts[1:].argmax()) + 1
        for target, distance_px, frontier in batches:
            band_dice.update(torch.where(target > 0, most_frequent, 0), target, distance_px, frontier)
    result = metrics.compute()
    zero, band = zero_dice.compute(), band_dice.compute()
    result["baselines"] = {"gain_dice_all_class_0": zero["gain_dice"],
                           "gain_dice_with_class_0_all_class_0": zero["gain_dice_with_class_0"],
                           "gain_dice_oracle_band_most_frequent": band["gain_dice"],
                           "gain_dice_with_class_0_oracle_band_most_frequent": band["gain_dice_with_class_0"],
                           "gain_dice_frontier_oracle_band_most_frequent": band["gain_dice_frontier"],
                           "gain_band_exact_oracle_band_most_frequent": band["gain_band_exact"],
                           "gain_band_one_off_oracle_band_most_frequent": band["gain_band_one_off"],
                           "most_frequent_foreground_class": most_frequent}
    result["evaluated"] = {"model": str(model_path or "shipped"), "inputs": model.config.inputs,
                           "encoder": model.config.encoder, "data": str(data), "scenes": len(chosen),
                           "samples": len(samples), "size": size, "depth": depth,
                           "split": "given" if scenes else ("held-out" if recorded and not all_scenes else "all")}
    return result


def format_report(result: dict) -> str:
    """The metrics as a short text table."""
    evaluated, baselines = result["evaluated"], result["baselines"]
    K = len(result["gain_dice_per_class"])
    rows = [
        f"model {evaluated['model']} ({evaluated['encoder']}, {evaluated['inputs']}) on {evaluated['samples']} "
        f"views of {evaluated['scenes']} {evaluated['split']} scene(s) at {evaluated['size']} px, "
        f"{evaluated['depth']} depth",
        f"  DF error (px)          {result['df_error_px']:.3f}   (band D < r: {result['df_error_band_px']:.3f})",
        f"  gain Dice              {result['gain_dice_with_class_0']:.3f}   paper-comparable: all pixels, K classes "
        f"with class 0, macro (baselines: all class 0 {baselines['gain_dice_with_class_0_all_class_0']:.3f}; "
        f"labelled band, most frequent class {baselines['gain_dice_with_class_0_oracle_band_most_frequent']:.3f})",
        f"    classes 1-{K - 1} only    {result['gain_dice']:.3f}   (baselines {baselines['gain_dice_all_class_0']:.3f}, "
        f"{baselines['gain_dice_oracle_band_most_frequent']:.3f})",
        f"    read in D_pred < r   {result['gain_dice_read_with_class_0']:.3f}   class 0 elsewhere, as anchoring reads it "
        f"(classes 1-{K - 1}: {result['gain_dice_read']:.3f})",
        f"    at label F pixels    {result['gain_dice_frontier']:.3f}   (baseline "
        f"{baselines['gain_dice_frontier_oracle_band_most_frequent']:.3f})",
        "    per class 0-" + f"{K - 1}       " + " ".join("  -" if np.isnan(v) else f"{v:.2f}"
                                                     for v in result["gain_dice_per_class"]),
        f"  gain class in D < r    exact {result['gain_band_exact']:.3f}, one class off {result['gain_band_one_off']:.3f}, "
        f"further {result['gain_offsets']['band']['further']:.3f}, mean |offset| "
        f"{result['gain_band_mean_abs_offset']:.2f} classes (baseline: exact "
        f"{baselines['gain_band_exact_oracle_band_most_frequent']:.3f}, one off "
        f"{baselines['gain_band_one_off_oracle_band_most_frequent']:.3f})",
        f"  frontier mask D < l    precision {result['frontier_precision']:.3f}  recall {result['frontier_recall']:.3f}",
        f"  best F1 (l = {result['best_f1_threshold_px']} px)   precision {result['best_f1_precision']:.3f}  "
        f"recall {result['best_f1_recall']:.3f}  (F_d at this recall: precision "
        f"{result['fd_precision_at_best_f1_recall']:.3f})",
        f"  depth jumps F_d        precision {result['fd_precision']:.3f}  recall {result['fd_recall']:.3f}",
        f"  at equal recall        model precision at F_d's recall {result['model_precision_at_fd_recall']:.3f}; "
        f"F_d precision at the model's recall {result['fd_precision_at_model_recall']:.3f}",
    ]
    return "\n".join(rows)

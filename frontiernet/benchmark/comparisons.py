"""Paired comparisons of a benchmark's runs: each method against a reference (classic, the all-knowing
bound) and each depth source against ground truth, as ratios of means over paired runs (same scene,
start and repeat) with a percentile bootstrap interval that resamples whole (scene, start) clusters
(``report.interval`` of ``configs/bench.yaml``), per scene source and over all scenes. Used by
:mod:`.report` (``table.md``) and :mod:`.readme_table`.
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from ..errors import InputError
from ..scenes.spec import parse_spec
from .plan import scene_key

REFERENCE = "classic"  # the paper's Table I baseline (Yamauchi), which the report compares every method with
DEPTH_REFERENCE = "ground_truth"  # the paper's Table I's open-dot rows, which each depth source is compared with


def scene_source(scene: str) -> str:
    try:
        return parse_spec(scene).source
    except InputError:  # a scene spec that no longer resolves (its files moved) is still reported
        return "other"


def source_groups(scenes: list[str]) -> dict[str, list[str]]:
    """Scenes by source (``mesh``, ``hm3d``, ``floorplan``, ``procedural``), in order of first
    appearance, plus ``all scenes`` when there are several sources."""
    groups: dict[str, list[str]] = defaultdict(list)
    for scene in scenes:
        groups[scene_source(scene)].append(scene)
    if len(groups) > 1:
        groups["all scenes"] = list(scenes)
    return dict(groups)


def ratio_interval(ours: np.ndarray, theirs: np.ndarray, clusters: list, conf) -> tuple[float, float] | None:
    """Percentile bootstrap interval of ``sum(ours) / sum(theirs)`` (the ratio of means over
    paired runs) that resamples whole clusters with replacement (`clusters`: one hashable label
    per pair, e.g. its (scene, start)); None with fewer than two clusters.

    Args:
        ours, theirs: (P,) float64 the paired values. conf: ``report.interval`` of
            ``configs/bench.yaml`` (``confidence``, ``draws``, ``seed``).
    """
    labels = {label: index for index, label in enumerate(dict.fromkeys(clusters))}
    if len(labels) < 2:
        return None
    member = np.array([labels[label] for label in clusters])
    sums = np.stack([np.bincount(member, ours, len(labels)), np.bincount(member, theirs, len(labels))], 1)
    rng = np.random.default_rng(int(conf.seed))
    picks = rng.integers(len(labels), size=(int(conf.draws), len(labels)))
    totals = sums[picks].sum(axis=1)  # (draws, 2)
    ratios = totals[:, 0] / np.where(totals[:, 1] > 0, totals[:, 1], np.nan)
    tail = 50.0 * (1.0 - float(conf.confidence))
    low, high = np.nanpercentile(ratios, [tail, 100.0 - tail])
    return float(low), float(high)


def paired_ratio_cell(pairs: list[tuple[dict, dict]], field: str, interval) -> str:
    """One cell of a paired comparison: the ratio of the mean `field` of the first rows of `pairs`
    to the second's, its bootstrap interval over (scene, start) clusters in square brackets
    (:func:`ratio_interval`; `interval`: ``report.interval`` of ``configs/bench.yaml``; none with
    one cluster) and in round brackets the pairs where the first is larger - smaller;
    ``--`` without pairs or when the second's mean is 0."""
    ours = np.array([float(a[field]) for a, _ in pairs])
    theirs = np.array([float(b[field]) for _, b in pairs])
    if not len(pairs) or theirs.mean() <= 0:
        return "--"
    bounds = ratio_interval(ours, theirs, [(a["scene"], a["start"]) for a, _ in pairs], interval)
    shown = f" [{bounds[0]:.2f}, {bounds[1]:.2f}]" if bounds is not None else ""
    wins, losses = (ours > theirs).sum(), (ours < theirs).sum()
    return f"{ours.mean() / theirs.mean():.2f}x{shown} ({wins}-{losses})"


VOX_FIELDS = {"vox25_shared": "Vox@25", "vox50_shared": "Vox@50", "vox100": "Vox@100"}
BOUND = "omniscient"  # the all-knowing bound (frontiernet/exploration/omniscient.py): every method as a share of it


def versus_markdown(done: list[dict], scenes: list[str], methods: list[str], interval,
                    reference: str = REFERENCE, fields=("vox25_shared", "vox50_shared"),
                    title: str | None = None) -> list[str]:
    """Each method against `reference` over paired runs (same scene, start and repeat, both
    finished), per scene source and over all scenes: the ratio of their mean `fields` (keys of
    :data:`VOX_FIELDS`; Vox@25 and Vox@50 by default: the paper's Table I comparison, FrontierNet /
    Classic about 1.75 at both) with its bootstrap interval over (scene, start) clusters
    (:func:`paired_ratio_cell`; `interval`: ``report.interval`` of ``configs/bench.yaml``), and how
    many pairs the method covered more (wins) and less (losses). `title`: the section's heading
    (default "Against <reference> (paired runs)"). No section unless `reference` is among `methods`."""
    others = [m for m in methods if m != reference]
    if reference not in methods or not others:
        return []
    by_run = {(r["method"], r["scene"], r["start"], r["repeat"]): r for r in done}
    groups = source_groups(scenes)
    names = [VOX_FIELDS[field] for field in fields]
    lines = [f"### {title or f'Against {reference} (paired runs)'}", "",
             f"Ratio of mean {', '.join(names[:-1])} and {names[-1]} to {reference}'s over the runs both finished (same scene, start, "
             f"repeat), with its {float(interval.confidence):.0%} bootstrap interval over (scene, start) clusters "
             "in square brackets; in round brackets the pairs where the method covered more - less.", "",
             "| method | " + " | ".join(" | ".join(f"{name}: {vox}" if i == 0 else vox for i, vox in enumerate(names))
                                        for name in groups) + " |",
             "| --- |" + " --- |" * len(names) * len(groups)]
    for method in others:
        cells = []
        for members in groups.values():
            pairs = [(r, by_run[(reference, *key[1:])]) for key, r in by_run.items()
                     if key[0] == method and key[1] in members and (reference, *key[1:]) in by_run]
            cells += [paired_ratio_cell(pairs, field, interval) for field in fields]
        lines.append(f"| {method} | " + " | ".join(cells) + " |")
    return lines + [""]


def bound_markdown(done: list[dict], scenes: list[str], methods: list[str], interval) -> list[str]:
    """Every method as a share of the all-knowing bound (:data:`BOUND`, when among `methods`): its
    mean Vox@25, Vox@50 and Vox@100 over the bound's on paired runs, per scene source and over all
    scenes (:func:`versus_markdown`), then per scene (no section without the bound)."""
    if BOUND not in methods:
        return []
    title = f"Share of the bound ({BOUND}, paired runs)"
    lines = versus_markdown(done, scenes, methods, interval, BOUND, tuple(VOX_FIELDS), title)
    if len(scenes) > 1 and lines:
        for scene in scenes:
            lines += versus_markdown([r for r in done if r["scene"] == scene], [scene], methods, interval, BOUND,
                                     tuple(VOX_FIELDS), f"Share of the bound on {scene_key(scene)}")
    return lines


def penalty_markdown(done: list[dict], methods: list[str], depths: list[str] | None, interval) -> list[str]:
    """The monocular penalty (the paper's Table I, filled against open dots): for each depth
    source other than ground truth, per method the ratio of its mean Vox@25, Vox@50 (shared
    steps, as in each source's summary) and Vox@100 on that source to its mean on ground truth,
    over paired runs (same method, scene, start and repeat, both finished), over all scenes, as
    :func:`paired_ratio_cell` gives it (interval over (scene, start) clusters; wins: pairs where
    that source covered more; `interval`: ``report.interval`` of ``configs/bench.yaml``). No section
    unless ground truth is among several `depths`."""
    if not depths or DEPTH_REFERENCE not in depths or len(depths) < 2:
        return []
    by_run = {(r["depth"], r["method"], r["scene"], r["start"], r["repeat"]): r for r in done}
    lines = []
    for source in [d for d in depths if d != DEPTH_REFERENCE]:
        lines += [f"### Monocular penalty: {source} / {DEPTH_REFERENCE} depth (paired runs)", "",
                  f"Ratio of each method's mean Vox@k on {source} depth to its mean on {DEPTH_REFERENCE} depth over "
                  f"the runs both finished (same scene, start, repeat; all scenes), with its "
                  f"{float(interval.confidence):.0%} bootstrap interval over (scene, start) clusters in square "
                  f"brackets; in round brackets the pairs where {source} covered more - less (the paper's "
                  "FrontierNet with monocular depth: 0.95x / 0.99x at Vox@50 / @100).", "",
                  "| method | Vox@25 | Vox@50 | Vox@100 |", "| --- | --- | --- | --- |"]
        for method in methods:
            pairs = [(r, by_run[(DEPTH_REFERENCE, *key[1:])]) for key, r in by_run.items()
                     if key[:2] == (source, method) and (DEPTH_REFERENCE, *key[1:]) in by_run]
            cells = [paired_ratio_cell(pairs, field, interval) for field in ("vox25_shared", "vox50_shared", "vox100")]
            lines.append(f"| {method} | " + " | ".join(cells) + " |")
        lines.append("")
    return lines


__all__ = ["REFERENCE", "DEPTH_REFERENCE", "BOUND", "VOX_FIELDS", "scene_source", "source_groups", "ratio_interval",
           "paired_ratio_cell", "versus_markdown", "bound_markdown", "penalty_markdown"]

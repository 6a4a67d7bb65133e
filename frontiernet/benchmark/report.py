"""Benchmark report: ``results.csv``, ``table.md`` and coverage curves per scene.

**Vox@k** (docs/design.md item 7, the paper's Table I): coverage (known fraction of the scene's
explorable volume) at a step shared by the runs of one comparison (same scene, start and
repeat): with scene-sized budgets (:mod:`.budget`) the mean over the compared methods of the step
at which each first reaches k % coverage (the paper's), with a fixed budget the mean of k % of
each one's steps (:func:`add_shared_vox`); a run that ended earlier holds its final coverage.
k = 100 is the end of each run (the budget unless it stopped earlier). **Success**: Vox@100 > 40 %.
Table cells are mean +- std over starts x repeats; the last column is the mean over scenes.
The summary at the top has the paper's Table I columns (Vox@25/50/100, success) for each scene source (meshes, HM3D, floor
plans, procedural scenes) and for all scenes: mean +- std over every run of those scenes; then
every method against ``classic`` over paired runs (ratio of mean Vox@25 and @50 with a cluster
bootstrap interval, ``configs/bench.yaml``; wins and losses), and what the runs cost in
worker-hours (copies of a run excluded).
Where the steps go (:mod:`.steps_report`): per method, the mean share of the budget in each
category of the runs' step accounts, their premature stops and unseen reachable volume.
GLEAM's metrics come with each run (:mod:`frontiernet.exploration.surface`): surface coverage
of Poisson-disk samples of the mesh, its AUC over the budget and the one-way Chamfer distance
to the robot's map. The paired comparisons and their intervals are :mod:`.comparisons`.

With several depth sources (``--depth gt,emulated``, :mod:`.plan`) a comparison is also one
source's (the shared Vox@25 / @50 steps are among the runs of one source), ``results.csv`` has a
``depth`` column, and ``table.md`` gives the summary and the comparison with ``classic`` per
source, then the **monocular penalty**: per method, each other source's mean Vox@25 / @50 / @100
(the numbers of its summary) over ground truth's, over paired runs (same scene, start and
repeat), with the same bootstrap interval as against classic; then compute and the per-scene
tables per source.
"""

from __future__ import annotations

import csv
from collections import defaultdict
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import atomic_path, write_text
from .comparisons import REFERENCE, VOX_FIELDS, bound_markdown, penalty_markdown, source_groups, versus_markdown
from .plan import scene_key
from .runner import ROW_FIELDS
from .steps_report import account_columns, account_fields, steps_markdown
from .store import FinishedRuns

SUCCESS_COVERAGE = 0.4
METRICS = (("vox25_shared", "Vox@25 (%)", 100.0), ("vox50_shared", "Vox@50 (%)", 100.0),
           ("vox100", "Vox@100 (%)", 100.0), ("success", "success (%)", 100.0),
           ("surface_coverage", "surface coverage (%, GLEAM)", 100.0), ("surface_auc", "surface coverage AUC (%)", 100.0),
           ("chamfer_m", "Chamfer distance (cm, one-way, lower is better)", 100.0),
           ("path_length_m", "path length (m)", 1.0), ("step_ms", "time per step (ms)", 1.0))


def coverage_at(curve: np.ndarray, step: float) -> float:
    """Coverage of a per-step curve (index = step) when the step count reaches `step` (the
    first whole step at or beyond it), holding the last value beyond the curve's end."""
    return float(curve[min(int(np.ceil(step - 1e-9)), len(curve) - 1)])


VOX_STEPS = ("budget", "coverage")


def first_step_at(curve: np.ndarray, level: float) -> int:
    """The first step at which a per-step coverage curve reaches `level` (a fraction); the run's
    last step when it never does."""
    reached = np.flatnonzero(curve >= level - 1e-12)
    return int(reached[0]) if len(reached) else len(curve) - 1


def add_shared_vox(rows: list[dict], curves: dict, vox_steps: str = "budget", defining: set | None = None) -> None:
    """Set ``vox25_shared`` and ``vox50_shared`` of every finished row: each run's coverage at a step
    shared by the runs of one comparison (same scene, start, repeat and depth source).

    The shared step is, by `vox_steps`:

    * ``coverage`` (the paper's definition, the scene-sized protocol: :mod:`.budget`): the mean over
      the compared runs of the step at which each first reaches 25 / 50 % coverage (a run that never
      does counts its last step);
    * ``budget`` (the fixed-budget benchmarks made before): the mean over the compared runs of
      25 / 50 % of each one's steps.

    Args:
        rows: result rows (:data:`~frontiernet.benchmark.runner.ROW_FIELDS`; ``depth`` when the
            benchmark has several sources: a comparison is one source's runs).
        curves: row index -> (S + 1,) coverage per step of the finished runs.
        defining: the methods whose runs set the shared steps (:func:`finished_methods`: those with
            every planned run finished, so that a method joining a folder moves no other method's
            Vox@k until all its runs are in); the other runs are read at those steps. None, or a
            comparison without any of them: every run of the comparison.
    """
    if vox_steps not in VOX_STEPS:
        raise InputError(f"vox_steps must be one of {', '.join(VOX_STEPS)}, got {vox_steps!r}")
    groups = defaultdict(list)
    for index, row in enumerate(rows):
        if index in curves:
            groups[(row["scene"], row["start"], row["repeat"], row.get("depth"))].append(index)
    for members in groups.values():
        setting = [i for i in members if defining is None or rows[i]["method"] in defining] or members
        for k in (25, 50):
            if vox_steps == "coverage":
                step = float(np.mean([first_step_at(curves[i], k / 100) for i in setting]))
            else:
                step = float(np.mean([k / 100 * (len(curves[i]) - 1) for i in setting]))
            for i in members:
                rows[i][f"vox{k}_shared"] = coverage_at(curves[i], step)


def _cell(values: list, scale: float, spread: bool = True) -> str:
    if not values:
        return "--"
    values = np.asarray(values, np.float64) * scale
    return f"{values.mean():.1f} +- {values.std():.1f}" if spread and len(values) > 1 else f"{values.mean():.1f}"


SUMMARY_METRICS = METRICS[:4]


def common_starts(runs: list[dict]) -> tuple[set, list[str]]:
    """The (start, repeat) pairs that the plan's `runs` give every method, and the methods given more
    (a benchmark grown by more starts for some methods: ``METHODS=classic,random-frontier STARTS=3``).
    The table compares the methods on the same starts: a comparison's shared Vox@k step is the mean
    over the methods that ran it (:func:`add_shared_vox`), so a start only two methods ran
    has another step than one all ran, and its runs would weigh in one method's mean and not another's."""
    planned: dict[str, set] = {}
    for run in runs:
        planned.setdefault(run["method"], set()).add((run["start"], run["repeat"]))
    common = set.intersection(*planned.values()) if planned else set()
    return common, [method for method, pairs in planned.items() if pairs != common]


def unfinished_methods(runs: list[dict], rows: list[dict]) -> dict[str, tuple[int, int]]:
    """Method -> (finished, planned) for each method of the plan's `runs` with a run not finished
    (no row among `rows`, the finished runs: done or failed), counted over the :func:`common_starts`
    (a method given more starts counts only the starts every method has)."""
    common, _ = common_starts(runs)
    planned = [run for run in runs if (run["start"], run["repeat"]) in common]
    finished = [row for row in rows if (row["start"], row["repeat"]) in common]
    counts = {method: (sum(row["method"] == method for row in finished), sum(run["method"] == method for run in planned))
              for method in dict.fromkeys(run["method"] for run in planned)}
    return {method: (ran, of) for method, (ran, of) in counts.items() if ran < of}


def finished_methods(runs: list[dict], rows: list[dict]) -> set[str]:
    """The methods of the plan's `runs` with every planned run finished among `rows` (no
    :func:`unfinished_methods`): those whose runs set the shared Vox@k steps (:func:`add_shared_vox`)."""
    return {run["method"] for run in runs} - set(unfinished_methods(runs, rows))


def summary_markdown(done: list[dict], scenes: list[str], methods: list[str]) -> list[str]:
    """Table I layout per scene source and over all scenes: rows methods, columns Vox@25/50/100
    and success, cells mean +- std over the finished runs (`done`) of those scenes (success: the
    rate alone, as the paper gives it)."""
    lines = []
    for name, members in source_groups(scenes).items():
        lines += [f"### Summary: {name} ({len(members)} scene{'s' * (len(members) > 1)})", "",
                  "| method | runs | " + " | ".join(title for _, title, _ in SUMMARY_METRICS) + " |",
                  "| --- | --- |" + " --- |" * len(SUMMARY_METRICS)]
        for method in methods:
            runs = [r for r in done if r["method"] == method and r["scene"] in members]
            cells = [_cell([float(r[field]) for r in runs if r.get(field) is not None], scale, field != "success")
                     for field, _, scale in SUMMARY_METRICS]
            lines.append(f"| {method} | {len(runs)} | " + " | ".join(cells) + " |")
        lines.append("")
    return lines


def compute_markdown(rows: list[dict], methods: list[str]) -> list[str]:
    """What the finished `rows` cost: per method the runs actually made (a ``copy_of`` row took
    no time of its own), their mean wall time and their sum, and the total in worker-hours (the
    sum of each run's ``wall_s``, whatever the number of workers running them side by side)."""
    made = [r for r in rows if not r.get("copy_of") and r.get("wall_s") not in (None, "")]
    if not made:
        return []
    lines = ["### Compute (runs made, copies excluded)", "", "| method | runs | wall per run (s) | worker-hours |",
             "| --- | --- | --- | --- |"]
    for method in methods:
        seconds = [float(r["wall_s"]) for r in made if r["method"] == method]
        if seconds:
            lines.append(f"| {method} | {len(seconds)} | {np.mean(seconds):.0f} | {sum(seconds) / 3600:.2f} |")
    total = sum(float(r["wall_s"]) for r in made)
    return lines + [f"| all | {len(made)} | {total / len(made):.0f} | {total / 3600:.2f} |", ""]


def metric_markdown(done: list[dict], scenes: list[str], methods: list[str]) -> list[str]:
    """One Table I per metric of :data:`METRICS`: rows methods, columns scenes and their mean,
    cells mean +- std over the finished runs (`done`) of each scene."""
    names = [scene_key(s) for s in scenes]
    lines = []
    for field, title, scale in METRICS:
        lines += [f"### {title}", "", "| method | " + " | ".join(names) + " | mean |",
                  "| --- |" + " --- |" * (len(names) + 1)]
        for method in methods:
            per_scene = [[float(r[field]) for r in done if r["method"] == method and r["scene"] == s
                          and r.get(field) is not None] for s in scenes]
            means = [np.mean(v) * scale for v in per_scene if v]
            overall = f"{np.mean(means):.1f}" if len(means) == len(scenes) else "--"
            lines.append(f"| {method} | " + " | ".join(_cell(v, scale) for v in per_scene) + f" | {overall} |")
        lines.append("")
    return lines


def table_markdown(rows: list[dict], scenes: list[str], methods: list[str], pending: int = 0,
                   depths: list[str] | None = None, *, interval, starts: tuple[set, list[str]] | None = None) -> str:
    """The summary (:func:`summary_markdown`), each method against ``classic``
    (:func:`versus_markdown`), where the steps go (:func:`~.steps_report.steps_markdown`), the compute
    (:func:`compute_markdown`), then one Table I per metric
    (:func:`metric_markdown`) (`pending`: runs of the plan not finished yet, said at the top).
    With several depth sources (`depths`, rows with their ``depth``): the summary and the
    comparison with classic per source, the monocular penalty (:func:`penalty_markdown`), then
    compute and the per-metric tables per source, each part under a ``## <source> depth`` heading.
    `interval`: ``report.interval`` of ``configs/bench.yaml`` (the comparisons' bootstrap); `starts`:
    :func:`common_starts` of the plan, where some methods ran more starts than others: every table is then
    of the starts all methods ran, and a section more compares the methods that ran more on all of theirs."""
    every = [r for r in rows if r["status"] == "done"]
    common, more = starts if starts is not None else (None, [])
    done = every if not more else [r for r in every if (r["start"], r["repeat"]) in common]
    lines = []
    if pending:
        lines += [f"Interim: {len(rows)} of {len(rows) + pending} runs finished; Vox@25 and @50 thresholds are "
                  "shared among the finished runs of each comparison.", ""]
    if more:
        lines += [f"The tables are of the starts every method ran ({len(done)} finished runs); {', '.join(more)} "
                  f"ran more, compared on all of theirs under \"Against {REFERENCE} on every start\" ({len(every)} "
                  "finished runs in all; results.csv holds every run).", ""]
    regimes = depths or [None]

    def of(depth) -> list[dict]:
        return done if depth is None else [r for r in done if r.get("depth") == depth]

    def heading(depth, part: str) -> list[str]:
        return [] if depth is None else [f"## {depth} depth: {part}", ""]

    for depth in regimes:
        lines += heading(depth, "summary") + summary_markdown(of(depth), scenes, methods)
        lines += versus_markdown(of(depth), scenes, methods, interval)
        if REFERENCE in more:  # (a start only some methods ran has its Vox@k step shared among those)
            lines += versus_markdown([r for r in every if depth is None or r.get("depth") == depth], scenes,
                                     [m for m in methods if m in more], interval, fields=tuple(VOX_FIELDS),
                                     title=f"Against {REFERENCE} on every start")
        lines += bound_markdown(of(depth), scenes, methods, interval)
        lines += steps_markdown(of(depth), methods)
    lines += penalty_markdown(done, methods, depths, interval)
    for depth in regimes:
        lines += heading(depth, "per scene") + compute_markdown(of(depth), methods)
        lines += metric_markdown(of(depth), scenes, methods)
    failed = [r for r in rows if r["status"] != "done"]
    if failed:
        lines += [f"{len(failed)} run(s) failed (see results.csv):", ""]
        lines += [f"- {r['method']}{f' on {d} depth' if (d := r.get('depth')) else ''} on {scene_key(r['scene'])}, "
                  f"start {r['start']}, repeat {r['repeat']}: {r['error']}" for r in failed] + [""]
    return "\n".join(lines)


def plot_curves(rows: list[dict], curves: dict, scenes: list[str], title: str, path: Path) -> None:
    """Mean coverage per step of each method over its runs on `scenes` (band: +- std over
    those runs; a run that stopped early holds its final coverage); with several depth sources,
    of each method on each source (``method (source)``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(figsize=(6, 4), dpi=100)
    for method, depth in dict.fromkeys((r["method"], r.get("depth")) for r in rows):
        runs = [curves[i] for i, r in enumerate(rows) if i in curves and r["method"] == method
                and r.get("depth") == depth and r["scene"] in scenes]
        if not runs:
            continue
        length = max(len(c) for c in runs)
        stacked = np.stack([np.pad(c, (0, length - len(c)), mode="edge") for c in runs]) * 100
        mean, std = stacked.mean(0), stacked.std(0)
        axes.plot(mean, label=f"{method} ({depth})" if depth else method)
        axes.fill_between(np.arange(length), mean - std, mean + std, alpha=0.15)
    axes.set(xlabel="step", ylabel="coverage (% of explorable volume)", title=title)
    axes.grid(alpha=0.3)
    if axes.lines:
        axes.legend(fontsize=8)
    figure.tight_layout()
    with atomic_path(path) as tmp:
        figure.savefig(tmp, format="png")
    plt.close(figure)


def report_files(scenes: list[str]) -> list[str]:
    """The names of the files :func:`write_report` may write for a benchmark of `scenes`: results.csv,
    table.md and every coverage plot's (:func:`~frontiernet.io.check_output_files` checks them before the work)."""
    return ["results.csv", "table.md", *(f"coverage_{stem}.png" for stem, _, _ in _plot_sets(scenes, set(scenes)))]


def _plot_sets(scenes: list[str], reported: set) -> list[tuple[str, list[str], str]]:
    """(file stem, scenes, title) of each coverage plot: one per scene with finished runs, and
    with several scenes one per scene source (as the summary) and, if several sources, all."""
    sets = [(scene_key(s), [s], scene_key(s)) for s in scenes if s in reported]
    return sets + [(f"summary_{name.replace(' ', '_')}", members, f"{name} ({len(members)} scenes, mean)")
                   for name, members in source_groups(scenes).items() if len(members) > 1 and reported & set(members)]


def write_report(out: Path, rows: list[dict], scenes: list[str], methods: list[str], pending: int = 0,
                 finished: FinishedRuns | None = None, depths: list[str] | None = None, *, interval,
                 vox_steps: str = "budget", starts: tuple[set, list[str]] | None = None,
                 defining: set | None = None) -> dict:
    """Write ``results.csv``, ``table.md``, ``coverage_<scene>.png`` and, with several scenes,
    ``coverage_summary_<source>.png`` (see :func:`_plot_sets`) into `out`; returns paths.
    `rows`: the finished (done or failed) runs; `pending`: how many of the plan's runs are not;
    `finished`: the runs' records (per run or packed; None: read from `out`); `depths`: the
    benchmark's depth sources when it has several (the rows carry theirs; results.csv then has a
    ``depth`` column after ``method``), else None; `interval`: ``report.interval`` of
    ``configs/bench.yaml``; `vox_steps`: how Vox@25 / @50's shared steps are set (:func:`add_shared_vox`;
    a plan's ``settings.vox_steps``, ``budget`` for plans made before the scene-sized protocol); `starts`:
    the plan's :func:`common_starts` (:func:`table_markdown`); `defining`: the methods whose runs set the
    shared steps (:func:`add_shared_vox`; the bench command's: :func:`finished_methods`)."""
    out = Path(out)
    finished = finished if finished is not None else FinishedRuns(out)
    curves = {}
    for index, row in enumerate(rows):
        if row["status"] == "done":
            metrics = finished.metrics(row.get("copy_of") or row["key"])
            curves[index] = np.asarray(metrics["coverage_per_step"], np.float64)
            row.update(account_fields(metrics))  # where the steps went, when the record has it
    add_shared_vox(rows, curves, vox_steps, defining)
    fields = [*ROW_FIELDS, "vox25_shared", "vox50_shared", *account_columns(rows)]
    if depths:
        fields.insert(fields.index("method") + 1, "depth")

    with atomic_path(out / "results.csv") as tmp, open(tmp, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=fields, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    table = table_markdown(rows, scenes, methods, pending, depths, interval=interval, starts=starts)
    write_text(out / "table.md", table)
    plots = []
    for stem, members, title in _plot_sets(scenes, {row["scene"] for row in rows}):
        plots.append(out / f"coverage_{stem}.png")
        plot_curves(rows, curves, members, title, plots[-1])
    return {"results": out / "results.csv", "table": out / "table.md", "plots": plots}


__all__ = ["write_report", "report_files", "common_starts", "finished_methods", "unfinished_methods", "add_shared_vox", "table_markdown", "summary_markdown", "versus_markdown", "bound_markdown",
           "ratio_interval",
           "paired_ratio_cell", "penalty_markdown", "metric_markdown", "compute_markdown", "coverage_at",
           "SUCCESS_COVERAGE"]

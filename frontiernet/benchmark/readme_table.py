"""The results table that README.md and docs/benchmark.md show, built from a benchmark folder.

One Markdown table, rows methods per depth source: each method's mean Vox@25 / @50 / @100 over
the finished runs, its share of the all-knowing bound (``omniscient``) and its ratios to
``classic`` (the paper's Table I baseline) and to ``nbvp`` (its strongest), of the means over
paired runs, with the bootstrap interval of :func:`.comparisons.ratio_interval` at Vox@50. The
figures are those of the folder's report (``table.md``: its summary, "Against classic" and
"Share of the bound" sections compute the same means and ratios from the same rows).

``frontiernet bench --report --out DIR`` writes it to ``DIR/table_readme.md``
(:func:`write_readme_table`); the pages include it between :data:`BEGIN` and :data:`END`, and
tests/test_readme_table.py checks README.md's block against the published folder named by
``readme.source`` in ``configs/bench.yaml``.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..config import load_config
from ..io import write_text
from .comparisons import BOUND, REFERENCE, VOX_FIELDS, ratio_interval
from .report import add_shared_vox, common_starts, finished_methods, unfinished_methods
from .runner import finished_row, with_copies
from .store import FinishedRuns, read_plan

BEGIN = "<!-- results-table:begin -->"
END = "<!-- results-table:end -->"
FILE = "table_readme.md"
"""What ``bench --report`` writes beside ``table.md``."""
NBVP = "nbvp"  # the paper's strongest baseline (Table I), the second reference of the table


def published_folder(root: str | Path | None = None) -> Path:
    """The published benchmark folder (``readme.source`` of ``configs/bench.yaml``), relative to
    `root` (default: the folder holding ``frontiernet/``, the repository)."""
    root = Path(root) if root is not None else Path(__file__).resolve().parents[2]
    return root / str(load_config("bench").readme.source)


def folder_rows(out: str | Path) -> list[dict]:
    """The finished runs' rows of benchmark folder `out` with their shared Vox@25 / @50, as
    ``bench --report`` computes them (:func:`~frontiernet.benchmark.report`: the steps set by the
    methods with every planned run finished), nothing written."""
    out = Path(out)
    plan, finished = read_plan(out), FinishedRuns(out)
    own = (finished_row(run, finished) for run in plan["runs"] if not run.get("copy_of"))
    rows = [row for row in with_copies(plan["runs"], {row["key"]: row for row in own if row is not None})
            if row is not None]
    curves = {index: np.asarray(finished.metrics(row.get("copy_of") or row["key"])["coverage_per_step"], np.float64)
              for index, row in enumerate(rows) if row["status"] == "done"}
    add_shared_vox(rows, curves, plan["settings"].get("vox_steps", "budget"), finished_methods(plan["runs"], rows))
    return rows


def _paired(done: list[dict], method: str, reference: str) -> list[tuple[dict, dict]]:
    """(method's row, reference's row) of the runs both finished: same scene, start and repeat."""
    theirs = {(r["scene"], r["start"], r["repeat"]): r for r in done if r["method"] == reference}
    return [(r, theirs[key]) for r in done if r["method"] == method
            and (key := (r["scene"], r["start"], r["repeat"])) in theirs]


def ratios_cell(pairs: list[tuple[dict, dict]], interval) -> str:
    """Ratios of the mean Vox@25, Vox@50 and Vox@100 of the first rows of `pairs` to the second's,
    ``a / b [lo, hi] / c``: Vox@50's with its bootstrap interval over (scene, start) clusters
    (:func:`~.comparisons.ratio_interval`, the paper's headline column); ``--`` without pairs."""
    cells = []
    for field in VOX_FIELDS:
        ours = np.array([float(a[field]) for a, _ in pairs])
        theirs = np.array([float(b[field]) for _, b in pairs])
        if not len(pairs) or theirs.mean() <= 0:
            return "--"
        cell = f"{ours.mean() / theirs.mean():.2f}x"
        if field == "vox50_shared":
            bounds = ratio_interval(ours, theirs, [(a["scene"], a["start"]) for a, _ in pairs], interval)
            cell += f" [{bounds[0]:.2f}, {bounds[1]:.2f}]" if bounds is not None else ""
        cells.append(cell)
    return " / ".join(cells)


def readme_markdown(rows: list[dict], out: str | Path, source: str | None = None) -> str | None:
    """The results table of benchmark folder `out` (its plan gives the scenes, methods and depth
    sources) from its finished `rows` (with shared Vox@k: :func:`folder_rows` or the rows
    ``bench --report`` returns); `source`: how the caption names the folder (default `out`).

    Per depth source and method whose planned runs are all finished (the others are named under the
    table with their counts, so that no row rests on the scenes a method happened to reach first):
    the mean Vox@25 / @50 / @100 over the finished runs of the starts every method has (:func:`~.report.common_starts`; the other starts are in the report's ``table.md``), then, over
    paired runs (:func:`ratios_cell`), the share of the all-knowing bound (:data:`~.report.BOUND`),
    the ratio to ``classic`` and to ``nbvp``, each column only when that method is in the folder.
    None when ``classic`` is not among the methods."""
    plan = read_plan(Path(out))
    scenes = list(plan["start_poses"])
    methods = list(dict.fromkeys(run["method"] for run in plan["runs"]))
    if REFERENCE not in methods:
        return None
    references = [(name, title) for name, title in ((BOUND, "share of the bound"), (REFERENCE, "to classic"),
                                                      (NBVP, "to nbvp")) if name in methods]
    depths = list(dict.fromkeys(run.get("depth") for run in plan["runs"]))
    interval = load_config("bench").report.interval
    common, more = common_starts(plan["runs"])
    unfinished = unfinished_methods(plan["runs"], rows)
    done = [row for row in rows if row["status"] == "done" and (row["start"], row["repeat"]) in common]
    lines = ["| method | depth | runs | Vox@25 (%) | Vox@50 (%) | Vox@100 (%) | " +
             " | ".join(f"{title}, Vox@25 / @50 / @100" for _, title in references) + " |",
             "| --- | --- | --- | --- | --- | --- |" + " --- |" * len(references)]
    for depth in depths:
        own = [row for row in done if row.get("depth") == depth]
        name = (depth or str(plan["settings"].get("depth") or "--")).replace("_", " ")
        for method in (method for method in methods if method not in unfinished):
            runs = [row for row in own if row["method"] == method]
            means = [f"{100 * np.mean([float(r[field]) for r in runs]):.1f}" if runs else "--" for field in VOX_FIELDS]
            ratios = ["1.00x" if method == reference else ratios_cell(_paired(own, method, reference), interval)
                      for reference, _ in references]
            lines.append(f"| {method} | {name} | {len(runs)} | " + " | ".join(means + ratios) + " |")
    protocol = plan["settings"].get("budget")
    budget = f", {protocol} steps a run" if isinstance(protocol, int) else \
        ", scene-sized step budgets (configs/bench.yaml)" if isinstance(protocol, dict) else ""
    vox = ("the coverage at 25 / 50 / 100 % of each run's budget" if plan["settings"].get("vox_steps", "budget") ==
           "budget" else "the coverage at the step where the methods on average first reach 25 / 50 %, and at the end")
    interim = ("Not yet in the table, their runs not all finished: " + ", ".join(
        f"{method} ({ran} of {of} runs)" for method, (ran, of) in unfinished.items()) + ". ") if unfinished else ""
    which = "its first start" if common == {(0, 0)} else f"the {len(common)} (start, repeat) pairs every method ran"
    starts = f" Each scene from {which} ({' and '.join(more)} ran more: the report's `table.md`)." if more else ""
    caption = (f"{interim}`{Path(source or out).as_posix()}`: {len(scenes)} scenes{budget}.{starts} Vox@k: {vox}, mean over "
               "the runs (%). Ratios: of the means over paired runs (same scene, start, repeat and depth), Vox@50's "
               f"with its {float(interval.confidence):.0%} bootstrap interval over (scene, start) clusters. "
               f"Generated by `frontiernet bench --report` (`{FILE}`).")
    return "\n".join(lines + ["", caption]) + "\n"


def write_readme_table(out: str | Path, rows: list[dict], source: str | None = None) -> Path | None:
    """Write :func:`readme_markdown` to ``out/table_readme.md``; returns its path (None without
    classic among the methods)."""
    text = readme_markdown(rows, out, source)
    if text is None:
        return None
    write_text(Path(out) / FILE, text)
    return Path(out) / FILE


def marked_block(text: str) -> str | None:
    """What a page holds between :data:`BEGIN` and :data:`END` (without the markers and the blank
    lines around them); None without both markers."""
    match = re.search(re.escape(BEGIN) + r"\n+(.*?)\n*" + re.escape(END), text, re.S)
    return None if match is None else match.group(1) + "\n"


def with_block(text: str, table: str) -> str:
    """`text` with its marked block replaced by `table`."""
    if marked_block(text) is None:
        raise ValueError(f"no {BEGIN} ... {END} block")
    return re.sub(re.escape(BEGIN) + r".*?" + re.escape(END), lambda _: f"{BEGIN}\n\n{table.rstrip()}\n\n{END}",
                  text, count=1, flags=re.S)


__all__ = ["readme_markdown", "write_readme_table", "folder_rows", "published_folder", "marked_block", "with_block",
           "BEGIN", "END", "FILE"]

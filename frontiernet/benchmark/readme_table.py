"""The results table that README.md and docs/benchmark.md show, built from a benchmark folder.

One Markdown table, rows methods per depth source: each method's mean Vox@25 / @50 / @100 over
all scenes (the "all scenes" summary of the folder's ``table.md``, :func:`.report.summary_markdown`)
and its ratio to ``classic``'s over paired runs with the bootstrap interval (the report's
"Against classic" table with Vox@100 added, :func:`.report.versus_markdown`). The cells are the
report's own, taken from its tables, so the pages cannot show other figures than the data gives.

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
from .report import REFERENCE, VOX_FIELDS, add_shared_vox, summary_markdown, versus_markdown
from .runner import finished_row, with_copies
from .store import FinishedRuns, read_plan

BEGIN = "<!-- results-table:begin -->"
END = "<!-- results-table:end -->"
FILE = "table_readme.md"
"""What ``bench --report`` writes beside ``table.md``."""


def published_folder(root: str | Path | None = None) -> Path:
    """The published benchmark folder (``readme.source`` of ``configs/bench.yaml``), relative to
    `root` (default: the folder holding ``frontiernet/``, the repository)."""
    root = Path(root) if root is not None else Path(__file__).resolve().parents[2]
    return root / str(load_config("bench").readme.source)


def folder_rows(out: str | Path) -> list[dict]:
    """The finished runs' rows of benchmark folder `out` with their shared Vox@25 / @50, as
    ``bench --report`` computes them (:func:`~frontiernet.benchmark.report`), nothing written."""
    out = Path(out)
    plan, finished = read_plan(out), FinishedRuns(out)
    own = (finished_row(run, finished) for run in plan["runs"] if not run.get("copy_of"))
    rows = [row for row in with_copies(plan["runs"], {row["key"]: row for row in own if row is not None})
            if row is not None]
    curves = {index: np.asarray(finished.metrics(row.get("copy_of") or row["key"])["coverage_per_step"], np.float64)
              for index, row in enumerate(rows) if row["status"] == "done"}
    add_shared_vox(rows, curves, plan["settings"].get("vox_steps", "budget"))
    return rows


def _cells(line: str) -> list[str]:
    return [cell.strip() for cell in line.strip().strip("|").split("|")]


def _last_table(lines: list[str]) -> dict[str, list[str]]:
    """Method -> cells of the last row block of a report section (`lines`: one section's table)."""
    rows = [_cells(line) for line in lines if line.startswith("| ") and not line.startswith("| method ")]
    return {cells[0]: cells[1:] for cells in rows}


def readme_markdown(rows: list[dict], out: str | Path, source: str | None = None) -> str | None:
    """The results table of benchmark folder `out` (its plan gives the scenes, methods and depth
    sources) from its finished `rows` (with shared Vox@k: :func:`folder_rows` or the rows
    ``bench --report`` returns); `source`: how the caption names the folder (default `out`).
    None when ``classic`` is not among the methods."""
    plan = read_plan(Path(out))
    scenes = list(plan["start_poses"])
    methods = list(dict.fromkeys(run["method"] for run in plan["runs"]))
    if REFERENCE not in methods:
        return None
    depths = list(dict.fromkeys(run.get("depth") for run in plan["runs"]))
    interval = load_config("bench").report.interval
    done = [row for row in rows if row["status"] == "done"]
    fields = tuple(VOX_FIELDS)
    lines = ["| method | depth | Vox@25 (%) | Vox@50 (%) | Vox@100 (%) | Vox@25 to classic | Vox@50 to classic "
             "| Vox@100 to classic |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    counts = set()
    for depth in depths:
        own = [row for row in done if row.get("depth") == depth]
        summary = summary_markdown(own, scenes, methods)
        last = max(i for i, line in enumerate(summary) if line.startswith("### Summary"))
        means = _last_table(summary[last:])  # all scenes (or the one source): runs, Vox@25/50/100, success
        versus = _last_table(versus_markdown(own, scenes, methods, interval, fields=fields))
        name = (depth or str(plan["settings"].get("depth") or "--")).replace("_", " ")
        for method in methods:
            runs, *vox = means[method][:4]
            counts.add(runs)
            ratios = ["1.00x"] * len(fields) if method == REFERENCE else \
                [re.sub(r" \(\d+-\d+\)$", "", cell) for cell in versus[method][-len(fields):]]
            lines.append(f"| {method} | {name} | " + " | ".join(value.split(" +- ")[0] for value in vox) +
                         " | " + " | ".join(ratios) + " |")
    protocol = plan["settings"].get("budget")
    budget = f", {protocol} steps a run" if isinstance(protocol, int) else \
        ", scene-sized step budgets" if isinstance(protocol, dict) else ""
    vox = ("the coverage at 25 / 50 / 100 % of each run's budget" if plan["settings"].get("vox_steps", "budget") ==
           "budget" else "the coverage at the step where the methods on average reach 25 / 50 %, and at the end")
    interim = f"Interim: {len(rows)} of {len(plan['runs'])} runs finished. " if len(rows) < len(plan["runs"]) else ""
    caption = (f"{interim}`{Path(source or out).as_posix()}`: {len(scenes)} scenes, {' or '.join(sorted(counts))} "
               f"runs a method and depth{budget}. Vox@k: {vox}, mean over all runs (%). To classic: ratio of the "
               "mean to classic's over paired runs (same scene, start, repeat and depth), with its "
               f"{float(interval.confidence):.0%} bootstrap interval over (scene, start) clusters. Generated by "
               f"`frontiernet bench --report` (`{FILE}`).")
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

"""Paired ratios between benchmark runs made in different folders from the same starts (docs/benchmark.md,
issue 27 steps 4 and 5): each variant's Vox@25 / @50 / @100 and its ratio to two references, with the
report's bootstrap interval over (scene, start) clusters (``frontiernet.benchmark.comparisons.paired_ratio_cell``).

A run is named ``FOLDER_OR_CSV:METHOD[@SOURCE][=LABEL]``; runs pair by (scene, start, repeat). Folders
joined by ``+`` pool their runs (``runs/procedural+runs/house:classic``, e.g. one scene set run in two
folders). A folder run with several depth sources (``--depth gt,emulated``) needs the source
(``classic@emulated``; ``gt`` stands for ``ground_truth``). The first two are the references (e.g. classic and the default oracle), every one is
compared with both:

    .venv/bin/python tests/bench/paired.py runs/base:classic runs/base:oracle=default \\
        runs/none:oracle=gain_reduction-none
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np

from frontiernet.benchmark.comparisons import paired_ratio_cell
from frontiernet.config import load_config

FIELDS = ("vox25", "vox50", "vox100")


def load(spec: str) -> tuple[str, dict]:
    """``FOLDER_OR_CSV[+FOLDER_OR_CSV...]:METHOD[@SOURCE][=LABEL]`` -> (label, {(scene, start, repeat):
    row}) of its finished runs, pooled over the folders (a run found in two of them is refused)."""
    where, _, method = spec.rpartition(":")
    method, _, label = method.partition("=")
    method, _, source = method.partition("@")
    source = {"gt": "ground_truth"}.get(source, source)
    rows, names = {}, []
    for part in where.split("+"):
        path = Path(part)
        if path.is_dir():
            if not (path / "results.csv").is_file():  # an untracked report (docs/benchmark/regimes)
                sys.exit(f"{path}: no results.csv; `frontiernet bench --report --out {path}` writes it")
            path = path / "results.csv"
        names.append(path.parent.name)
        with open(path) as handle:
            for r in csv.DictReader(handle):
                depth = r.get("depth") or ""
                if depth and not source:
                    sys.exit(f"{path}: its runs name their depth source; give one: {method}@{depth}")
                if r["method"] == method and r["status"] == "done" and depth == source:
                    key = (r["scene"], r["start"], r["repeat"])
                    if key in rows:
                        sys.exit(f"{path}: run {key} of {method} is also in another folder of {spec}")
                    rows[key] = r
    return label or f"{'+'.join(names)}:{method}" + (f"@{source}" if source else ""), rows


def main(specs: list[str]) -> None:
    interval = load_config("bench").report.interval
    runs = [load(spec) for spec in specs]
    (first, reference_a), (second, reference_b) = runs[0], runs[1]
    print(f"| run | n | Vox@25 | Vox@50 | Vox@100 | to {first} @25 | @50 | @100 | to {second} @25 | @50 | @100 |")
    print("| --- " * 11 + "|")
    for label, rows in runs:
        keys = sorted(rows)
        means = [f"{100 * np.mean([float(rows[k][f]) for k in keys]):.1f}" for f in FIELDS]
        cells = [paired_ratio_cell([(rows[k], reference[k]) for k in keys if k in reference], f, interval)
                 for reference in (reference_a, reference_b) for f in FIELDS]
        print(f"| {label} | {len(keys)} | " + " | ".join(means + cells) + " |")


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    main(sys.argv[1:])

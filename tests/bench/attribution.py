"""The attribution table of docs/benchmark.md ("Where the value of gain is lost"): Vox@25 / @50 /
@100 per method and its ratio to classic, per scene and over all, from a benchmark's
``results.csv`` (``frontiernet bench --report`` writes it, also from an unfinished run).

Only (scene, start, repeat) comparisons in which every listed method finished count, so every
mean and ratio is over the same runs. Vox@25 and @50 are the report's shared-step values
(``vox25_shared``, ``vox50_shared``).

    .venv/bin/python tests/bench/attribution.py /work/bench27_3/results.csv \
        classic,oracle,oracle-uniform,frontiernet-oracle-gain,frontiernet,df-uniform
"""

from __future__ import annotations

import csv
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

COLUMNS = ("vox25_shared", "vox50_shared", "vox100")


def main(results: str, methods: list[str]) -> None:
    runs = defaultdict(dict)  # (scene, start, repeat) -> method -> (3,) Vox@k in %
    for row in csv.DictReader(open(results)):
        if row["status"] == "done" and row["method"] in methods:
            runs[(row["scene"], row["start"], row["repeat"])][row["method"]] = [100 * float(row[c]) for c in COLUMNS]
    complete = {key: value for key, value in runs.items() if set(value) >= set(methods)}
    groups = defaultdict(list)
    for (scene, _, _), value in sorted(complete.items()):
        groups[Path(scene).name].append(value)
    groups["all"] = list(complete.values())
    print(f"{len(complete)} complete comparisons of {len(runs)} started")
    print("| scene (comparisons) | method | Vox@25 | Vox@50 | Vox@100 | ratio to classic @25 / @50 / @100 |")
    print("| --- | --- | --- | --- | --- | --- |")
    for scene, values in groups.items():
        if not values:
            continue
        classic = np.mean([v["classic"] for v in values], axis=0)
        for method in methods:
            mean = np.mean([v[method] for v in values], axis=0)
            ratio = " / ".join(f"{m / c:.2f}x" for m, c in zip(mean, classic))
            print(f"| {scene} ({len(values)}) | {method} | " + " | ".join(f"{m:.1f}" for m in mean) + f" | {ratio} |")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2].split(","))

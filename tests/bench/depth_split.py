"""Which part of the pipeline loses coverage on monocular depth (issue 27, docs/exploration.md)?

Replays a benchmark folder's runs of METHOD on emulated depth (its plan's starts, seed 0, 300
steps, no video) with the robot's *map* fed the ground truth's range-clipped sensor depth, while
perception and anchoring keep the emulated depth: against the same runs on emulated depth (the
map too) it measures what the map's errors cost (planning grid, bookkeeping), against ground-truth
runs what the anchoring's do. Writes OUT/results.csv in the benchmark's columns (for
``tests/bench/paired.py``).

    .venv/bin/python tests/bench/depth_split.py PLAN_FOLDER METHOD OUT [--model M] [--workers 2]
"""

from __future__ import annotations

import argparse
import csv
from multiprocessing import Pool
from pathlib import Path

import frontiernet.exploration.explorer as explorer_module
from frontiernet.benchmark.plan import scene_key


def integrate_ground_truth(self, depth, frame, T) -> None:
    """Explorer._integrate with the frame's sensor depth in place of the depth source's."""
    self.map.integrate(frame.depth, frame.K, T)
    self.map.clear_sphere(T[:3, 3], self.agent.radius)


def one_run(task: dict) -> dict:
    from frontiernet.exploration.run import load_run_config, main

    explorer_module.Explorer._integrate = integrate_ground_truth
    out = Path(task["out"]) / task["key"]
    record = main(load_run_config(), task["scene"], out, method=task["method"], model=task["model"],
                  depth="emulated", max_steps=task["budget"], start=task["start"], seed=0, video=False,
                  progress=False)
    vox = record["vox_at"]
    return {"scene": task["scene"], "method": task["method"], "start": task["index"], "repeat": 0, "status": "done",
            "vox25": vox["25"], "vox50": vox["50"], "vox100": vox["100"], "stop_reason": record["stop_reason"],
            "steps": record["steps"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("plan_folder")
    parser.add_argument("method")
    parser.add_argument("out")
    parser.add_argument("--model", default=None)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--budget", type=int, default=300)
    args = parser.parse_args()
    from frontiernet.benchmark.store import read_plan

    plan = read_plan(args.plan_folder)
    tasks = [{"scene": scene, "index": index, "start": ",".join(str(v) for v in pose), "method": args.method,
              "model": args.model, "budget": args.budget, "out": args.out,
              "key": f"{scene_key(scene)}_start{index}"}
             for scene, poses in plan["start_poses"].items() for index, pose in enumerate(poses)]
    Path(args.out).mkdir(parents=True, exist_ok=True)
    with Pool(args.workers) as pool:
        rows = pool.map(one_run, tasks, chunksize=1)
    with open(Path(args.out) / "results.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    for row in rows:
        print(row)


if __name__ == "__main__":
    main()

"""Frame-level view of the oracle's hybrids (issue 27, step 3): what each one's frontier pixels
and gains are on the same views, before any closed loop.

For each start pose of a benchmark's ``plan.json`` (first `SCENES` scenes) and 4 headings 90 deg
apart, renders the 480 px view and counts, at each perception's working size:

* the model's frontier pixels (D < l) and the share of them that the model's gain puts in class 0
  (``frontiernet`` drops them: ``anchoring.drop_zero_gain``) and that the ground truth's gain puts
  in class 0 (``frontiernet-oracle-gain`` drops them);
* the ground truth's frontier pixels and the share with ground-truth class 0 (``oracle`` drops
  them; ``oracle-uniform`` gives them the uniform class and keeps them);
* the ground truth's mean decoded gain (m^3) over its kept frontier pixels, and the model's.

    .venv/bin/python tests/bench/hybrid_frames.py /work/bench27_3/plan.json 2
"""

from __future__ import annotations

import sys

import numpy as np


def main(plan_path: str, scenes: int) -> None:
    from pathlib import Path

    from frontiernet.benchmark.store import read_plan
    from frontiernet.config import load_config
    from frontiernet.exploration.methods import MethodContext, make_method
    from frontiernet.exploration.run import run_section
    from frontiernet.frontiers.gain import decode_gain
    from frontiernet.geometry import pose_from_heading
    from frontiernet.simulator.world import build_world

    conf = load_config("explore")
    sim = run_section(conf, "sim")
    plan = read_plan(Path(plan_path).parent if Path(plan_path).name.startswith("plan.json") else plan_path)
    pitch = np.radians(float(conf.motion.pitch_deg))
    for spec, poses in list(plan["start_poses"].items())[:scenes]:
        world = build_world(spec, sim, run_section(conf, "scenes"))
        scene, voxels, renderer = world.scene, world.voxels, world.renderer
        context = MethodContext(conf, sim, scene=scene, voxels=voxels)
        hybrid = make_method("frontiernet-oracle-gain", context).source.perception
        model, oracle = hybrid.base, hybrid.gain_source
        sums = np.zeros(8)
        for x, y, z, yaw in poses:
            for turn in (0, 90, 180, 270):
                frame = renderer.render(pose_from_heading(x, y, z, np.radians(yaw + turn), pitch))
                mixed, own, truth = hybrid(frame, frame.depth), model(frame, frame.depth), oracle(frame, frame.depth)
                where = own.distance_field < own.labels["frontier_threshold_px"]
                truth_where = truth.distance_field < truth.labels["frontier_threshold_px"]
                truth_gain = decode_gain(truth.gain_class, truth.labels["bin_edges"], truth.labels["bin_unit_m3"],
                                         "lower_bound")
                own_gain = decode_gain(own.gain_class, own.labels["bin_edges"], own.labels["bin_unit_m3"],
                                       "lower_bound")
                sums += [where.sum(), (where & (own.gain_class == 0)).sum(), (where & (mixed.gain_class == 0)).sum(),
                         truth_where.sum(), (truth_where & (truth.gain_class == 0)).sum(),
                         truth_gain[truth_where & (truth.gain_class > 0)].sum(),
                         own_gain[where & (own.gain_class > 0)].sum(), 1]
        n, own_zero, truth_zero_on_model, gt_n, gt_zero, gt_gain, own_gain_sum, views = sums
        print(f"{spec}: {int(views)} views; model frontier px {n / views:.0f}/view at 320 px, class 0 by the model "
              f"{own_zero / max(n, 1):.0%}, by the ground truth {truth_zero_on_model / max(n, 1):.0%}; "
              f"ground-truth frontier px {gt_n / views:.0f}/view at 480 px, class 0 {gt_zero / max(gt_n, 1):.0%}; "
              f"mean gain of kept px: ground truth {gt_gain / max(gt_n - gt_zero, 1):.1f} m^3, "
              f"model {own_gain_sum / max(n - own_zero, 1):.1f} m^3", flush=True)


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 2)

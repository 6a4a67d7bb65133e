"""Audit of the frontier bookkeeping (issue 27, step 4; docs/benchmark.md): is a frontier removed
for low gain really one whose space is seen?

Runs one exploration (``exploration.run.main``, 300 steps, no video; ground-truth depth, or the
``DEPTH`` environment variable's source, with the ``MODEL`` file) and, at each removal,
measures the true unseen explorable volume the tracker's gain view (``tracking.gain_view``) still
sees from the frontier, best of ``tracking.unknown_cap_yaw_offsets_deg`` around its direction: rays
pass every voxel the *scene* does not occupy and count the explorable voxels the robot's map has not
observed. Writes every removal (step, reason, predicted gain, gain when removed, true unseen volume,
the map's unknown volume) and a summary to OUT.json; prints the summary.

    .venv/bin/python tests/bench/audit_removals.py OUT.json procedural:2000 "13.4,1.7,1.2,163.26" \
        oracle [tracking.gain_reduction=none ...]
    DEPTH=emulated MODEL=model.onnx .venv/bin/python tests/bench/audit_removals.py ... frontiernet
"""
import json
import os
import sys
import time

import numpy as np

import frontiernet.exploration.explorer as explorer_module
from frontiernet.exploration.run import load_run_config, main
from frontiernet.frontiers import tracking
from frontiernet.mapping.traversal import frustum_volume
from frontiernet.simulator.camera import PinholeCamera

out_path, scene, start = sys.argv[1:4]
method = sys.argv[4] if len(sys.argv) > 4 else "oracle"
overrides = sys.argv[5:]
depth, model = os.environ.get("DEPTH", "gt"), os.environ.get("MODEL")
conf = load_run_config(overrides=overrides)
CURRENT = {}
RECORDS = []
view = conf.tracking.gain_view
camera = PinholeCamera(int(view.width_px), int(view.width_px), float(view.focal_px), float(view.focal_px),
                       (int(view.width_px) - 1) / 2.0, (int(view.width_px) - 1) / 2.0, float(view.max_depth_m))
directions = camera.ray_directions().reshape(-1, 3).astype(np.float64)
turns = np.radians(np.asarray(list(conf.tracking.unknown_cap_yaw_offsets_deg) or [0.0], np.float64))

original_track = explorer_module.Explorer._track


def _track(self, observations, T):
    CURRENT["explorer"] = self
    return original_track(self, observations, T)


original_remove = tracking.FrontierTracker.remove


def remove(self, frontier_id, reason):
    explorer = CURRENT.get("explorer")
    frontier = self.frontiers.get(frontier_id)
    if explorer is not None and frontier is not None:
        voxels = explorer.voxels
        position = frontier.position.copy()
        if self.view_z is not None:
            position[2] = self.view_z
        poses = tracking.poses_from_headings(np.repeat(position[None], len(turns), 0), frontier.yaw + turns)
        volumes = np.empty(len(turns))
        counted = voxels.explorable & ~explorer.map.observed
        frustum_volume(np.ascontiguousarray(poses[:, :3, 3]), np.ascontiguousarray(poses[:, :3, :3]), directions,
                       float(view.max_depth_m), float(view.focal_px), voxels.origin, voxels.voxel_size,
                       ~voxels.occupied, counted, volumes)
        map_unknown = explorer.map.visible_unknown_volume(poses, int(view.width_px), float(view.focal_px),
                                                          float(view.max_depth_m))
        RECORDS.append({"step": int(explorer.agent.steps), "reason": reason,
                        "predicted_m3": float(frontier.predicted_gain_m3), "gain_m3": float(frontier.gain_m3),
                        "true_unseen_m3": float(volumes.max()), "map_unknown_m3": float(map_unknown.max()),
                        "position": np.round(frontier.position, 2).tolist()})
    return original_remove(self, frontier_id, reason)


explorer_module.Explorer._track = _track
tracking.FrontierTracker.remove = remove
clock = time.time()
record = main(conf, scene, out_path + ".run", method=method, model=model, depth=depth, max_steps=300, start=start,
              video=False, progress=False)
low = [r for r in RECORDS if r["reason"] == "low_gain"]
true = np.array([r["true_unseen_m3"] for r in low]) if low else np.zeros(0)
summary = {"scene": scene, "method": method, "depth": depth, "overrides": overrides,
           "vox100": record["coverage"], "steps": record["steps"], "stop_reason": record["stop_reason"],
           "removals": len(RECORDS), "low_gain": len(low),
           "low_gain_true_ge_1m3": int((true >= 1.0).sum()), "low_gain_true_ge_5m3": int((true >= 5.0).sum()),
           "low_gain_true_median_m3": float(np.median(true)) if len(true) else None,
           "wall_s": round(time.time() - clock, 1)}
json.dump({"summary": summary, "records": RECORDS}, open(out_path, "w"))
print(json.dumps(summary))

"""Explorable volume under the two rules of ``sim.voxels.explorable``, scene by scene.

Each scene is voxelised once (the surface voxels are the same for both rules); the ``enclosed``
rule (the published benchmark's per-slice flood) and the ``reachable`` rule
(frontiernet/scenes/explorable.py) then pick their explorable voxels from it. Printed per
scene: both volumes in m^3, the change, and the voxels only one rule counts (where they lie in
height, so that a change can be explained). Default scenes: the shared house, the four KTH
plans, procedural:1000-1009 (published) and procedural:2000-2003 (development).

    .venv/bin/python tests/bench/explorable_rules.py [SPEC ...] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from frontiernet.config import load_config
from frontiernet.scenes import load_scene
from frontiernet.scenes.spec import expand_specs
from frontiernet.scenes.explorable import reachable_space
from frontiernet.simulator.voxels import voxelize_scene

SHARED = Path(__file__).resolve().parents[2].parent / "shared" / "data"
DEFAULT_SCENES = [str(SHARED / "scenes" / "aws_small_house.glb"), str(SHARED / "floorplans" / "kth"),
                  "procedural:1000-1009", "procedural:2000-2003"]


def compare(spec: str, conf) -> dict:
    """Both rules' explorable volume on one scene, and where they differ."""
    scene = load_scene(spec, load_config("scenes"))
    clock = time.perf_counter()
    grid = voxelize_scene(scene, OmegaConf.merge(conf, {"explorable": "enclosed"}))
    enclosed_s = time.perf_counter() - clock
    clock = time.perf_counter()
    space = reachable_space(grid.occupied, grid.origin, grid.voxel_size, conf, seed=scene.metadata.explorable_seed,
                            box=scene.metadata.explorable_bounds, where=spec)
    reachable_s = time.perf_counter() - clock
    old, new = grid.explorable, space.explorable
    cube = grid.voxel_size ** 3
    heights = grid.origin[2] + (np.arange(grid.shape[2]) + 0.5) * grid.voxel_size

    def layers(mask):  # metres above the grid's bottom of the layers holding `mask` voxels
        counts = mask.sum(axis=(0, 1))
        return [round(float(heights[k] - grid.origin[2]), 2) for k in np.flatnonzero(counts)]

    only_new, only_old = new & ~old, old & ~new
    return {"spec": spec, "enclosed_m3": round(old.sum() * cube, 2), "reachable_m3": round(new.sum() * cube, 2),
            "change_pct": round(100.0 * (new.sum() - old.sum()) / max(old.sum(), 1), 2),
            "only_reachable_m3": round(only_new.sum() * cube, 2), "only_enclosed_m3": round(only_old.sum() * cube, 2),
            "only_reachable_voxels": int(only_new.sum()), "only_enclosed_voxels": int(only_old.sum()),
            "only_reachable_layers_m": layers(only_new), "only_enclosed_layers_m": layers(only_old),
            "seed_voxel": None if space.seed is None else space.seed.tolist(),
            "enclosed_s": round(enclosed_s, 2), "reachable_s": round(reachable_s, 2)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("specs", nargs="*", help="scene specs (default: the shared house, KTH, procedural)")
    parser.add_argument("--json", help="also write the rows to this JSON file")
    args = parser.parse_args()
    conf = load_config("sim").voxels
    specs = expand_specs(args.specs or [s for s in DEFAULT_SCENES if s.startswith("procedural") or Path(s).exists()])
    rows = []
    print(f"{'scene':58s} {'enclosed':>9s} {'reachable':>9s} {'change':>7s} {'+only':>7s} {'-only':>7s}  m^3")
    for spec in specs:
        row = compare(spec, conf)
        rows.append(row)
        print(f"{spec[-58:]:58s} {row['enclosed_m3']:9.1f} {row['reachable_m3']:9.1f} {row['change_pct']:6.2f}% "
              f"{row['only_reachable_m3']:7.1f} {row['only_enclosed_m3']:7.1f}", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()

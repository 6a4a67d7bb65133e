"""How much of the space a robot could plan through does a map built from monocular depth lose
(issue 27, docs/exploration.md "Monocular depth")?

For each start of a benchmark plan, runs ``classic`` on ground-truth depth for BUDGET steps (the
trajectory), then replays that trajectory's frames into maps: one from the ground truth's sensor
depth (the reference) and one per variant from emulated monocular depth (the same seeded error
sequence for every variant, so the variants are paired). At each checkpoint it builds each map's
planning grid (``PlanningGrid.from_map``, the planner's own rule) and counts, over the cells
reachable from the robot on the reference grid:

- ``lost``: the share the variant's grid cannot reach from the robot (doors sealed, walls
  thickened into the room);
- ``extra``: cells reachable on the variant's grid that are not traversable on the reference's,
  as a share of the reference's reachable cells (space carved through walls);
- ``occ_far``: the variant's occupied voxels in the planning band farther than one voxel from
  every occupied voxel of the reference map, per reference occupied voxel (thickening, phantoms);
- ``frontiers``: the variant's map frontiers (``classic``'s, :func:`map_frontiers`) per frontier of
  the reference map (unknown left beside free space becomes goals).

Variants are ``name:key=value,key=value`` of the ``map`` section (e.g.
``sym:log_odds_miss=-0.85``); ``base`` is the shipped section.

    .venv/bin/python tests/bench/map_quality.py PLAN_FOLDER OUT.json [VARIANT ...] [--budget 300]
        [--checkpoints 100 200 300]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf
from scipy import ndimage


def reachable(grid, xy: np.ndarray) -> np.ndarray:
    """(X, Y) bool: the traversable cells 8-connected to the robot's cell on `grid`."""
    traversable = np.isfinite(grid.cost)
    labels, _ = ndimage.label(traversable, structure=np.ones((3, 3), bool))
    i, j = grid.cell(xy)
    return labels == labels[i, j] if labels[i, j] else np.zeros_like(traversable)


def grid_view(occupancy, z: float, xy: np.ndarray, conf, T: np.ndarray) -> dict:
    """What :func:`compare` reads of one map at the robot's pose: its planning grid, the cells
    reachable from the robot, the occupied cells of the planning band and its map frontiers."""
    from frontiernet.frontiers.map_frontiers import map_frontiers
    from frontiernet.planning.planner import PlanningGrid

    band = float(conf.planner["height_band_m"])
    grid = PlanningGrid.from_map(occupancy, z, conf.planner, xy)
    return {"traversable": np.isfinite(grid.cost), "reach": reachable(grid, xy),
            "occupied": occupancy.slice_2d(z - band, z + band)[1],
            "frontiers": len(map_frontiers(occupancy, z, conf, T, "uniform"))}


def compare(reference: dict, variant: dict) -> dict:
    """The four measures of a variant's :func:`grid_view` against the reference's."""
    n = max(int(reference["reach"].sum()), 1)
    near_ref = ndimage.binary_dilation(reference["occupied"], np.ones((3, 3), bool))
    return {"lost": float((reference["reach"] & ~variant["reach"]).sum()) / n,
            "extra": float((variant["reach"] & ~reference["traversable"]).sum()) / n,
            "occ_far": float((variant["occupied"] & ~near_ref).sum()) / max(int(reference["occupied"].sum()), 1),
            "frontiers": variant["frontiers"] / max(reference["frontiers"], 1)}


def trajectory(scene: str, start: list, budget: int, out: Path) -> list[np.ndarray]:
    from frontiernet.benchmark.plan import scene_key
    from frontiernet.exploration.run import load_run_config, main

    folder = out / f"{scene_key(scene)}_{'_'.join(map(str, start))}"
    if not (folder / "trajectory.json").exists():
        main(load_run_config(), scene, folder, method="classic", depth="gt", max_steps=budget,
             start=",".join(map(str, start)), seed=0, video=False, progress=False)
    return [np.asarray(T) for T in json.loads((folder / "trajectory.json").read_text())["T_world_cam"]]


def replay(scene: str, poses: list, variants: dict, checkpoints: list[int]) -> dict:
    from frontiernet.depth import make_depth_source
    from frontiernet.exploration.run import load_run_config, run_section
    from frontiernet.mapping import OccupancyMap
    from frontiernet.simulator.world import build_world

    conf = load_run_config()
    world = build_world(scene, run_section(conf, "sim"), run_section(conf, "scenes"))
    reference = OccupancyMap.like(world.voxels, conf.map)
    maps = {name: OccupancyMap.like(world.voxels, OmegaConf.merge(conf.map, overrides))
            for name, overrides in variants.items()}
    source = make_depth_source("emulated", run_section(conf, "depth"))
    source.reset(0)
    radius = float(run_section(conf, "sim").agent.radius_m)
    rows = {name: {} for name in variants}
    for index, T in enumerate(poses):
        frame = world.renderer.render(T)
        depth = source.estimate(frame.rgb, frame.K, frame.hit_depth)
        reference.integrate(frame.depth, frame.K, T)
        reference.clear_sphere(T[:3, 3], radius)
        for occupancy in maps.values():
            occupancy.integrate(depth, frame.K, T, monocular=True)
            occupancy.clear_sphere(T[:3, 3], radius)
        if index in checkpoints or index == len(poses) - 1:
            z, xy = float(T[2, 3]), T[:2, 3]
            seen = grid_view(reference, z, xy, conf, T)  # once per checkpoint, not per variant
            for name, occupancy in maps.items():
                rows[name][index] = compare(seen, grid_view(occupancy, z, xy, conf, T))
    return rows


def parse_variant(text: str) -> tuple[str, dict]:
    name, _, body = text.partition(":")
    overrides = {}
    for item in filter(None, body.split(",")):
        key, value = item.split("=")
        overrides[key] = None if value == "null" else float(value)
    return name, overrides


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("plan_folder")
    parser.add_argument("out")
    parser.add_argument("variants", nargs="*")
    parser.add_argument("--budget", type=int, default=300)
    parser.add_argument("--checkpoints", type=int, nargs="+", default=[100, 200, 300])
    args = parser.parse_args()
    variants = dict([("base", {})] + [parse_variant(v) for v in args.variants])
    from frontiernet.benchmark.store import read_plan

    plan = read_plan(args.plan_folder)
    out = Path(args.out)
    cache = out.parent / (out.stem + "_trajectories")
    results = json.loads(out.read_text()) if out.exists() else {}
    for scene, starts in plan["start_poses"].items():
        for k, start in enumerate(starts):
            key = f"{scene} {k}"
            if key in results and all(v in results[key] for v in variants):
                continue
            poses = trajectory(scene, start, args.budget, cache)
            results[key] = replay(scene, poses, variants, args.checkpoints)
            out.write_text(json.dumps(results, indent=1))
            last = {name: rows[max(rows, key=int)] for name, rows in results[key].items()}
            print(key, {name: {m: round(v, 3) for m, v in row.items()} for name, row in last.items()}, flush=True)
    for name in variants:
        for metric in ("lost", "extra", "occ_far", "frontiers"):
            values = [rows[name][max(rows[name], key=int)][metric] for rows in results.values() if name in rows]
            print(f"{name:>12} {metric:>8} mean {np.mean(values):.3f} median {np.median(values):.3f} (n {len(values)})")


if __name__ == "__main__":
    main()

"""What the emulated monocular depth does to a frame, measured on sampled views of a scene.

For views at sampled start poses (the shared house when it is there, else ``procedural:0``):

* the share of pixels beyond the sensor range (3.5 m) whose emulated depth lands inside it,
  where the map integrates them as hits: the emulation of ``configs/depth.yaml`` (which degrades
  the renderer's ``hit_depth``) against the old one (the range-clipped depth with beyond-range
  pixels at ``fill_depth`` 3.5 m, one scale per episode, fresh noise each frame);
* the emulation's per-frame accuracy on the pixels in range, in the metrics the monocular
  papers report (AbsRel, delta1), to compare with the figures ``configs/depth.yaml`` cites;
* its frame-to-frame change at a standing camera (mean |log ratio| of consecutive estimates of
  the same view), to compare with the temporal alignment error (TAE) it cites.

    .venv/bin/python tests/bench/emulated_depth_stats.py [--views 40] [--frames 20] [--scene SPEC]
"""

from __future__ import annotations

import argparse

import numpy as np

from frontiernet.benchmark.perf import default_bench_scene
from frontiernet.config import load_config
from frontiernet.depth import make_depth_source
from frontiernet.exploration.region import start_sampler
from frontiernet.simulator.world import build_world

OLD = {"fill_depth": 3.5, "scale_per_frame": False, "frame_correlation": 0.0}
"""The emulation before it saw past the sensor range (with the clipped ground truth)."""


def landed_inside(source, frames, far: bool, max_range: float) -> float:
    """Share of the beyond-range pixels (NaN in ``frame.depth``) estimated within `max_range`."""
    source.reset(0)
    inside = beyond = 0
    for frame in frames:
        estimate = source.estimate(frame.rgb, frame.K, frame.hit_depth if far else frame.depth)
        mask = ~np.isfinite(frame.depth)
        beyond += int(mask.sum())
        inside += int((mask & (estimate <= max_range)).sum())
    return inside / max(beyond, 1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--views", type=int, default=40)
    parser.add_argument("--frames", type=int, default=20, help="frames of a standing camera, per view")
    parser.add_argument("--scene", default=None)
    args = parser.parse_args()
    spec = default_bench_scene(args.scene)
    sim = load_config("sim")
    world = build_world(spec, sim, load_config("scenes"))
    _, draw = start_sampler(world.scene, world.voxels, load_config("explore"))
    rng = np.random.default_rng(1)
    renderer = world.renderer
    frames = [renderer.render(draw(rng)) for _ in range(args.views)]
    max_range = float(sim.camera.max_depth)
    print(f"{spec}: {args.views} views, {np.mean([np.mean(~np.isfinite(f.depth)) for f in frames]):.0%} of "
          f"their pixels beyond {max_range} m")
    shipped = load_config("depth").emulated
    old, new = make_depth_source("emulated", {**shipped, **OLD}), make_depth_source("emulated", shipped)
    print(f"beyond-range pixels estimated inside the range (map hits): old {landed_inside(old, frames, False, max_range):.1%},"
          f" now {landed_inside(new, frames, True, max_range):.1%}")
    abs_rel, delta1, change = [], [], []
    for index, frame in enumerate(frames):
        new.reset(index)
        valid = np.isfinite(frame.depth)
        estimates = [new.estimate(frame.rgb, frame.K, frame.hit_depth) for _ in range(args.frames)]
        ratio = estimates[0][valid] / frame.depth[valid]
        abs_rel.append(np.mean(np.abs(ratio - 1.0)))
        delta1.append(np.mean(np.maximum(ratio, 1.0 / ratio) < 1.25))
        change += [np.mean(np.abs(np.log(b[valid] / a[valid]))) for a, b in zip(estimates, estimates[1:])]
    print(f"per frame, pixels in range: AbsRel {np.mean(abs_rel):.3f}, delta1 {np.mean(delta1):.3f}; "
          f"consecutive frames of a standing camera differ by {np.mean(change):.1%} (mean |log ratio|)")


if __name__ == "__main__":
    main()

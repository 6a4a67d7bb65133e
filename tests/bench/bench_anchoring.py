"""Benchmark of anchoring (paper III-E) on realistic 320 x 320 views, as a ratio to a baseline.

Views of a scene (the shared house when it is there, else ``procedural:0``) are rendered at
the model's input size (320 x 320, f = 200 px: the paper's 480 px / f = 300 px camera
resized), the shipped model predicts D and the gain classes, and
:func:`frontiernet.frontiers.anchor_prediction` turns them into 3D frontiers. Machines are
noisy, so each anchoring time is also given as a ratio to a baseline on the same image:
``cv2.Sobel`` (dx and dy, kernel 9) + ``scipy.ndimage.distance_transform_edt``.
A last, synthetic view has dense frontier bands (~15000 frontier pixels) to show the
``max_pixels`` bound. The summary covers the views with at least 100 frontier pixels.

    .venv/bin/python tests/bench/bench_anchoring.py [--views 8] [--repeats 5] [--scene SPEC]

Goal: anchoring well under 50 ms on 2 CPU cores (model + anchoring at 5 Hz).
"""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np
from scipy import ndimage

from frontiernet.benchmark.perf import default_bench_scene
from frontiernet.config import load_config
from frontiernet.frontiers import anchor_prediction
from frontiernet.model.predictor import Predictor
from frontiernet.simulator.poses import sample_poses
from frontiernet.simulator.world import build_world

SIZE, FOCAL, MAX_DEPTH = 320, 200.0, 3.5


def best_time(function, repeats: int) -> float:
    """Fastest of `repeats` calls, seconds."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return min(times)


def baseline(depth: np.ndarray, mask: np.ndarray) -> None:
    """The reference work: Sobel derivatives of depth and a distance transform of the mask."""
    filled = np.nan_to_num(depth, nan=MAX_DEPTH).astype(np.float32)
    cv2.Sobel(filled, cv2.CV_32F, 1, 0, ksize=9)
    cv2.Sobel(filled, cv2.CV_32F, 0, 1, ksize=9)
    ndimage.distance_transform_edt(~mask)


def predicted_views(scene_spec: str, views: int, seed: int) -> list[dict]:
    """Rendered views with the shipped model's outputs: depth, D, gain classes, K, pose."""
    sim = load_config("sim")
    sim.camera.update(width=SIZE, height=SIZE, focal_px=FOCAL, max_depth=MAX_DEPTH, background=[0, 0, 0])
    world = build_world(scene_spec, sim, load_config("scenes"))
    poses = sample_poses(world.scene, world.voxels, views, seed, sim.poses)
    renderer = world.renderer
    predictor = Predictor(threads=2)
    out = []
    for T in poses:
        frame = renderer.render(T)
        distance, logits = predictor.predict(frame.rgb, np.nan_to_num(frame.depth, nan=0.0))
        out.append({"name": "model", "depth": frame.depth, "distance": distance, "gain_class": logits.argmax(0),
                    "K": frame.K, "T": T, "labels": predictor.labels})
    return out


def dense_view(labels: dict, K: np.ndarray) -> dict:
    """A synthetic view with wide frontier bands on a row of occluders (~15000 frontier pixels)."""
    depth = np.full((SIZE, SIZE), 3.0, np.float32)
    for u0 in range(20, SIZE - 40, 60):
        depth[40:280, u0:u0 + 30] = 1.5
    edges = np.abs(cv2.Sobel(depth, cv2.CV_32F, 1, 0, ksize=3)) > 0
    distance = ndimage.distance_transform_edt(~ndimage.binary_dilation(edges, iterations=2)).astype(np.float32)
    return {"name": "dense", "depth": depth, "distance": distance, "gain_class": np.full((SIZE, SIZE), 6),
            "K": K, "T": np.eye(4), "labels": labels}


def time_view(view: dict, conf, repeats: int) -> tuple[int, int, float, float]:
    """(frontier pixels, frontiers, anchoring seconds, baseline seconds) of one view."""
    threshold = conf.frontier_threshold_px or view["labels"]["frontier_threshold_px"]
    mask = view["distance"] < threshold

    def anchor():
        return anchor_prediction(view["distance"], view["gain_class"], view["depth"], view["K"], view["T"],
                                 conf, view["labels"], np.random.default_rng(0))

    count = len(anchor())
    return int(mask.sum()), count, best_time(anchor, repeats), best_time(lambda: baseline(view["depth"], mask), repeats)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--views", type=int, default=12)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--scene", default=None, help="scene spec (default: the shared house or procedural:0)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    conf = load_config("explore").anchoring
    cv2.setNumThreads(2)

    views = predicted_views(default_bench_scene(args.scene), args.views, args.seed)
    views.append(dense_view(views[0]["labels"], views[0]["K"]))
    print(f"{'view':>8} {'F px':>6} {'frontiers':>9} {'anchoring ms':>12} {'baseline ms':>11} {'ratio':>6}")
    ratios, times = [], []
    for index, view in enumerate(views):
        pixels, count, anchoring_s, baseline_s = time_view(view, conf, args.repeats)
        ratio = anchoring_s / baseline_s
        if pixels >= 100:
            ratios.append(ratio)
            times.append(anchoring_s)
        print(f"{view['name'] + str(index):>8} {pixels:>6} {count:>9} {anchoring_s * 1e3:>12.1f} "
              f"{baseline_s * 1e3:>11.2f} {ratio:>6.1f}")
    print(f"views with >= 100 frontier pixels: {len(times)}")
    print(f"anchoring / baseline: median {np.median(ratios):.1f}x, max {np.max(ratios):.1f}x; "
          f"anchoring median {np.median(times) * 1e3:.1f} ms, max {np.max(times) * 1e3:.1f} ms (goal < 50 ms)")


if __name__ == "__main__":
    main()

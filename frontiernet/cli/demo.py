"""``frontiernet demo``: a fly-through of the default scene with FrontierNet's proposals (``make demo``).

Each frame is rendered, given a depth prior (``configs/demo.yaml: depth``, emulated monocular
by default) and passed through the model (the shipped one unless ``--model``). Writes
``flythrough.mp4`` (camera image beside its frontier overlay: frontier pixels coloured by
gain class), ``contact_sheet.png`` (a grid of overlay frames), ``topdown.png`` (the path on a
cut-away top view) and ``trajectory.json`` to ``--out``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..config import load_config


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("demo", help="render a fly-through of the default scene",
                                   description=__doc__.splitlines()[0])
    parser.add_argument("--scene", help="scene spec (default: configs/demo.yaml `scene`)")
    parser.add_argument("--out", default="outputs/demo", help="output folder (default outputs/demo)")
    parser.add_argument("--frames", type=int, help="at most this many frames")
    parser.add_argument("--config", help="YAML overriding configs/demo.yaml")
    parser.add_argument("--model", help="model file (default: the shipped model)")
    parser.add_argument("--no-model", action="store_true", help="render only, no network")
    parser.set_defaults(func=run)


def write_video(path: Path, frames: list[np.ndarray], fps: float) -> None:
    """Write (H, W, 3) uint8 RGB frames to an MP4 file atomically."""
    import cv2

    from ..io import atomic_write

    def write(tmp: Path) -> None:
        height, width = frames[0].shape[:2]
        writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*"mp4v"), fps, (width, height))
        for frame in frames:
            writer.write(np.ascontiguousarray(frame[..., ::-1]))
        writer.release()

    atomic_write(path, write)


def draw_path(topdown: np.ndarray, xy: np.ndarray, bounds: np.ndarray, pixel_size: float) -> np.ndarray:
    """Draw world (N, 2) points onto a top view made by :func:`~frontiernet.scenes.preview.topdown_image`."""
    import cv2

    image = topdown.copy()
    cols = ((xy[:, 0] - bounds[0, 0]) / pixel_size).astype(np.int32)
    rows = ((bounds[1, 1] - xy[:, 1]) / pixel_size).astype(np.int32)
    points = np.stack([cols, rows], 1).reshape(-1, 1, 2)
    cv2.polylines(image, [points], False, (255, 40, 40), max(1, image.shape[1] // 300))
    cv2.circle(image, tuple(int(v) for v in points[0, 0]), max(3, image.shape[1] // 120), (40, 200, 40), -1)
    return image


class FrameProposals:
    """Rendered frame -> [camera image | frontier overlay] with the model at its input size."""

    def __init__(self, model, conf):
        from ..depth import make_depth_source
        from ..model import Predictor

        self.predictor = Predictor(model)
        self.depth_source = make_depth_source(conf.depth, load_config("depth"))
        self.depth_source.reset(0)

    def __call__(self, frame) -> np.ndarray:
        from ..model import invalid_to_zero
        from ..model.overlay import frontier_overlay

        depth = self.depth_source.estimate(frame.rgb, frame.K, frame.depth)
        result = self.predictor.predict_at_size(frame.rgb, invalid_to_zero(depth),
                                                int(self.predictor.conf["inference"]["size"]))
        labels = self.predictor.labels
        overlay = frontier_overlay(result["rgb"], result["distance_field"], result["gain_class"],
                                   float(labels["frontier_threshold_px"]), int(labels["num_classes"]))
        return np.concatenate([result["rgb"], overlay], axis=1)


def run(args) -> int:
    from rich.progress import Progress

    from ..io import ensure_dir, write_image, write_json
    from ..scenes import load_scene
    from ..scenes.preview import contact_sheet, topdown_image
    from ..simulator.agent import Agent
    from ..simulator.camera import PinholeCamera, Renderer
    from ..simulator.flythrough import plan_flythrough
    from ..simulator.voxels import voxelize_scene

    conf = load_config("demo", args.config)
    sim = load_config("sim")
    if args.frames is not None:
        conf.flythrough.max_frames = args.frames
    out = ensure_dir(args.out)
    start = time.perf_counter()
    spec = args.scene or conf.scene
    scene = load_scene(spec)
    voxels = voxelize_scene(scene, sim.voxels)
    poses = plan_flythrough(scene, voxels, conf.flythrough)
    renderer = Renderer(scene, PinholeCamera.from_config(sim.camera), sim.camera.background)
    agent = Agent(scene, poses[0], sim.agent, voxels)
    proposals = None if args.no_model else FrameProposals(args.model, conf)
    frames, trajectory, collisions = [], [], 0
    with Progress(transient=True) as progress:
        task = progress.add_task(f"fly-through of {scene.name}", total=len(poses))
        for target in poses:
            result = agent.move_to(target)
            collisions += int(result.collided)
            trajectory.append(agent.pose.copy())
            frame = renderer.render(agent.pose)
            frames.append(frame.rgb if proposals is None else proposals(frame))
            progress.advance(task)
    write_video(out / "flythrough.mp4", frames, float(conf.fps))
    picks = np.linspace(0, len(frames) - 1, min(int(conf.contact_sheet_frames), len(frames))).astype(int)
    write_image(out / "contact_sheet.png",
                contact_sheet([frames[i][::2, ::2] for i in picks], columns=4, labels=[f"frame {i}" for i in picks]))
    pixel_size = 0.05
    xy = np.array([pose[:2, 3] for pose in trajectory])
    write_image(out / "topdown.png", draw_path(topdown_image(scene, pixel_size), xy, scene.bounds, pixel_size))
    write_json(out / "trajectory.json", {
        "scene": spec, "frames": len(frames), "steps": agent.steps, "collisions": collisions,
        "path_length_m": float(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum()),
        "T_world_cam": [pose.tolist() for pose in trajectory]})
    print(f"demo: {len(frames)} frames of {scene.name} ({agent.steps} steps, "
          f"{time.perf_counter() - start:.1f} s) -> {out}/flythrough.mp4, contact_sheet.png, topdown.png")
    return 0

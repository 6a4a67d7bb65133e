"""``frontiernet render``: one view of a scene: ``rgb.png``, ``depth.npy`` (metres), ``depth.png``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..config import load_config
from ..errors import InputError
from ..geometry import pose_from_heading


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "render", help="render RGB, depth and normals from a pose",
        description="Render one view. Writes rgb.png, depth.npy (float32 metres, z-depth, NaN = invalid), "
                    "depth.png (coloured, invalid black), normals.png and camera.json (T_world_cam, K).")
    parser.add_argument("spec", metavar="SPEC", help="scene spec (see `frontiernet scene --help`)")
    parser.add_argument("--pose", required=True, metavar="x,y,z,yaw[,pitch]",
                        help="camera position (metres, world Z-up) and heading; angles in radians, "
                             "or degrees with a 'deg' suffix (e.g. 90deg); yaw 0 looks along +x, pitch > 0 up")
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument("--config", help="YAML overriding configs/sim.yaml (camera, voxels)")
    parser.add_argument("--no-check", action="store_true",
                        help="skip the check that the pose lies in the scene's free space")
    parser.set_defaults(func=run)


def parse_pose(text: str) -> tuple[float, float, float, float, float]:
    """``"x,y,z,yaw[,pitch]"`` -> floats; angles in radians or with a ``deg`` suffix."""
    parts = [part.strip() for part in text.split(",")]
    if len(parts) not in (4, 5):
        raise InputError(f"--pose '{text}': expected x,y,z,yaw[,pitch]")
    values = []
    for index, part in enumerate(parts):
        degrees = index >= 3 and part.lower().endswith("deg")
        try:
            value = float(part[:-3] if degrees else part)
        except ValueError:
            raise InputError(f"--pose '{text}': '{part}' is not a number") from None
        if not np.isfinite(value):
            raise InputError(f"--pose '{text}': '{part}' is not finite")
        values.append(np.radians(value) if degrees else value)
    if len(values) == 4:
        values.append(0.0)
    if abs(values[4]) >= np.pi / 2:
        raise InputError(f"--pose '{text}': pitch must lie strictly between -90 and 90 degrees")
    return tuple(values)


def run(args) -> int:
    from ..io import colorize_depth, ensure_dir, write_image, write_json, write_npy
    from ..scenes import load_scene
    from ..simulator.camera import PinholeCamera, Renderer

    conf = load_config("sim", args.config)
    x, y, z, yaw, pitch = parse_pose(args.pose)
    scene = load_scene(args.spec)
    if not args.no_check:
        from ..simulator.poses import check_pose
        from ..simulator.voxels import voxelize_scene

        check_pose(scene, voxelize_scene(scene, conf.voxels), np.array([x, y, z]), conf=conf.poses)
    out = ensure_dir(args.out)
    camera = PinholeCamera.from_config(conf.camera)
    frame = Renderer(scene, camera, conf.camera.background).render(pose_from_heading(x, y, z, yaw, pitch))
    write_image(out / "rgb.png", frame.rgb)
    write_npy(out / "depth.npy", frame.depth)
    write_image(out / "depth.png", colorize_depth(frame.depth, camera.max_depth))
    write_image(out / "normals.png", ((frame.normals * 0.5 + 0.5) * 255 * frame.hit_mask[..., None]).astype(np.uint8))
    write_json(out / "camera.json", {"spec": args.spec, "T_world_cam": frame.T_world_cam.tolist(),
                                     "K": frame.K.tolist(), "width": camera.width, "height": camera.height,
                                     "max_depth": camera.max_depth, "depth_units": "m", "depth_invalid": "NaN"})
    valid = np.isfinite(frame.depth)
    print(f"wrote {Path(out)}: valid depth {valid.mean():.0%}, "
          f"range {np.nanmin(frame.depth) if valid.any() else float('nan'):.2f}-"
          f"{np.nanmax(frame.depth) if valid.any() else float('nan'):.2f} m")
    return 0

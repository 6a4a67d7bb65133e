"""``frontiernet render``: one view of a scene. Writes rgb.png, depth.npy (float32 metres, z-depth,
NaN = invalid), depth.png (coloured, invalid black), normals.png and camera.json (T_world_cam, K)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..geometry import parse_pose_text, pose_from_heading
from . import options


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("render", help="render RGB, depth and normals from a pose", description=__doc__)
    options.scene_world(parser, "camera, voxels")
    parser.add_argument("--pose", required=True, metavar="x,y,z,yaw[,pitch]",
                        help="camera position (metres, world Z-up) and heading; angles in degrees, or radians with "
                             "a 'rad' suffix (e.g. 1.57rad); yaw 0 looks along +x, pitch > 0 up")
    options.output_folder(parser, force=True)
    parser.add_argument("--no-check", action="store_true",
                        help="skip the check that the pose lies in the scene's free space")
    parser.set_defaults(func=run)


RENDER_OUTPUTS = ("rgb.png", "depth.npy", "depth.png", "normals.png", "camera.json")
"""The files ``frontiernet render`` writes in its folder."""


def run(args) -> int:
    from ..io import (check_output_files, check_output_folder, claim_output_folder, colorize_depth, write_image,
                      write_json, write_npy)
    from ..scenes.spec import scene_file
    from ..simulator.world import build_world, load_world_config

    check_output_folder(args.out, args.force)
    check_output_files(args.out, RENDER_OUTPUTS, [(scene_file(args.spec), "the scene"), (args.config, "the config file")])
    x, y, z, yaw, pitch = parse_pose_text(args.pose)
    conf = load_world_config(args.config)
    world = build_world(args.spec, conf, conf.scenes, voxels=not args.no_check)
    if world.voxels is not None:
        from ..simulator.poses import check_pose

        check_pose(world.scene, world.voxels, np.array([x, y, z]), conf=conf.poses)
    camera = world.renderer.camera
    frame = world.renderer.render(pose_from_heading(x, y, z, yaw, pitch))
    with claim_output_folder(args.out, args.force) as out:  # (checked again: a run may have written there since)
        write_image(out / "rgb.png", frame.rgb)
        write_npy(out / "depth.npy", frame.depth)
        write_image(out / "depth.png", colorize_depth(frame.depth, camera.max_depth))
        write_image(out / "normals.png",
                    ((frame.normals * 0.5 + 0.5) * 255 * frame.hit_mask[..., None]).astype(np.uint8))
        write_json(out / "camera.json", {"spec": args.spec, "T_world_cam": frame.T_world_cam.tolist(),
                                         "K": frame.K.tolist(), "width": camera.width, "height": camera.height,
                                         "max_depth": camera.max_depth, "depth_units": "m", "depth_invalid": "NaN"})
    valid = np.isfinite(frame.depth)
    seen = (f"range {np.nanmin(frame.depth):.2f}-{np.nanmax(frame.depth):.2f} m" if valid.any() else
            f"no surface within the camera's max_depth of {camera.max_depth:g} m")  # (was "range nan-nan m")
    print(f"wrote {Path(out)}: valid depth {valid.mean():.0%}, {seen}")
    return 0

"""``frontiernet sequence``: frontier proposals on a captured image sequence (no simulator).

Reads TUM RGB-D, Redwood/Open3D (.log), COLMAP models or a plain folder of images (posed with
pycolmap), fills in depth with a monocular model when the sequence has none, runs the network
per frame and tracks the 3D frontiers across the sequence. Writes to ``--out``:
``frontiers.json``, ``map.ply`` (fused coloured points) + ``frontiers.ply`` (arrows coloured by
gain), ``poses.json``, ``occupancy.npz``, ``overlay.mp4`` and ``summary.json``; per-frame network
outputs in ``cache/`` (a re-run resumes from them).
"""

from __future__ import annotations

from ..errors import InputError
from ..geometry import parse_intrinsics_text
from . import options


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("sequence", help="3D frontier proposals on your own posed images or video frames",
                                   description=__doc__.split("\n\n")[0])
    parser.add_argument("--input", required=True, metavar="PATH",
                        help="sequence folder: TUM (rgb.txt), Redwood (color/ + *.log), COLMAP (cameras.bin, "
                             "sparse/0) or a folder of images")
    parser.add_argument("--format", default="auto", choices=("auto", "tum", "redwood", "colmap", "images"),
                        help="reader (default: detected from the folder)")
    parser.add_argument("--depth", default="sensor",
                        help="sensor (the sequence's depth images) or a monocular model: depth_anything_v2, "
                             "metric3d_v2 (local weights; configs/depth.yaml says where)")
    options.model_option(parser, what="FrontierNet model file")
    parser.add_argument("--intrinsics", metavar="FX,FY,CX,CY",
                        help="pinhole intrinsics in pixels, overriding the reader's (TUM, Redwood, images)")
    parser.add_argument("--stride", type=int, help="use every n-th frame (default: frames.stride)")
    parser.add_argument("--max-frames", type=int, help="use at most this many frames")
    parser.add_argument("--no-video", action="store_true", help="skip overlay.mp4")
    options.config_file(parser, "configs/sequence.yaml")
    options.output_folder(parser)
    options.config_overrides(parser, "tracking.merge_distance_m=0.8")
    parser.set_defaults(func=run)


def camera_from_intrinsics(text: str, input_path):
    """A :class:`~frontiernet.sequences.Camera` of the given intrinsics at the size of the first image."""
    from pathlib import Path

    from ..sequences import Camera
    from ..sequences.readers import IMAGE_SUFFIXES, image_size

    fx, fy, cx, cy = parse_intrinsics_text(text)
    images = sorted(path for path in Path(input_path).rglob("*") if path.suffix.lower() in IMAGE_SUFFIXES
                    and "depth" not in path.parts)
    if not images:
        raise InputError(f"{input_path}: no images found to size the camera of --intrinsics")
    return Camera.pinhole(fx, fy, cx, cy, *image_size(images[0]))


def run(args) -> int:
    from ..sequences.main import load_sequence_config, main

    conf = load_sequence_config(args.config, args.overrides)
    if args.stride is not None:
        conf.frames.stride = args.stride
    if args.max_frames is not None:
        conf.frames.max_frames = args.max_frames
    camera = camera_from_intrinsics(args.intrinsics, args.input) if args.intrinsics else None
    summary = main(conf, args.input, args.out, format=args.format, depth=args.depth, model=args.model, camera=camera,
                   video=not args.no_video)
    print(f"sequence: {summary['frames']} frames ({summary['format']}, {summary['depth']} depth): "
          f"{summary['frontiers_alive']} frontiers alive at the end, removed {summary['frontiers_removed']}; "
          f"{summary['seconds']['total']:.0f} s. Outputs in {args.out}/ (frontiers.json, map.ply, frontiers.ply"
          f"{', overlay.mp4' if not args.no_video else ''})")
    for note in summary["notes"]:
        print(f"  note: {note}")
    return 0

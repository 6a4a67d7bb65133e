"""``frontiernet sequence``: frontier proposals on a captured image sequence (no simulator).

Reads TUM RGB-D, Redwood/Open3D (.log), COLMAP models, a plain folder of images (posed with
pycolmap) or a robot recording (rosbag1 .bag, rosbag2 folder, .mcap, .db3), fills in depth with
a monocular model when the sequence has none, runs the network per frame and tracks the 3D
frontiers across the sequence. Writes to ``--out``: ``frontiers.json``, ``map.ply`` (fused
coloured points) + ``frontiers.ply`` (arrows coloured by gain), ``poses.json``,
``occupancy.npz``, ``overlay.mp4``, ``frontiers.mcap`` (the same as ROS 2 messages for Foxglove
and RViz; ``--rosbag2`` adds a rosbag2 folder) and ``summary.json``; per-frame network outputs
in ``cache/`` (a re-run resumes from them).
"""

from __future__ import annotations

from ..errors import InputError
from ..geometry import check_intrinsics_fit, parse_intrinsics_text
from . import options


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("sequence", help="3D frontier proposals on your own posed images or video frames",
                                   description=__doc__.split("\n\n")[0])
    parser.add_argument("--input", required=True, metavar="PATH", type=options.input_path("sequence or recording"),
                        help="sequence folder: TUM (rgb.txt), Redwood (color/ + *.log), COLMAP (cameras.bin, "
                             "sparse/0) or a folder of images; or a recording: .bag, .mcap, .db3, a rosbag2 folder")
    parser.add_argument("--format", default="auto", choices=("auto", "tum", "redwood", "colmap", "images", "rosbag"),
                        help="reader (default: detected from the input)")
    parser.add_argument("--depth", default="sensor",
                        help="sensor (the sequence's depth images) or a monocular model: depth_anything_v2, "
                             "metric3d_v2 (local weights; configs/depth.yaml says where)")
    options.model_option(parser, what="FrontierNet model file")
    parser.add_argument("--intrinsics", metavar="FX,FY,CX,CY",
                        help="pinhole intrinsics in pixels, overriding the reader's (TUM, Redwood, images, a "
                             "recording's CameraInfo)")
    parser.add_argument("--topics", metavar="ROLE=TOPIC,...",
                        help="a recording's topics where the choice is ambiguous: rgb=/cam/color,depth=/cam/depth,"
                             "info=/cam/info,pose=/odom (pose: a nav_msgs/Odometry or geometry_msgs/PoseStamped "
                             "topic, or /tf; default: found by type)")
    parser.add_argument("--stride", type=int, help="use every n-th frame (default: frames.stride)")
    parser.add_argument("--max-frames", type=int, help="use at most this many frames")
    parser.add_argument("--no-video", action="store_true", help="skip overlay.mp4")
    parser.add_argument("--no-mcap", action="store_true", help="skip frontiers.mcap")
    parser.add_argument("--rosbag2", action="store_true",
                        help="also write the ROS messages as a rosbag2 folder (rosbag2/, sqlite3 storage)")
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
    width, height = image_size(images[0])
    check_intrinsics_fit(fx, fy, cx, cy, width, height)
    return Camera.pinhole(fx, fy, cx, cy, width, height)


def recording_options(args) -> tuple[object, dict | None]:
    """(camera, the recording's reader options): a recording's ``--intrinsics`` are sized by its
    images when they are read, a folder's here."""
    from ..sequences import is_recording
    from ..sequences.rosbag import parse_topics

    if args.format == "rosbag" or (args.format == "auto" and is_recording(args.input)):
        intrinsics = parse_intrinsics_text(args.intrinsics) if args.intrinsics else None
        return None, {"topics": parse_topics(args.topics), "intrinsics": intrinsics}
    camera = camera_from_intrinsics(args.intrinsics, args.input) if args.intrinsics else None
    return camera, ({"topics": parse_topics(args.topics)} if args.topics else None)


def run(args) -> int:
    from ..sequences.main import load_sequence_config, main

    options.refuse_contradictions(args.overrides, {  # (the option replaced the key without a word)
        "frames.stride": (f"--stride {args.stride}", args.stride),
        "frames.max_frames": (f"--max-frames {args.max_frames}", args.max_frames)})
    conf = load_sequence_config(args.config, args.overrides)
    if args.stride is not None:
        conf.frames.stride = args.stride
    if args.max_frames is not None:
        conf.frames.max_frames = args.max_frames
    camera, recording = recording_options(args)
    summary = main(conf, args.input, args.out, format=args.format, depth=args.depth, model=args.model, camera=camera,
                   video=not args.no_video, recording=recording, mcap=not args.no_mcap, rosbag2=args.rosbag2)
    written = ["frontiers.json", "map.ply", "frontiers.ply", *(["overlay.mp4"] if not args.no_video else []),
               *summary.get("ros_outputs", [])]
    print(f"sequence: {summary['frames']} frames ({summary['format']}, {summary['depth']} depth): "
          f"{summary['frontiers_alive']} frontiers alive at the end, removed {summary['frontiers_removed']}; "
          f"{summary['seconds']['total']:.0f} s. Outputs in {args.out}/ ({', '.join(written)})")
    for note in summary["notes"]:
        print(f"  note: {note}")
    return 0

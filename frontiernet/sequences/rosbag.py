"""Robot recordings as sequences (issue 57): rosbag1 ``.bag``, rosbag2 folders (sqlite3 or MCAP
storage), plain ``.mcap`` and ``.db3`` files, read with ``rosbags`` (pure Python, no ROS install).

:func:`read_rosbag` streams the recording once (never holding more than one message), writes
its colour and depth images to a work folder and returns the same :class:`~.frames.Sequence`
as the folder readers, so the rest of ``frontiernet sequence`` is unchanged:

* colour: ``sensor_msgs/Image`` (rgb8, bgr8, rgba8, bgra8, mono8) or ``CompressedImage`` (jpeg,
  png: the bytes are kept as they are);
* depth: ``sensor_msgs/Image`` 16UC1 (millimetres) or 32FC1 (metres), or a 16-bit PNG
  ``CompressedImage``; each colour frame takes the depth frame nearest its stamp, when within
  ``rosbag.depth_max_time_difference_s`` (``configs/sequence.yaml``);
* intrinsics: ``sensor_msgs/CameraInfo`` (distortion undistorted as the COLMAP reader does), or
  ``--intrinsics``;
* poses ``T_world_cam``: the colour frame's chain in ``/tf`` + ``/tf_static`` up to its root
  (the fixed frame: ``map``, ``odom``, ...), else an ``Odometry`` / ``PoseStamped`` topic (chained
  to the camera through tf where tf links them), else pycolmap on the images (up to scale, as
  for a folder of images).

Topics are found by type (and, for images, by the first message's encoding) when that is
unambiguous; ``topics`` (``--topics rgb=...,depth=...,info=...,pose=...``) sets them otherwise.
Frames: the images' ``header.frame_id`` is a ROS optical frame (REP 103: x right, y down, z
forward), the axes of our OpenCV camera frame, so its pose in the fixed frame is ``T_world_cam``.
"""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..config import option_section
from ..errors import InputError
from .frames import Camera, RosFrames, Sequence, SequenceFrame
from .readers import _nearest, check_camera_size
from .ros_extract import RECORDING_SUFFIXES, Extracted, extract, is_recording, messages, open_recording
from .ros_messages import CAMERA_INFO, COMPRESSED, DEPTH_ENCODINGS, IMAGE, POSE_TYPES, R_BODY_OPTICAL, TF, \
    camera_from_info
from .ros_tf import Track, chain_poses, describe

__all__ = ["RECORDING_SUFFIXES", "ROLES", "is_recording", "open_recording", "parse_topics", "read_rosbag",
           "rosbag_config", "select_topics"]
ROLES = ("rgb", "depth", "info", "pose")
ROSBAG_OPTIONS = ("depth_max_time_difference_s", "pose_max_time_difference_s", "camera_axes")
"""The keys of the ``rosbag`` section of ``configs/sequence.yaml``."""
_WANTS = {"rgb": (IMAGE, COMPRESSED), "depth": (IMAGE, COMPRESSED), "info": (CAMERA_INFO,), "pose": (*POSE_TYPES, TF)}


def parse_topics(text: str | None) -> dict[str, str]:
    """``rgb=/cam/color,depth=/cam/depth,info=/cam/info,pose=/odom`` -> {role: topic}; InputError
    naming ``--topics`` for an unknown role, a malformed entry, a role given twice or one topic given
    for two roles (:func:`check_distinct_topics`)."""
    topics = {}
    for entry in filter(None, (part.strip() for part in (text or "").split(","))):
        role, sep, topic = entry.partition("=")
        if not sep or not topic.strip() or role.strip() not in ROLES:
            raise InputError(f"--topics: '{entry}' is not ROLE=TOPIC with ROLE one of {', '.join(ROLES)}")
        if role.strip() in topics:
            raise InputError(f"--topics: {role.strip()} is given twice ({topics[role.strip()]}, {topic.strip()}); "
                             "give each role once")
        topics[role.strip()] = topic.strip()
    return check_distinct_topics(topics)


def check_distinct_topics(topics: dict) -> dict:
    """`topics` ({role: topic}) if no topic is given for two roles; InputError naming both otherwise (one
    topic as rgb and depth read its images as both, and the depth as missing)."""
    roles = {}
    for role, topic in topics.items():
        if topic in roles:
            raise InputError(f"--topics: {roles[topic]}={topic} and {role}={topic} give one topic for two roles; "
                             "each role needs its own topic")
        roles[topic] = role
    return topics


def rosbag_config(conf) -> dict:
    """The ``rosbag`` section of ``configs/sequence.yaml`` (:data:`ROSBAG_OPTIONS`), checked."""
    options = option_section(conf, ROSBAG_OPTIONS, "rosbag")
    for key in ROSBAG_OPTIONS[:2]:
        if not isinstance(options[key], (int, float)) or isinstance(options[key], bool) or not options[key] >= 0:
            raise InputError(f"rosbag.{key} must be a non-negative number of seconds, got {options[key]!r}")
    if options["camera_axes"] not in ("auto", "optical", "body"):
        raise InputError(f"rosbag.camera_axes must be auto, optical or body, got {options['camera_axes']!r}")
    return options


def _listing(topics: dict) -> str:
    shown = [f"{name} ({info.msgtype})" for name, info in sorted(topics.items())]
    return ", ".join(shown[:12]) + (f" and {len(shown) - 12} more" if len(shown) > 12 else "") or "none"


def _image_kind(reader, path: Path, topic: str, info) -> str:
    """``colour``, ``depth`` or ``other``: what the image topic's first message holds."""
    first = next(messages(reader, path, info.connections), None)
    if first is None:
        return "other"
    message = first[3]
    if info.msgtype == COMPRESSED:
        text = str(message.format)
        return "depth" if "compressedDepth" in text or text.startswith(("16UC1", "mono16", "32FC1")) else "colour"
    encoding = str(message.encoding)
    return "depth" if encoding in DEPTH_ENCODINGS or encoding in ("16SC1", "32FC2") else "colour"


def _only(candidates: list[str], role: str, path: Path, what: str) -> str | None:
    if len(candidates) > 1:
        raise InputError(f"{path}: several {what} topics ({', '.join(candidates)}): choose one with "
                         f"--topics {role}=TOPIC")
    return candidates[0] if candidates else None


def _sibling_info(infos: list[str], rgb: str) -> list[str]:
    """The CameraInfo topics in the colour topic's namespace (``/cam/color/camera_info`` for
    ``/cam/color/image_raw``, image_transport's convention) where there are such, else all."""
    beside = [info for info in infos if rgb.startswith(info.rsplit("/", 1)[0] + "/")]
    return beside or infos


def select_topics(reader, path: Path, given: dict) -> dict:
    """{role: topic or None} for ``rgb``, ``depth``, ``info``, ``pose`` (given ones checked against
    their message types, the others found); plus ``tf`` (the TFMessage topics) and
    ``pose_candidates`` (the pose topics read when tf does not pose the camera)."""
    topics = reader.topics
    for role, topic in check_distinct_topics(given).items():
        if topic not in topics:
            raise InputError(f"{path}: --topics {role}={topic}: no such topic; the recording has {_listing(topics)}")
        if topics[topic].msgtype not in _WANTS[role]:
            raise InputError(f"{path}: topic {topic} is {topics[topic].msgtype}; {role} needs "
                             f"{' or '.join(_WANTS[role])}")
    by_type = lambda *types: sorted(name for name, info in topics.items() if info.msgtype in types)  # noqa: E731
    images = by_type(IMAGE, COMPRESSED)
    kinds = {topic: _image_kind(reader, path, topic, topics[topic]) for topic in images
             if topic not in given.values()}
    chosen = dict(given)
    if "rgb" not in chosen:
        colour = [topic for topic in images if kinds.get(topic) == "colour"]
        if not colour:
            raise InputError(f"{path}: no colour image topic (sensor_msgs/Image or CompressedImage); the recording "
                             f"has {_listing(topics)}")
        chosen["rgb"] = _only(colour, "rgb", path, "colour image")
    if "depth" not in chosen:
        chosen["depth"] = _only([t for t in images if kinds.get(t) == "depth"], "depth", path, "depth image")
    if "info" not in chosen:
        chosen["info"] = _only(_sibling_info(by_type(CAMERA_INFO), chosen["rgb"]), "info", path, "CameraInfo")
    chosen.setdefault("pose", None)
    chosen["tf"] = by_type(TF)
    chosen["pose_candidates"] = [chosen["pose"]] if chosen["pose"] else by_type(*POSE_TYPES)
    return chosen


# ----------------------------------------------------------------------------- poses


@dataclass
class Poses:
    """The frames' poses: ``T_fixed_cam`` (N, 4, 4) float64, found (N,) bool, the fixed frame and
    how they were found (for the notes); ``poses`` None: the recording has none."""

    fixed_frame: str | None = None
    poses: np.ndarray | None = None
    found: np.ndarray | None = None
    notes: list = field(default_factory=list)


def _axes(options: dict, default: str) -> np.ndarray:
    """(4, 4): the posed frame's axes to optical axes (``rosbag.camera_axes``, `default` for auto)."""
    T = np.eye(4)
    if (default if options["camera_axes"] == "auto" else options["camera_axes"]) == "body":
        T[:3, :3] = R_BODY_OPTICAL
    return T


def _tf_poses(path, data: Extracted, chosen, times, options) -> Poses | None:
    """Poses from the camera frame's tf chain when it holds a moving edge (or pose=/tf was given)."""
    forced = chosen["pose"] in chosen["tf"]
    if chosen["pose"] and not forced:  # a pose topic was chosen
        return None
    edges = data.tf.chain(data.camera_frame)
    moving = any(isinstance(transform, Track) for _, _, transform in edges)
    if not moving:
        if forced or (data.tf.moving and not data.pose_tracks):
            raise InputError(f"{path}: tf: the camera frame '{data.camera_frame}' (topic {chosen['rgb']}) does not "
                             f"reach a fixed frame: its chain {describe(edges, data.camera_frame)} has no moving "
                             f"transform (moving frames in /tf: {', '.join(data.tf.moving_frames()) or 'none'})")
        return None
    tolerance = options["pose_max_time_difference_s"]
    poses, found = chain_poses(edges, times, tolerance)
    root = edges[-1][0]
    return Poses(root, poses @ _axes(options, "optical"), found,
                 [f"poses: tf {describe(edges, data.camera_frame)} (fixed frame '{root}')"])


def _topic_poses(path, data: Extracted, chosen, times, options) -> Poses:
    """Poses from a pose topic, chained to the camera frame through tf where tf links its body."""
    topic = _only(sorted(data.pose_tracks), "pose", path, "pose (Odometry, PoseStamped)")
    if chosen["pose"] and topic is None:
        raise InputError(f"{path}: pose topic {chosen['pose']} has no messages")
    if topic is None:
        return Poses(notes=["the recording has no poses (no tf chain to the camera, no pose topic): pycolmap "
                            "poses the frames"])
    track = data.pose_tracks[topic]
    tolerance = options["pose_max_time_difference_s"]
    poses, found = track.at(times, tolerance)
    edges = data.tf.chain(data.camera_frame, stop=track.child) if track.child else []
    if track.child == data.camera_frame:
        note = f"poses: topic {topic}, of the camera frame '{data.camera_frame}'"
        poses = poses @ _axes(options, "optical")
    elif edges and edges[-1][0] == track.child:
        T_body_cam, ok = chain_poses(edges, times, tolerance)
        poses, found = poses @ T_body_cam @ _axes(options, "optical"), found & ok
        note = f"poses: topic {topic} ('{track.parent}' -> '{track.child}') and tf {describe(edges, data.camera_frame)}"
    else:
        axes = options["camera_axes"] if options["camera_axes"] != "auto" else "body"
        poses = poses @ _axes(options, "body")
        note = (f"poses: topic {topic} taken as the camera's, with {axes} axes (no tf from "
                f"'{track.child or 'its body'}' to the camera frame '{data.camera_frame}'; rosbag.camera_axes)")
    return Poses(track.parent, poses, found, [note])


# ----------------------------------------------------------------------------- the sequence


def _camera(path, chosen, data: Extracted, camera: Camera | None, intrinsics, notes: list) -> Camera:
    size = data.size
    if camera is not None or intrinsics is not None:
        if data.info is not None:
            notes.append(f"intrinsics given explicitly; CameraInfo of {chosen['info']} ignored")
        return check_camera_size(camera, size, path) if camera is not None else \
            Camera.pinhole(*intrinsics, *size).checked("--intrinsics")
    if data.info is None:
        where = f"topic {chosen['info']} has no messages" if chosen["info"] else "there is no CameraInfo topic"
        raise InputError(f"{path}: {where} for the colour topic {chosen['rgb']}: give the intrinsics with "
                         "--intrinsics FX,FY,CX,CY")
    try:
        return camera_from_info(data.info, chosen["info"], size)
    except InputError as error:  # "topic ...: CameraInfo ..." gets the file's name
        raise InputError(f"{path}: {error}") from None


def _matched_depth(data: Extracted, times: np.ndarray, options) -> tuple[list, np.ndarray]:
    """(depth file per colour frame or None, has depth (N,) bool)."""
    if not data.depth:
        return [None] * len(times), np.ones(len(times), bool)
    depth_times = np.array([stamp for stamp, _ in data.depth], np.int64)
    index, difference = _nearest(depth_times, times)
    return [data.depth[i][1] for i in index], difference / 1e9 <= options["depth_max_time_difference_s"]


def _remove_unused(data: Extracted, used: set) -> None:
    for _, file in [*data.rgb, *data.depth]:
        if file not in used:
            file.unlink(missing_ok=True)


def _frame(k: int, rgb: Path, camera: Camera, pose, depth: Path | None, stamp: int) -> SequenceFrame:
    scale = 1.0 if depth is not None and depth.suffix == ".npy" else 1000.0  # npy: metres; png: millimetres
    return SequenceFrame(index=k, name=rgb.name, rgb_path=rgb, camera=camera, T_world_cam=pose, depth_path=depth,
                         depth_scale=scale, timestamp=stamp / 1e9)


def _kept(path, data, chosen, has_depth, found, options, notes) -> np.ndarray:
    kept = np.flatnonzero(has_depth & found)
    if len(kept) < len(has_depth):
        notes.append(f"skipped {int((~has_depth).sum())} frame(s) without a depth frame within "
                     f"{options['depth_max_time_difference_s']} s and {int((has_depth & ~found).sum())} without a "
                     f"pose within {options['pose_max_time_difference_s']} s ({len(kept)} of {len(has_depth)} kept)")
    if not len(kept):
        depth = f"a depth frame of {chosen['depth']} and " if chosen["depth"] else ""
        raise InputError(f"{path}: no colour frame of {chosen['rgb']} has {depth}a pose within the tolerances of "
                         "configs/sequence.yaml rosbag")
    return kept


def _posed_by_colmap(data: Extracted, camera, depth, kept, colmap_dir, sfm, progress, notes) -> Sequence:
    """The kept frames posed by pycolmap (up to scale), with their depth and stamps."""
    from ..config import load_config
    from .sfm import read_image_folder

    sfm = load_config("sequence").sfm if sfm is None else sfm
    sequence = read_image_folder(data.work / "rgb", camera if camera.remap is None else None, colmap_dir, conf=sfm,
                                 progress=progress)
    by_name = {data.rgb[i][1].name: (data.rgb[i][0], depth[i]) for i in kept}
    frames = [_frame(frame.index, frame.rgb_path, frame.camera, frame.T_world_cam, by_name[frame.name][1],
                     by_name[frame.name][0]) for frame in sequence.frames]
    return replace(sequence, frames=frames, format="rosbag", notes=[*notes, *sequence.notes])


def read_rosbag(path: str | Path, camera: Camera | None = None, work_dir: str | Path | None = None, *,
                topics: dict | None = None, intrinsics: tuple | None = None, conf, sfm=None,
                colmap_dir: str | Path | None = None, progress: bool = True) -> Sequence:
    """The frames of a robot recording as a :class:`Sequence` (format ``rosbag``).

    Args:
        path: a ``.bag``, ``.mcap`` or ``.db3`` file or a rosbag2 folder.
        camera: intrinsics at the images' size overriding CameraInfo; `intrinsics` (fx, fy, cx,
            cy) px does the same at whatever size the images have.
        work_dir: folder for the extracted images (``rgb/``, ``depth/``: 16-bit PNG millimetres or
            ``.npy`` float32 metres); replaced on each call. None: a new temporary folder.
        topics: {role: topic} for ``rgb``, ``depth``, ``info``, ``pose`` (:func:`parse_topics`).
        conf: the ``rosbag`` section of ``configs/sequence.yaml`` (:func:`rosbag_config`).
        sfm, colmap_dir: the ``sfm`` section (None: the shipped one) and pycolmap's work folder
            (None: a temporary one), used when the recording has no poses.
    Returns:
        One frame per colour message (sorted by ``header.stamp``) with a depth frame and a pose
        within the tolerances; ``T_world_cam`` in the fixed frame (metres) and ``ros``
        (:class:`~.frames.RosFrames`: fixed and camera frame ids, stamps in ns).
    """
    path, options = Path(path), rosbag_config(conf)
    created = work_dir is None or not Path(work_dir).exists()
    work = Path(tempfile.mkdtemp(prefix="frontiernet-recording-") if work_dir is None else work_dir)
    try:
        with open_recording(path) as reader:
            chosen = select_topics(reader, path, dict(topics or {}))
            data = extract(reader, path, chosen, work, progress)
        notes = [f"recording: colour {chosen['rgb']}, depth {chosen['depth'] or 'none'}, camera info "
                 f"{chosen['info'] or 'none'}", *data.notes]
        cam = _camera(path, chosen, data, camera, intrinsics, notes)
        times = np.array([stamp for stamp, _ in data.rgb], np.int64)
        depth, has_depth = _matched_depth(data, times, options)
        poses = _tf_poses(path, data, chosen, times, options) or _topic_poses(path, data, chosen, times, options)
        notes += poses.notes
        found = poses.found if poses.poses is not None else np.ones(len(times), bool)
        kept = _kept(path, data, chosen, has_depth, found, options, notes)
        _remove_unused(data, {data.rgb[i][1] for i in kept} | {depth[i] for i in kept})
        stamps = {data.rgb[i][1].name: int(times[i]) for i in kept}
        if poses.poses is None:
            from .sfm import check_image_count  # pycolmap: only for a recording without poses

            check_image_count(len(kept), path, "the recording has no poses and holds")
            sequence = _posed_by_colmap(data, cam, depth, kept, colmap_dir, sfm, progress, notes)
            return replace(sequence, root=path, ros=RosFrames("map", data.camera_frame, stamps, posed=False))
        frames = [_frame(k, data.rgb[i][1], cam, poses.poses[i], depth[i], int(times[i])) for k, i in enumerate(kept)]
        return Sequence(frames, "rosbag", path, metric=True, notes=notes,
                        ros=RosFrames(poses.fixed_frame, data.camera_frame, stamps))
    except BaseException:
        if created:
            shutil.rmtree(work, ignore_errors=True)
        else:
            for name in ("rgb", "depth"):
                shutil.rmtree(work / name, ignore_errors=True)
        raise

"""``frontiernet sequence``: offline frontier proposals on a captured image sequence (hloc-style
``main(conf, ...)``).

1. Read the sequence (:func:`~frontiernet.sequences.open_sequence`: TUM, Redwood, COLMAP, a
   folder of images that pycolmap reconstructs, or a robot recording: :mod:`.rosbag`), keep
   every ``frames.stride``-th frame.
2. Pass 1 (:mod:`.perceive`): depth (the sensor's, or a monocular model's) and the network's 2D
   outputs per frame (:meth:`FrontierStream.perceive <.stream.FrontierStream.perceive>`), cached
   in ``<out>/cache`` (a re-run resumes).
3. Metric scale for up-to-scale poses (COLMAP): the median ratio of the frames' metric depth to
   the reconstruction's depths (:func:`~frontiernet.sequences.sfm.metric_scale`).
4. A Z-up world (:mod:`.gravity`), then pass 2 (:mod:`.tracking`): 3D frontiers tracked over a
   map fused from the frames (:meth:`FrontierStream.track <.stream.FrontierStream.track>` per frame).
5. Outputs (:mod:`.outputs`): ``frontiers.json``, ``map.ply`` (fused coloured points),
   ``frontiers.ply`` (arrows coloured by gain), ``poses.json``, ``occupancy.npz``,
   ``overlay.mp4`` (per frame: frontier pixels and tracked frontiers | the map from above);
   :mod:`.ros_out`: ``frontiers.mcap`` (and a ``rosbag2/`` folder) with the same as ROS messages.
"""

from __future__ import annotations

import shutil
import time
from pathlib import Path

import numpy as np

from ..errors import InputError, whole_number
from ..io import claim_output_folder, ensure_dir, write_json
from .gravity import gravity_alignment
from .outputs import VIDEO, check_run_outputs, write_arrows, write_frontiers
from .perceive import perceive_frames
from .stream import FrontierStream, load_sequence_config
from .tracking import check_map_extent, track_frontiers


def check_frames(stride, max_frames) -> tuple[int, int | None]:
    """(stride, max_frames) of ``frames``, checked: InputError naming the key (and its option) for a
    stride < 1 or a max_frames < 1 (None: every frame)."""
    stride = whole_number(stride, "frames.stride (--stride)", 1)
    return stride, None if max_frames is None else whole_number(max_frames, "frames.max_frames (--max-frames)", 1)


def check_outputs(conf) -> None:
    """InputError naming the first key of `conf` (a sequence's config) outside its declared range, before
    any frame is read (:func:`~frontiernet.config.check_ranges`; a library caller's own config too):
    ``outputs.video_fps`` is the video's and the ROS output's clock, ``seed`` numpy's, ``bounds_margin_m``
    the map's extent."""
    from ..config import check_ranges
    from .stream import SEQUENCE_LAYOUT

    check_ranges(conf, SEQUENCE_LAYOUT)


def check_network(network) -> None:
    """InputError naming ``network.size`` unless it is null (the model's) or a network input size in
    pixels (:func:`~frontiernet.model.predictor.input_size`: an integer in [8, 2048])."""
    from ..model.predictor import input_size

    if network.size is not None:
        input_size(network.size, "network.size")


def check_depth(depth, conf=None) -> None:
    """InputError unless `depth` is ``sensor``, the name of a depth source of
    :data:`~frontiernet.depth.SOURCES` (``emulated`` degrades the sensor's depth) or a
    :class:`~frontiernet.depth.DepthSource`; InputError too when that source's weights are missing
    (:func:`~frontiernet.depth.check_depth_files`, with `conf`'s ``depth`` section)."""
    from ..depth import SOURCES, check_depth_files, depth_source_name

    if isinstance(depth, str) and depth != "sensor" and depth_source_name(depth) not in SOURCES:
        raise InputError(f"--depth {depth}: not a depth source; valid: sensor (the sequence's depth images, the "
                         f"default), gt, {', '.join(SOURCES)}")
    if isinstance(depth, str) and depth != "sensor":
        check_depth_files(depth, conf.get("depth") if conf is not None else None)


DEPTH_FILES = {"tum": "a depth.txt listing its depth images (5000 units per metre)",
               "redwood": "a depth/ folder of 16-bit millimetre PNGs, one per colour image",
               "colmap": "a depth/ folder beside images/ (the images' names, 16-bit millimetre .png or .npy metres)"}
"""Where each sequence format keeps its depth images, as a run without them says."""
ESTIMATE_DEPTH = "estimate depth with --depth depth_anything_v2 or --depth metric3d_v2"


def no_depth_message(sequence, format: str, input_path) -> str:
    """The refusal of a sensor-depth run on `sequence` (read as `format` from `input_path`) whose frames lack
    depth, as one sentence: what is missing, then the two ways on (its depth where the format keeps it,
    :data:`DEPTH_FILES`; or a depth model)."""
    if format == "rosbag":
        return (f"{input_path}: the recording has no depth image topic; name one with --topics depth=TOPIC, or "
                f"{ESTIMATE_DEPTH}")
    if format not in DEPTH_FILES:  # a folder of images (posed by pycolmap): depth can only be estimated
        return f"{input_path}: the images have no depth; {ESTIMATE_DEPTH}"
    missing = next(frame.name for frame in sequence if frame.depth_path is None)
    return (f"{input_path}: frame {missing} has no depth image; give the sequence {DEPTH_FILES[format]}, or "
            f"{ESTIMATE_DEPTH}")


def select_frames(sequence, stride: int, max_frames: int | None):
    """Every `stride`-th frame, at most `max_frames` of them (None: all)."""
    stride, max_frames = check_frames(stride, max_frames)
    indices = list(range(0, len(sequence), stride))
    if max_frames is not None:
        indices = indices[:max_frames]
    return sequence.subset(indices)


def model_identity(model) -> str:
    """What names a model file in the cache key: its path, size and modification time (a model
    retrained into the same file must not reuse the old outputs)."""
    from ..model import default_model_path

    path = Path(model) if model is not None else default_model_path()
    stat = path.stat() if path.is_file() else None
    return f"{path.resolve()}:{stat.st_size}:{stat.st_mtime_ns}" if stat else str(path)


def metric_poses(sequence, cache_paths, conf) -> tuple[np.ndarray, float, list[str]]:
    """(N, 4, 4) metric ``T_world_cam`` of the frames, the scale applied, and notes."""
    poses = sequence.poses()
    if sequence.metric:
        return poses, 1.0, []
    from .perceive import cached_full_depth
    from .sfm import metric_scale

    depths = {frame.index: cached_full_depth(path) for frame, path in zip(sequence, cache_paths)}
    scale, stats = metric_scale(sequence, depths)
    poses = poses.copy()
    poses[:, :3, 3] *= scale
    return poses, scale, [f"poses were up to scale: x {scale:.4f} to metres (median depth ratio of {stats['points']} "
                          f"reconstructed points in {stats['images']} frames, spread {stats['spread']:.3f} in log)"]


class _Pictures:
    """Per-frame video pictures and ROS messages (pass 2's ``on_frame``), of the run's `stream`."""

    def __init__(self, sequence, conf, stream, writer, ros=None) -> None:
        self.sequence, self.conf, self.stream, self.writer, self.ros = sequence, conf, stream, writer, ros
        self.topdown = self.cells = None

    def __call__(self, index, arrays, tracked) -> None:
        if self.writer is None and self.ros is None:
            return
        camera = self.stream.overlay()
        if self.ros is not None:  # the map every outputs.ros.map_every_frames frames and at the last
            self.ros.write(self.stream.ros_messages(map=True if index == len(self.sequence) - 1 else None))
        if self.writer is not None:
            self.writer.add(self.picture(index, camera, tracked))

    def picture(self, index, camera, tracked) -> np.ndarray:
        """The video picture: the `camera` picture (:func:`~.outputs.camera_picture`) beside the map
        from above."""
        import cv2

        from ..exploration.drawing import TopDown, label
        from ..exploration.motion import yaw_of

        frontiers = list(tracked.tracker)
        height = camera.shape[0]
        occupancy = tracked.map
        if self.topdown is None:  # the part of the map the frames see, in map cells
            size = occupancy.voxel_size
            first = np.floor((tracked.seen_bounds[0, :2] - occupancy.origin[:2]) / size).astype(int) - 2
            last = np.ceil((tracked.seen_bounds[1, :2] - occupancy.origin[:2]) / size).astype(int) + 2
            first, last = np.maximum(first, 0), np.minimum(last, occupancy.shape[:2])
            self.cells = (slice(first[0], last[0]), slice(first[1], last[1]))
            self.topdown = TopDown(occupancy.origin[:2] + first * size, tuple(last - first), size, height_px=height)
        low, high = (tracked.view_z + float(offset) for offset in self.conf.outputs.map_band_m)
        free, occupied = (cells[self.cells] for cells in occupancy.slice_2d(low, high))
        T = tracked.poses[index]
        top = self.topdown.draw(self.topdown.background(free, occupied), tracked.poses[:index + 1, :2, 3], T[:2, 3],
                                yaw_of(T), frontiers, None, self.stream.colour)
        name = self.sequence.frames[index].name
        camera = label(camera, f"{name}: {len(frontiers)} frontiers")
        return cv2.hconcat([camera, top])


def reader_options(format: str, conf, out: Path, progress: bool, recording: dict | None) -> dict:
    """The options of the reader of `format`: pycolmap's work folder ``<out>/colmap`` for images;
    for a recording also ``<out>/recording`` (its images) and `recording` (``topics``,
    ``intrinsics``: :func:`~.rosbag.read_rosbag`), which only a recording takes."""
    if format == "rosbag":
        return {"work_dir": out / "recording", "conf": conf.rosbag, "sfm": conf.sfm, "colmap_dir": out / "colmap",
                "progress": progress, **(recording or {})}
    if recording and any(value is not None and value != {} for value in recording.values()):
        raise InputError(f"--topics applies to recordings (.bag, .mcap, .db3, a rosbag2 folder), not to format "
                         f"{format}")
    return {"work_dir": out / "colmap", "conf": conf.sfm, "progress": progress} if format == "images" else {}


def main(conf, input_path: str | Path, out: str | Path, *, format: str = "auto", depth: str = "sensor",
         model: str | Path | None = None, camera=None, video: bool = True, progress: bool = True,
         recording: dict | None = None, mcap: bool = True, rosbag2: bool = False) -> dict:
    """Run the whole offline pipeline; returns the summary written to ``<out>/summary.json``.

    Args:
        conf: ``configs/sequence.yaml`` (with ``anchoring``, ``tracking`` and ``map`` from
            ``configs/explore.yaml``; see :func:`~.stream.load_sequence_config`; None: the shipped one).
        format: a reader of :data:`~frontiernet.sequences.READERS` or ``auto``.
        depth: ``sensor`` (the sequence's depth files) or a depth source of ``configs/depth.yaml``.
        model: model file (None: the shipped model).
        camera: a :class:`~frontiernet.sequences.Camera` overriding the sequence's intrinsics.
        recording: a recording's ``topics`` and ``intrinsics`` (:func:`~.rosbag.read_rosbag`).
        mcap, rosbag2: write ``frontiers.mcap`` and the ``rosbag2/`` folder (:mod:`.ros_out`).
    The frames, the outputs (:func:`check_outputs`), ``network.size``, the depth, `out` and the paths the run
    writes there (:func:`~.outputs.check_run_outputs`) are checked before any work, the map's extent over the
    frames' poses (:func:`~.tracking.check_map_extent`) before any frame is perceived (an up-to-scale sequence's
    once pass 1 gave its scale); a run refused after (an
    :class:`InputError`: a recording without depth, a reconstruction that fails, ...) removes the `out` folder
    if it made it, else the work folders it made there (``cache``, ``recording``, ``colmap``), while an
    interrupted run keeps them to resume; a second run on `out` while this one writes there is refused
    (:func:`~frontiernet.io.claim_output_folder`).
    """
    conf = load_sequence_config() if conf is None else conf
    check_frames(conf.frames.stride, conf.frames.max_frames)
    check_outputs(conf)
    check_network(conf.network)
    check_depth(depth, conf)
    check_run_outputs(out, video=video, mcap=mcap, rosbag2=rosbag2,  # what stands where the run writes
                      inputs=[(input_path, "the sequence (--input)"), (model, "the model file")])
    out = Path(out)
    made = [path for path in (*(out / name for name in WORK_FOLDERS), out) if not path.exists()]
    try:
        with claim_output_folder(out, force=True) as out:  # (a re-run resumes from out/cache)
            return _run(conf, input_path, out, format=format, depth=depth, model=model, camera=camera,
                        video=video, progress=progress, recording=recording, mcap=mcap, rosbag2=rosbag2)
    except InputError:
        for path in made[-1:] if made and made[-1] == out else made:  # all of `out` when this run made it
            shutil.rmtree(path, ignore_errors=True)
        raise


WORK_FOLDERS = ("cache", "recording", "colmap")
"""What a run keeps in `out` to resume: the per-frame cache, a recording's extracted frames, pycolmap's work."""


def _run(conf, input_path, out: Path, *, format, depth, model, camera, video, progress, recording, mcap,
         rosbag2) -> dict:
    from . import detect_format, open_sequence
    from .ros_out import RosWriter, output_frames

    started = time.perf_counter()
    out = ensure_dir(out)
    format = detect_format(input_path) if format == "auto" else format
    options = reader_options(format, conf, out, progress, recording)
    sequence = open_sequence(input_path, format, camera=camera, **options)
    sequence = select_frames(sequence, conf.frames.stride, conf.frames.max_frames)
    if not sequence.has_poses:
        raise InputError(f"{input_path}: the frames have no poses (use --format images to reconstruct them)")
    if depth == "sensor" and not sequence.has_depth:
        raise InputError(no_depth_message(sequence, format, input_path))
    if sequence.metric:  # every pose known in metres: the map's extent is checked before any frame is perceived
        poses = sequence.poses()
        check_map_extent(sequence, gravity_alignment(poses, str(conf.gravity)) @ poses, conf, input_path)
    stream = FrontierStream(conf=conf, model=model, depth=depth)
    cache_paths = perceive_frames(sequence, stream, out / "cache", model_identity(model), progress)
    perceived = time.perf_counter()
    poses, scale, notes = metric_poses(sequence, cache_paths, conf)
    T_aligned_input = gravity_alignment(poses, str(conf.gravity))
    poses = T_aligned_input @ poses
    if not sequence.metric:  # up to scale until pass 1's depth gave the scale
        check_map_extent(sequence, poses, conf, f"{input_path} (poses x {scale:.4g} to metres)")
    # the ROS outputs' frames and stamps (frames without stamps 1 / outputs.video_fps apart)
    stream.ros_frames = output_frames(sequence, T_aligned_input, scale, 1.0 / float(conf.outputs.video_fps))
    writer = None
    if video:
        from ..exploration.outputs import VideoWriter

        writer = VideoWriter(out / VIDEO, float(conf.outputs.video_fps))
    ros = RosWriter(out, mcap=mcap, rosbag2=rosbag2) if mcap or rosbag2 else None
    pictures = _Pictures(sequence, conf, stream, writer, ros)
    try:
        tracked = track_frontiers(sequence, poses, cache_paths, stream, on_frame=pictures, progress=progress,
                                  stamps_ns=stream.ros_frames.stamps_ns)
        if not len(stream.cloud.cloud.points):
            raise InputError(f"{input_path}: no depth pixel of any frame is valid (all 0, no return, or beyond "
                             f"{stream.cloud.max_depth_m:g} m): there is nothing to map")
    except BaseException:
        if ros is not None:
            ros.abort()
        raise
    ros_outputs = [] if ros is None else [path.name for path in ros.close()]
    names = [frame.name for frame in sequence]
    summary = {
        "input": str(input_path), "format": sequence.format, "frames": len(sequence), "depth": depth,
        "model": str(model or "shipped"), "world_frame": "gravity-aligned (+z up), metres, first camera at the origin",
        "T_world_input": np.round(T_aligned_input, 6).tolist(), "scale_to_metres": scale,
        "frontiers_alive": len(tracked.tracker), "frontiers_removed": dict(tracked.tracker.removed),
        "map_bounds_m": stream.bounds.tolist(), "view_z_m": stream.view_z,  # FrontierStream.start's, to repeat it
        "notes": [*sequence.notes, *notes],
        "seconds": {"reading_and_perception": round(perceived - started, 2),
                    **{stage: round(value, 2) for stage, value in tracked.seconds.items()}, "total": None},
    }
    write_frontiers(out / "frontiers.json", tracked, names, {key: summary[key] for key in
                                                              ("world_frame", "T_world_input", "scale_to_metres")})
    write_json(out / "poses.json", {"frames": names, "T_world_cam": np.round(poses, 6).tolist()})
    stream.cloud.write(out / "map.ply")
    write_arrows(out / "frontiers.ply", list(tracked.tracker), stream.colour)
    tracked.map.save(out / "occupancy.npz")
    if writer is not None:
        writer.close()
    if ros_outputs:
        summary["ros_outputs"] = ros_outputs
    summary["seconds"]["total"] = round(time.perf_counter() - started, 2)
    write_json(out / "summary.json", summary)
    return summary

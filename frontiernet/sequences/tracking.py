"""Pass 2 of ``frontiernet sequence``: the frames' frontiers lifted to 3D and tracked across the
sequence with the online pipeline's bookkeeping (paper III-E, III-F), a loop of
:meth:`FrontierStream.track <.stream.FrontierStream.track>` over the cached frames.

The map spans what all frames see and the tracker's gain views sit at the median camera height
(an offline run knows every pose in advance; a robot's stream takes a box around its first
pose). Poses are gravity-aligned and scaled to metres first (:mod:`.gravity`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..frontiers import FrontierTracker
from ..mapping import OccupancyMap
from ..timing import Stopwatch
from .perceive import cached_full_depth, load_cached


@dataclass
class TrackedSequence:
    """What pass 2 produced.

    Attributes:
        poses: (N, 4, 4) float64 ``T_world_cam`` of the frames in the aligned, metric world.
        tracker: the frontiers alive after the last frame (and ``removed_log``: the dropped ones).
        map: the :class:`OccupancyMap` fused from all frames.
        per_frame: one record per frame: ``frame`` name, ``observations`` (3D frontiers anchored),
            ``frontier_ids`` (the tracked ids they went to), ``alive`` (tracked frontiers after it).
        view_z: world height (m) of the tracker's gain views (median camera height).
        seen_bounds: (2, 3) world [min, max] corners of what the frames see (the map is this
            widened by ``bounds_margin_m``; pictures show this part).
    """

    poses: np.ndarray
    tracker: FrontierTracker
    map: OccupancyMap
    per_frame: list = field(default_factory=list)
    view_z: float = 0.0
    seen_bounds: np.ndarray | None = None
    seconds: dict = field(default_factory=dict)  # per stage over all frames (FrontierStream.seconds, pictures)


def seen_bounds(sequence, poses: np.ndarray, cache_paths, max_range_m: float, stride_px: int = 8) -> np.ndarray:
    """(2, 3) world [min, max] corners of what the frames see: the camera centres and their
    depth points (every `stride_px`-th pixel; rays longer than `max_range_m` end there, as the
    map integrates them)."""
    from ..geometry import back_projected_points

    points = [np.asarray(poses)[:, :3, 3]]
    for frame, T, path in zip(sequence, poses, cache_paths):
        depth = np.minimum(cached_full_depth(path), max_range_m)
        points.append(back_projected_points(depth, None, frame.camera.K, T, max_range_m, stride_px)[0])
    points = np.concatenate(points)
    return np.stack([points.min(0), points.max(0)])


MAP_BYTES_PER_VOXEL = 5  # (float32 log-odds and an observed flag)


def check_map_extent(sequence, poses: np.ndarray, conf, where) -> None:
    """InputError naming `where` (the sequence), the span of the frames' camera positions and the two frames
    farthest apart on its longest axis, when the box of those positions (`poses`: (N, 4, 4) aligned, metric
    ``T_world_cam``) widened by ``bounds_margin_m`` a side holds more than ``max_map_voxels`` of
    ``map.voxel_size``. That box is the least the map of :func:`track_frontiers` spans (it covers what the frames
    see too), so this needs no frame: ``sequence`` checks it as soon as the poses are metric, before the frames are
    perceived when the reader's are. A trajectory with a camera 1e6 m off asked for 368 GiB once every frame was
    perceived (a MemoryError), and 1e30 m overflowed the voxel count."""
    positions = np.asarray(poses, np.float64)[:, :3, 3]
    span = positions.max(axis=0) - positions.min(axis=0)
    margin, voxel = float(conf.bounds_margin_m), float(conf.map.voxel_size)
    count = math.prod(float(n) for n in np.maximum(np.ceil((span + 2 * margin) / voxel - 1e-9), 1))
    most = int(conf.max_map_voxels)
    if count <= most:  # (inf is not)
        return
    axis = int(np.argmax(span))
    first, last = (sequence.frames[int(index)].name for index in (positions[:, axis].argmin(),
                                                                    positions[:, axis].argmax()))
    raise InputError(f"{where}: the frames' camera positions span {' x '.join(f'{v:.4g}' for v in span)} m "
                     f"(gravity-aligned; frame {first} to frame {last} on {'xyz'[axis]}): a map over them, widened by "
                     f"bounds_margin_m {margin:g} m a side, holds {count:.3g} voxels of map.voxel_size {voxel:g} m "
                     f"({count * MAP_BYTES_PER_VOXEL / 2 ** 30:.3g} GiB), more than the {most:,} of max_map_voxels; check "
                     "the poses (metres), or set a larger map.voxel_size")


def track_frontiers(sequence, poses: np.ndarray, cache_paths, stream, on_frame=None, progress: bool = True,
                    stamps_ns=None) -> TrackedSequence:
    """Run pass 2 over the cached frames with `stream`.

    Args:
        sequence: the :class:`~frontiernet.sequences.Sequence` (names and intrinsics).
        poses: (N, 4, 4) float64 aligned, metric ``T_world_cam`` per frame.
        cache_paths: pass 1's cache file per frame (:mod:`.perceive`).
        stream: the run's :class:`~.stream.FrontierStream` (its config: sections ``anchoring``,
            ``tracking``, ``map``, ``bounds_margin_m``); restarted here over the frames' map.
        on_frame: optional ``callback(index, cached arrays, tracked)`` after each frame (video, ROS
            messages; timed as ``pictures``).
        stamps_ns: (N,) int stamps of the frames (the ROS outputs'), or None.
    """
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    conf = stream.conf
    view_z = float(np.median(poses[:, 2, 3]))
    seen = seen_bounds(sequence, poses, cache_paths, float(conf.map.max_range_m))
    margin = float(conf.bounds_margin_m)
    stream.start(seen + np.array([[-margin], [margin]]), view_z)
    result = TrackedSequence(poses, stream.tracker, stream.map, stream.per_frame, view_z=view_z, seen_bounds=seen,
                             seconds=stream.seconds)
    columns = (TextColumn("tracking"), BarColumn(), MofNCompleteColumn())
    stopwatch = Stopwatch(result.seconds)  # all frames' seconds per stage
    with Progress(*columns, transient=True, disable=not progress) as bar:
        task = bar.add_task("frames", total=len(poses))
        for index, (frame, path) in enumerate(zip(sequence, cache_paths)):
            arrays = load_cached(path)
            stream.track(arrays, poses[index], frame.camera.K, rgb=frame.rgb() if stream.point_cloud else None,
                         name=frame.name, stamp_ns=None if stamps_ns is None else int(stamps_ns[index]))
            if on_frame is not None:
                with stopwatch("pictures"):
                    on_frame(index, arrays, result)
            bar.advance(task)
    return result

"""Pass 2 of ``frontiernet sequence``: the frames' frontiers lifted to 3D and tracked across the
sequence with the online pipeline's bookkeeping (paper III-E, III-F).

Per frame, in order: anchor the cached network outputs (:func:`~frontiernet.frontiers.anchoring.
anchor_prediction`), integrate the frame's depth into an occupancy map fused from the frames so
far, fold the frontiers into a :class:`~frontiernet.frontiers.FrontierTracker` (merge), reduce
their gains by the known volume the map shows around them, drop the invalidated ones (low gain,
looked at from a frame's pose, inside occupied space). Poses are gravity-aligned and scaled to
metres first (:mod:`.gravity`). The tracker's gain views sit at the median camera height.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..frontiers import FrontierTracker
from ..frontiers.anchoring import anchor_prediction
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
    seconds: dict = field(default_factory=dict)  # per stage (anchoring, map, tracking, point_cloud_and_video), all frames


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


def track_frontiers(sequence, poses: np.ndarray, cache_paths, conf, labels: dict, on_frame=None,
                    progress: bool = True, monocular: bool = False) -> TrackedSequence:
    """Run pass 2 over the cached frames.

    Args:
        sequence: the :class:`~frontiernet.sequences.Sequence` (names and intrinsics).
        poses: (N, 4, 4) float64 aligned, metric ``T_world_cam`` per frame.
        cache_paths: pass 1's cache file per frame (:mod:`.perceive`).
        conf: the whole sequence config (sections ``anchoring``, ``tracking``, ``map``).
        labels: the model's label encoding.
        on_frame: optional ``callback(index, cached arrays, tracked)`` after each frame (video).
        monocular: the depth is a depth model's (its flying pixels,
            :attr:`~frontiernet.depth.base.DepthSource.flying_pixels`): the map integrates it as
            such (``OccupancyMap.integrate``'s `monocular`: ``map.depth_edge_rtol``, ``map.monocular_*``).
    """
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    view_z = float(np.median(poses[:, 2, 3]))
    seen = seen_bounds(sequence, poses, cache_paths, float(conf.map.max_range_m))
    margin = float(conf.bounds_margin_m)
    occupancy = OccupancyMap.from_bounds(seen + np.array([[-margin], [margin]]), conf.map)
    tracker = FrontierTracker(conf.tracking, view_z=view_z)
    result = TrackedSequence(poses, tracker, occupancy, view_z=view_z, seen_bounds=seen)
    rng = np.random.default_rng(int(conf.seed))
    columns = (TextColumn("tracking"), BarColumn(), MofNCompleteColumn())
    stopwatch = Stopwatch(result.seconds)  # all frames' seconds per stage
    with Progress(*columns, transient=True, disable=not progress) as bar:
        task = bar.add_task("frames", total=len(poses))
        for index, (frame, path) in enumerate(zip(sequence, cache_paths)):
            arrays = load_cached(path)
            T = poses[index]
            with stopwatch("anchoring"):
                observations = anchor_prediction(arrays["distance_field"].astype(np.float32), arrays["gain_class"],
                                                 arrays["depth"], arrays["K"], T, conf.anchoring, labels, rng)
            with stopwatch("map"):
                occupancy.integrate(arrays["full_depth"].astype(np.float32), frame.camera.K, T, monocular)
            with stopwatch("tracking"):
                ids = tracker.add(observations, index, index)
                tracker.update_gains(occupancy)
                removed_before = len(tracker.removed_log)
                tracker.prune(poses[:index + 1], occupancy)
                for record in tracker.removed_log[removed_before:]:
                    record["removed_frame"] = index
                result.per_frame.append({"frame": frame.name, "observations": len(observations),
                                         "frontier_ids": [i for i in ids if i is not None], "alive": len(tracker)})
            if on_frame is not None:
                with stopwatch("point_cloud_and_video"):
                    on_frame(index, arrays, result)
            bar.advance(task)
    return result

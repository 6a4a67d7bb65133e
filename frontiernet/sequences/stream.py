"""The per-frame API (issue 57): :class:`FrontierStream`, what ``frontiernet sequence`` runs on
each frame and the library part of a robot's node.

Give it a frame (an RGB image, its depth, intrinsics and the camera's pose) and get back the 3D
frontiers tracked so far::

    stream = FrontierStream(K)                     # the shipped model, configs/sequence.yaml
    frontiers = stream(rgb, T_world_cam, depth)    # list[TrackedFrontier]
    picture = stream.overlay()                     # (h, w, 3) uint8, the frame's frontier pixels
    messages = stream.ros_messages()               # list[RosMessage], ready to publish

Per frame, in order (``frontiernet sequence`` is a loop over :meth:`FrontierStream.perceive`,
cached, then :meth:`FrontierStream.track`): the depth (the sensor's, or a depth model's); the
network on the frame (:func:`~.perceive.perceive_image`); its frontier pixels anchored to 3D
frontiers (paper III-E); the depth integrated into an occupancy map; the frontiers folded into a
:class:`~frontiernet.frontiers.FrontierTracker` (merge), their gains reduced by the known volume
the map shows around them, the invalidated ones dropped (low gain, looked at from a frame's pose,
inside occupied space; paper III-F); the frame's coloured points added to the fused point cloud.

Conventions: ``T_world_cam`` (4, 4) maps OpenCV camera coordinates (x right, y down, z forward:
a ROS *optical* frame) into a **Z-up** world in metres (a ROS fixed frame, ``map`` or ``odom``,
REP 103); depth (H, W) float metres (NaN, 0 or negative: no return) or uint16 millimetres
(16UC1); images pinhole, or undistorted here when the intrinsics are a
:class:`~frontiernet.sequences.Camera` with remap tables
(:func:`~frontiernet.sequences.ros_messages.camera_from_info` makes one of a CameraInfo).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..timing import Stopwatch
from .frames import Camera
from .outputs import PointCloudFusion, camera_picture
from .perceive import perceive_image
from .ros_out import OutputFrames, RosMessages


@dataclass(frozen=True)
class TrackedFrontier:
    """One tracked 3D frontier after a frame.

    Attributes:
        id: the tracker's id: the same frontier keeps it across frames (never reused).
        position: (3,) float64 world metres.
        direction: (3,) float64 unit view direction in the world (where to look from it).
        gain_m3: expected information gain (m^3) after the map-based reduction.
        predicted_gain_m3: the network's gain, averaged over its observations.
        observations: frames merged into it.
        first_seen, last_seen: frame numbers (0-based, in the order the stream got them).
        first_stamp_ns, last_stamp_ns: those frames' stamps where they were given, else None.
    """

    id: int
    position: np.ndarray
    direction: np.ndarray
    gain_m3: float
    predicted_gain_m3: float
    observations: int
    first_seen: int
    last_seen: int
    first_stamp_ns: int | None = None
    last_stamp_ns: int | None = None


def load_sequence_config(user_file=None, overrides=()):
    """``configs/sequence.yaml`` with the ``anchoring``, ``tracking`` and ``map`` sections of
    ``configs/explore.yaml`` and a ``depth`` section (``configs/depth.yaml`` less its ``source``:
    the sequence's is ``--depth``) underneath (sequence.yaml's keys win), then a user file and
    overrides (``["tracking.merge_distance_m=0.8"]``)."""
    from omegaconf import OmegaConf

    from ..config import load_config, merge_user
    from ..depth import source_options

    explore = load_config("explore")
    base = OmegaConf.create({**{key: explore[key] for key in ("anchoring", "tracking", "map")},
                             "depth": source_options()})
    return merge_user(OmegaConf.merge(base, load_config("sequence")), user_file, overrides, layout=SEQUENCE_LAYOUT)


SEQUENCE_LAYOUT = {**{key: f"explore.{key}" for key in ("anchoring", "tracking", "map")}, "depth": "depth",
                   "": "sequence"}
"""Where the shipped files of a sequence's config sit in it (:func:`~frontiernet.config.check_ranges`)."""


def _matrix(value, shape: tuple, what: str) -> np.ndarray:
    array = np.asarray(value, np.float64)
    if array.shape != shape or not np.all(np.isfinite(array)):
        raise InputError(f"{what} must be a finite {shape} array, got shape {array.shape}")
    return array


def metric_depth(depth) -> np.ndarray | None:
    """(H, W) float32 metres, NaN where there is no return, of a float depth in metres or a
    uint16 one in millimetres (16UC1); None stays None."""
    if depth is None:
        return None
    depth = np.asarray(depth)
    if depth.ndim != 2:
        raise InputError(f"a depth image must be (H, W), got shape {depth.shape}")
    depth = depth.astype(np.float32) / np.float32(1000.0) if depth.dtype == np.uint16 else depth.astype(np.float32)
    depth[~(depth > 0)] = np.nan
    return depth


class FrontierStream:
    """Tracked 3D frontiers of a stream of posed frames (module doc).

    Args:
        intrinsics: (3, 3) pinhole ``K`` of the images (pixels), or a
            :class:`~frontiernet.sequences.Camera` (its remap tables undistort each frame); None:
            every call gives ``K``.
        model: a model file, or None for the shipped model; runtime: an opened
            :class:`~frontiernet.model.predictor.Runtime` instead.
        conf: the sequence config (:func:`load_sequence_config`; None: the shipped one).
        depth: ``sensor`` (each frame brings its depth) or a depth model of
            ``configs/depth.yaml`` (``depth_anything_v2``, ``metric3d_v2``: local weights) that
            estimates it from the image, or a :class:`~frontiernet.depth.DepthSource`.
        bounds: (2, 3) world [min, max] corners (metres) of the occupancy map; None: the
            ``stream.map_extent_m`` box around the first camera.
        view_z: world height of the tracker's gain views (m); None: ``stream.view_z``, else the
            first camera's height.
        point_cloud: fuse the frames' coloured points (the map of :meth:`ros_messages`; costs a
            voxel downsampling per frame).
        fixed_frame, camera_frame: the frame ids of :meth:`ros_messages` (the world's, the
            images' optical frame).
    Attributes:
        tracker, map: the :class:`~frontiernet.frontiers.FrontierTracker` and the fused
            :class:`~frontiernet.mapping.OccupancyMap` (after the first frame); bounds, view_z:
            the map's (2, 3) world box and the gain views' height (:meth:`start`).
        cloud: the :class:`~.outputs.PointCloudFusion` (``point_cloud``), per_frame: a record
            per frame (``frame``, ``observations``, ``frontier_ids``, ``alive``), seconds: per stage.
        ros_frames: an :class:`~.ros_out.OutputFrames` (frame ids, ``T_out_world``, ``publish_tf``).
    """

    def __init__(self, intrinsics=None, *, model=None, conf=None, depth="sensor", runtime=None, bounds=None,
                 view_z: float | None = None, point_cloud: bool = True, fixed_frame: str = "map",
                 camera_frame: str = "camera") -> None:
        from ..depth import make_depth_source
        from ..exploration.drawing import gain_colour_map
        from ..model import open_runtime

        self.conf = load_sequence_config() if conf is None else conf
        self.runtime = open_runtime(model, threads=self.conf.network.threads) if runtime is None else runtime
        if isinstance(depth, str):
            depth = None if depth == "sensor" else make_depth_source(depth, self.conf.depth)
        self.depth_source = depth
        self.monocular = depth is not None and bool(depth.flying_pixels)
        self.labels = dict(self.runtime.labels)
        self.colour = gain_colour_map(self.labels["bin_edges"], float(self.labels["bin_unit_m3"]))
        threshold = self.conf.anchoring.frontier_threshold_px
        self.threshold = float(self.labels["frontier_threshold_px"] if threshold is None else threshold)
        self.camera = intrinsics if isinstance(intrinsics, Camera) else None
        self.K = (self.camera.K if self.camera is not None else
                  None if intrinsics is None else _matrix(intrinsics, (3, 3), "intrinsics K"))
        self.point_cloud = bool(point_cloud)
        self.ros_frames = OutputFrames(str(fixed_frame), str(camera_frame), np.eye(4), None, False)
        self._bounds, self._view_z = bounds, view_z
        self.map = self.tracker = self.cloud = self.last = self._overlay = self._ros = None
        self.poses, self.stamps, self.per_frame, self.seconds = [], [], [], {}

    # ------------------------------------------------------------------ one call per frame

    def __call__(self, rgb: np.ndarray, T_world_cam: np.ndarray, depth=None, K=None, *, stamp_ns: int | None = None,
                 name: str | None = None) -> list[TrackedFrontier]:
        """Perceive and track one frame: `rgb` (H, W, 3) uint8 RGB, its camera's pose
        ``T_world_cam`` (4, 4), its `depth` (metres, or uint16 mm; None with a depth model), `K`
        ((3, 3) or a :class:`~frontiernet.sequences.Camera`) when the intrinsics change,
        `stamp_ns` its time stamp (ROS ``header.stamp`` in ns); returns the frontiers tracked
        after it (:attr:`frontiers`)."""
        T = _matrix(T_world_cam, (4, 4), "T_world_cam")  # before the network runs
        if K is not None:
            self.camera, self.K = (K, K.K) if isinstance(K, Camera) else (None, _matrix(K, (3, 3), "intrinsics K"))
        elif self.K is None:
            raise InputError("no intrinsics: give K with the frame or to FrontierStream(K)")
        depth = metric_depth(depth)
        if self.camera is not None and self.camera.remap is not None:
            rgb = self.camera.undistort(np.asarray(rgb))
            depth = None if depth is None else self.camera.undistort(depth, nearest=True)
        name = str(len(self.poses)) if name is None else name
        arrays = self.perceive(rgb, depth, self.K, name=name)
        return self.track(arrays, T, self.K, rgb=rgb, name=name, stamp_ns=stamp_ns)

    def perceive(self, rgb: np.ndarray, depth: np.ndarray | None, K: np.ndarray, *, name: str = "frame") -> dict:
        """The depth and the network's outputs of one pinhole frame (pass 1 of ``sequence``: the
        arrays of :mod:`.perceive`'s cache files). `depth` is float32 metres, NaN invalid."""
        rgb = np.asarray(rgb)
        if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
            raise InputError(f"frame {name}: the image must be (H, W, 3) uint8 RGB, got {rgb.dtype} {rgb.shape}")
        if depth is not None and depth.shape != rgb.shape[:2]:
            raise InputError(f"frame {name}: depth is {depth.shape[1]} x {depth.shape[0]} px but the image is "
                             f"{rgb.shape[1]} x {rgb.shape[0]} (depth must be registered to the colour image)")
        if depth is None and self.depth_source is None:
            raise InputError(f"frame {name}: no depth image; give one (metres or uint16 millimetres) or a depth "
                             "model, FrontierStream(depth='depth_anything_v2')")
        return perceive_image(rgb, depth, _matrix(K, (3, 3), "intrinsics K"), self.runtime, self.depth_source,
                              self.conf.network, name)

    def start(self, bounds=None, view_z: float | None = None, T_first: np.ndarray | None = None) -> None:
        """(Re)start tracking with an empty map over `bounds` ((2, 3) world [min, max] metres;
        None: ``stream.map_extent_m`` around `T_first`'s camera) and gain views at `view_z`
        (None: ``stream.view_z``, else `T_first`'s camera height)."""
        from ..frontiers import FrontierTracker
        from ..mapping import OccupancyMap

        conf = self.conf
        centre = np.zeros(3) if T_first is None else np.asarray(T_first, np.float64)[:3, 3]
        if bounds is None:
            bounds = centre + np.asarray(conf.stream.map_extent_m, np.float64)
        if view_z is None:
            view_z = centre[2] if conf.stream.view_z is None else float(conf.stream.view_z)
        self.bounds, self.view_z = np.asarray(bounds, np.float64), float(view_z)
        self.map = OccupancyMap.from_bounds(self.bounds, conf.map)
        self.tracker = FrontierTracker(conf.tracking, view_z=self.view_z)
        self.rng = np.random.default_rng(int(conf.seed))
        self.cloud = (PointCloudFusion(conf.outputs.point_voxel_m, conf.map.max_range_m, conf.outputs.point_stride_px)
                      if self.point_cloud else None)
        self.poses, self.stamps, self.per_frame, self.seconds = [], [], [], {}
        self.last, self._overlay, self._ros = None, None, None

    def track(self, arrays: dict, T_world_cam: np.ndarray, K: np.ndarray, *, rgb: np.ndarray | None = None,
              name: str | None = None, stamp_ns: int | None = None) -> list[TrackedFrontier]:
        """Pass 2 of one frame: :meth:`perceive`'s `arrays` anchored at ``T_world_cam``, its
        depth integrated with the frame's own (3, 3) `K`, the tracker updated, and (with `rgb`,
        the frame's (H, W, 3) image) its points fused; returns :attr:`frontiers`."""
        from ..frontiers.anchoring import anchor_prediction

        T = _matrix(T_world_cam, (4, 4), "T_world_cam")
        if self.map is None:
            self.start(self._bounds, self._view_z, T)
        index, conf, tracker, occupancy = len(self.poses), self.conf, self.tracker, self.map
        self.poses.append(T)
        self.stamps.append(None if stamp_ns is None else int(stamp_ns))
        stopwatch = Stopwatch(self.seconds)
        with stopwatch("anchoring"):
            observations = anchor_prediction(arrays["distance_field"].astype(np.float32), arrays["gain_class"],
                                             arrays["depth"], arrays["K"], T, conf.anchoring, self.labels, self.rng)
        full_depth = arrays["full_depth"].astype(np.float32)
        with stopwatch("map"):
            occupancy.integrate(full_depth, K, T, self.monocular)
        with stopwatch("tracking"):
            ids = tracker.add(observations, index, index)
            tracker.update_gains(occupancy)
            removed_before = len(tracker.removed_log)
            tracker.prune(np.stack(self.poses), occupancy)
            for record in tracker.removed_log[removed_before:]:
                record["removed_frame"] = index
            self.per_frame.append({"frame": str(index) if name is None else name, "observations": len(observations),
                                   "frontier_ids": [i for i in ids if i is not None], "alive": len(tracker)})
        if self.cloud is not None and rgb is not None:
            with stopwatch("point_cloud"):
                self.cloud.add(full_depth, rgb, K, T)
        self.last, self._overlay = arrays, None
        return self.frontiers

    # ------------------------------------------------------------------ what a node publishes

    @property
    def frontiers(self) -> list[TrackedFrontier]:
        """The frontiers alive after the last frame, in the tracker's order (by id)."""
        if self.tracker is None:
            return []
        stamps = self.stamps
        return [TrackedFrontier(int(f.id), np.array(f.position, np.float64), np.array(f.direction, np.float64),
                                float(f.gain_m3), float(f.predicted_gain_m3), int(f.observations),
                                int(f.first_step), int(f.last_step), stamps[f.first_step], stamps[f.last_step])
                for f in self.tracker]

    def overlay(self) -> np.ndarray:
        """(h, w, 3) uint8 of the last frame: the network's input with its frontier pixels coloured
        by gain class and the tracked frontiers in view as rings with their ids."""
        if self.last is None:
            raise InputError("no frame yet: call the stream with a frame first")
        if self._overlay is None:
            self._overlay = camera_picture(self.last, list(self.tracker), self.poses[-1], self.labels,
                                           self.threshold, self.colour)
        return self._overlay

    def ros_messages(self, map: bool | None = None) -> list:
        """The last frame's ROS 2 messages (:class:`~.ros_out.RosMessage`, :mod:`.ros_out`'s
        topics): frontier markers (dropped frontiers' deleted), frontier poses, overlay and its
        camera info, a tf ``fixed -> camera`` where ``ros_frames.publish_tf``, and with `map`
        (None: every ``outputs.ros.map_every_frames``-th frame) the fused point cloud (none
        without ``point_cloud``). Stamped
        with the frame's ``stamp_ns``, else frame number / ``outputs.video_fps``."""
        self.overlay()  # raises before the first frame
        if self._ros is None:
            self._ros = RosMessages(self.ros_frames, self.colour, float(self.conf.outputs.ros.arrow_length_m))
        index = len(self.poses) - 1
        stamp = self.stamps[-1]
        if stamp is None:
            stamp = round(index / float(self.conf.outputs.video_fps) * 1e9)
        if map is None:
            map = index % max(1, int(self.conf.outputs.ros.map_every_frames)) == 0
        cloud = self.cloud.arrays() if map and self.cloud is not None else None
        return self._ros.frame(stamp, self.poses[-1], self.tracker, self.overlay(), self.last["K"], cloud)

"""What ``frontiernet sequence`` writes for the robot's own tools (issue 57): ``frontiers.mcap``
(and with ``--rosbag2`` a rosbag2 folder, sqlite3 storage), ROS 2 messages per frame that
Foxglove and RViz show on top of the robot's data:

==================================== ================================ ==========================
topic                                type                             frame id
==================================== ================================ ==========================
``/frontiernet/frontiers``           visualization_msgs/MarkerArray   the fixed frame
``/frontiernet/frontier_poses``      geometry_msgs/PoseArray          the fixed frame
``/frontiernet/overlay``             sensor_msgs/Image (rgb8)         the camera frame
``/frontiernet/overlay/camera_info`` sensor_msgs/CameraInfo           the camera frame
``/frontiernet/map``                 sensor_msgs/PointCloud2          the fixed frame
``/tf`` (inputs that are not ROS)    tf2_msgs/TFMessage               ``map`` -> ``camera``
==================================== ================================ ==========================

Markers: per tracked frontier an arrow from its position along its view direction (the pose's
+x axis) coloured by its gain class, and a label ``id: gain m^3``; the marker ids are the
tracker's frontier ids, so a frontier keeps its marker across frames, and a dropped frontier's
markers are deleted. The overlay is the network's input with its frontier pixels and the tracked
frontiers in view (the video's left half). The map is the fused point cloud so far (x, y, z,
rgb), every ``outputs.ros.map_every_frames`` frames and at the last one.

:class:`RosMessages` builds a frame's messages (for a run, for a :class:`~.stream.FrontierStream`'s
``ros_messages`` and for ``explore --mcap``, :mod:`.ros_explore`), :class:`RosWriter` writes them.

Frames and stamps (:func:`output_frames`): a ROS recording's own fixed frame (the poses' frame:
tf root or pose topic frame), its camera's optical frame and the colour images' stamps, so the
output plays beside the recording; other inputs get ``map`` (the run's gravity-aligned world)
and ``camera`` with the frames' time stamps, or index / ``outputs.video_fps`` without them.
"""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import check_output_files, ensure_dir
from .gravity import rotation_between

MARKERS, POSES, OVERLAY, OVERLAY_INFO, MAP, TF_TOPIC = ("/frontiernet/frontiers", "/frontiernet/frontier_poses",
                                                       "/frontiernet/overlay", "/frontiernet/overlay/camera_info",
                                                       "/frontiernet/map", "/tf")
TOPICS = {MARKERS: "visualization_msgs/msg/MarkerArray", POSES: "geometry_msgs/msg/PoseArray",
          OVERLAY: "sensor_msgs/msg/Image", OVERLAY_INFO: "sensor_msgs/msg/CameraInfo",
          MAP: "sensor_msgs/msg/PointCloud2", TF_TOPIC: "tf2_msgs/msg/TFMessage"}


@dataclass
class OutputFrames:
    """Where the outputs sit.

    Attributes:
        fixed_frame, camera_frame: frame ids of the 3D messages and of the overlay.
        T_out_world: (4, 4) float64 from the run's world (gravity-aligned, metres) to the fixed frame.
        stamps_ns: (N,) int64 stamp per frame of a sequence (None: each frame brings its own).
        publish_tf: write ``fixed_frame -> camera_frame`` on ``/tf`` (not for ROS recordings,
            whose own tf places the camera).
    """

    fixed_frame: str
    camera_frame: str
    T_out_world: np.ndarray
    stamps_ns: np.ndarray | None
    publish_tf: bool


@dataclass
class RosMessage:
    """One output message, ready to publish or to write.

    Attributes:
        topic, msgtype: e.g. ``/frontiernet/frontiers``, ``visualization_msgs/msg/MarkerArray``.
        stamp_ns: its header's stamp (and log time), integer nanoseconds.
        message: the message object (``rosbags``' types, ROS 2 Humble definitions; the fields
            are ROS's).
        data: its CDR serialisation with the 4-byte encapsulation header: what rosbag2 and MCAP
            store and what ``rclpy``'s ``Publisher.publish(bytes)`` sends as it is.
    """

    topic: str
    msgtype: str
    stamp_ns: int
    message: object
    data: bytes


@lru_cache(maxsize=1)
def typestore():
    """``rosbags``' ROS 2 Humble type store (message classes, CDR, message definitions)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def output_frames(sequence, T_aligned_input: np.ndarray, scale: float, frame_period_s: float) -> OutputFrames:
    """The :class:`OutputFrames` of a run: a posed ROS recording's fixed frame (the run's world
    mapped back with ``inv(T_aligned_input)``, `scale` undone), else ``map`` = the run's world."""
    ros = sequence.ros
    if ros is not None:
        stamps = np.array([ros.stamps_ns[frame.name] for frame in sequence], np.int64)
        if ros.posed:
            T = np.linalg.inv(T_aligned_input)
            T[:3, :] /= scale  # back to the input's units (1 for a posed recording: metres)
            return OutputFrames(ros.fixed_frame, ros.camera_frame, T, stamps, False)
        return OutputFrames("map", ros.camera_frame, np.eye(4), stamps, False)
    stamps = np.array([round(frame.timestamp * 1e9) if frame.timestamp is not None else
                       round(frame.index * frame_period_s * 1e9) for frame in sequence], np.int64)
    return OutputFrames("map", "camera", np.eye(4), stamps, True)


def scratch(path: Path) -> Path:
    """Where an output of :class:`RosWriter` at `path` (the MCAP file, the rosbag2 folder) is written before it is
    renamed into place: ``.<name>.partial`` beside it."""
    return path.with_name(f".{path.name}.partial")


class _McapSink:
    """ROS 2 messages (CDR, ``ros2msg`` schemas) into one MCAP file, zstd chunks, streamed."""

    def __init__(self, path: Path, store) -> None:
        from mcap.writer import CompressionType, Writer

        self.path, self.partial, self.typestore = path, scratch(path), store
        self.stream = open(self.partial, "wb")
        self.writer = Writer(self.stream, compression=CompressionType.ZSTD)
        self.writer.start(profile="ros2", library="frontiernet")
        self.schemas, self.channels = {}, {}

    def write(self, topic: str, msgtype: str, stamp: int, data: bytes) -> None:
        if topic not in self.channels:
            if msgtype not in self.schemas:
                text = self.typestore.generate_msgdef(msgtype, ros_version=2)[0]
                self.schemas[msgtype] = self.writer.register_schema(msgtype, "ros2msg", text.encode())
            self.channels[topic] = self.writer.register_channel(topic, "cdr", self.schemas[msgtype])
        self.writer.add_message(self.channels[topic], log_time=stamp, data=data, publish_time=stamp)

    def close(self) -> None:
        self.writer.finish()
        self.stream.close()
        os.replace(self.partial, self.path)

    def abort(self) -> None:
        self.stream.close()
        self.partial.unlink(missing_ok=True)


class _Rosbag2Sink:
    """The same messages into a rosbag2 folder (sqlite3 storage, ``ros2 bag play`` reads it)."""

    def __init__(self, path: Path, store) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer

        self.path, self.partial, self.typestore = path, scratch(path), store
        shutil.rmtree(self.partial, ignore_errors=True)
        self.writer = Writer(self.partial, version=8, storage_plugin=StoragePlugin.SQLITE3)
        self.writer.open()
        self.connections = {}

    def write(self, topic: str, msgtype: str, stamp: int, data: bytes) -> None:
        if topic not in self.connections:
            self.connections[topic] = self.writer.add_connection(topic, msgtype, typestore=self.typestore)
        self.writer.write(self.connections[topic], stamp, data)

    def close(self) -> None:
        self.writer.close()
        shutil.rmtree(self.path, ignore_errors=True)
        for file in self.partial.glob(f"{self.partial.name}*"):  # the storage file is named after the folder
            file.rename(self.partial / f"{self.path.name}{file.name[len(self.partial.name):]}")
        text = (self.partial / "metadata.yaml").read_text().replace(self.partial.name, self.path.name)
        (self.partial / "metadata.yaml").write_text(text)
        os.replace(self.partial, self.path)

    def abort(self) -> None:
        shutil.rmtree(self.partial, ignore_errors=True)


ROSBAG2_NAME = "rosbag2"
"""The folder ``--rosbag2`` writes in the output folder (beside it its scratch ``.rosbag2.partial``)."""


def check_ros_outputs(out: Path, *, mcap: bool = True, rosbag2: bool = False, name: str = "frontiers.mcap") -> None:
    """Before the frames: InputError naming what stands where :class:`RosWriter` writes in `out` when it is of
    the wrong kind: a folder or a pipe at the MCAP file `name` or its scratch (with `mcap`); with `rosbag2` a
    file, a pipe or a link at the :data:`ROSBAG2_NAME` folder or its scratch folder (the folder is put there by
    a rename at the end: a file there failed the run after all its work)."""
    out = Path(out)
    if mcap:
        check_output_files(out, (name, scratch(out / name).name))
    if not rosbag2:
        return
    for path in (out / ROSBAG2_NAME, scratch(out / ROSBAG2_NAME)):
        if path.is_symlink():  # (the folder is renamed into place: a link there, even to a folder, fails it)
            kind = "a symbolic link"
        elif not os.path.lexists(path) or path.is_dir():
            continue
        else:
            kind = "a file" if path.is_file() else "not a regular file nor a folder (a device or a pipe?)"
        raise InputError(f"{path}: is {kind}, expected the {ROSBAG2_NAME} folder the run writes (--rosbag2); "
                         "remove it, or choose another --out")


class RosWriter:
    """Writes :class:`RosMessage` lists to an MCAP file ``<out>/<name>`` (with `mcap`) and the
    folder ``<out>/rosbag2/`` (with `rosbag2`), streamed; :meth:`close` puts them in place,
    :meth:`abort` removes what was written."""

    def __init__(self, out: Path, *, mcap: bool = True, rosbag2: bool = False, name: str = "frontiers.mcap") -> None:
        out = ensure_dir(out)
        check_ros_outputs(out, mcap=mcap, rosbag2=rosbag2, name=name)  # before any message, not at the end
        self.sinks = [_McapSink(out / name, typestore())] if mcap else []
        if rosbag2:
            self.sinks.append(_Rosbag2Sink(out / ROSBAG2_NAME, typestore()))

    def write(self, messages) -> None:
        for message in messages:
            for sink in self.sinks:
                sink.write(message.topic, message.msgtype, message.stamp_ns, message.data)

    def close(self) -> list[Path]:
        for sink in self.sinks:
            sink.close()
        return [sink.path for sink in self.sinks]

    def abort(self) -> None:
        for sink in self.sinks:
            sink.abort()


class RosMessages:
    """Builds the messages of one frame (module doc) for a run or a :class:`~.stream.FrontierStream`.

    It remembers the frontier ids whose markers it last sent, so that the markers of a dropped
    frontier are deleted in the next message.

    Args:
        frames: where the outputs sit (:func:`output_frames`; its ``stamps_ns`` are not read here).
        gain_colour: ``gain_m3 -> (r, g, b)`` 0-255 (the overlay's).
        arrow_length_m: length of the frontier arrows (``outputs.ros.arrow_length_m``).
    """

    def __init__(self, frames: OutputFrames, gain_colour, arrow_length_m: float = 0.5) -> None:
        self.typestore = typestore()
        self.types = self.typestore.types
        self.frames, self.colour, self.arrow_m = frames, gain_colour, float(arrow_length_m)
        self.alive: set[int] = set()

    def frame(self, stamp: int, T_world_cam: np.ndarray, frontiers, overlay: np.ndarray, K_overlay: np.ndarray,
              cloud=None) -> list[RosMessage]:
        """The messages of one frame stamped `stamp` (ns): its pose ``T_world_cam`` (run world),
        the `frontiers` tracked after it, its `overlay` (h, w, 3) uint8 with intrinsics
        `K_overlay`, and with `cloud` = (points (N, 3) run world metres, colours (N, 3) uint8) the
        map; in the order tf (when ``publish_tf``), markers, poses, overlay, camera info, map."""
        stamp = int(stamp)
        fixed = self._header(stamp, self.frames.fixed_frame)
        camera = self._header(stamp, self.frames.camera_frame)
        frontiers = list(frontiers)
        placed = self.frontier_poses(frontiers)
        messages = [(TF_TOPIC, self._tf(fixed, T_world_cam))] if self.frames.publish_tf else []
        messages += [(MARKERS, self._markers(fixed, frontiers, placed)),
                     (POSES, self.types["geometry_msgs/msg/PoseArray"](
                         header=fixed, poses=[self._pose(position, R) for position, R in placed])),
                     (OVERLAY, self._image(camera, overlay)),
                     (OVERLAY_INFO, self._camera_info(camera, K_overlay, overlay.shape[1], overlay.shape[0]))]
        messages = [self._message(topic, stamp, message) for topic, message in messages]
        return messages if cloud is None else [*messages, self.map_message(stamp, *cloud)]

    def map_message(self, stamp: int, points: np.ndarray, colours: np.ndarray) -> RosMessage:
        """The map message: (N, 3) run-world `points` (metres) and their (N, 3) uint8 `colours`."""
        T = self.frames.T_out_world
        points = np.asarray(points, np.float64).reshape(-1, 3) @ T[:3, :3].T + T[:3, 3]
        header = self._header(int(stamp), self.frames.fixed_frame)
        return self._message(MAP, int(stamp), self._cloud(header, points, np.asarray(colours, np.uint8).reshape(-1, 3)))

    def _message(self, topic: str, stamp: int, message) -> RosMessage:
        data = bytes(self.typestore.serialize_cdr(message, TOPICS[topic]))
        return RosMessage(topic, TOPICS[topic], stamp, message, data)

    # ------------------------------------------------------------------ messages

    def _header(self, stamp: int, frame: str):
        t = self.types
        time = t["builtin_interfaces/msg/Time"](sec=int(stamp // 1_000_000_000), nanosec=int(stamp % 1_000_000_000))
        return t["std_msgs/msg/Header"](stamp=time, frame_id=frame)

    def _pose(self, position: np.ndarray, R: np.ndarray):
        from scipy.spatial.transform import Rotation

        t = self.types
        q = Rotation.from_matrix(R).as_quat()
        return t["geometry_msgs/msg/Pose"](position=t["geometry_msgs/msg/Point"](*map(float, position)),
                                           orientation=t["geometry_msgs/msg/Quaternion"](*map(float, q)))

    def _marker(self, header, kind: int, namespace: str, frontier_id: int, action: int, pose=None, scale=(0, 0, 0),
                colour=(0, 0, 0, 0), text: str = ""):
        t = self.types
        return t["visualization_msgs/msg/Marker"](
            header=header, ns=namespace, id=int(frontier_id), type=kind, action=action,
            pose=pose or self._pose(np.zeros(3), np.eye(3)), scale=t["geometry_msgs/msg/Vector3"](*scale),
            color=t["std_msgs/msg/ColorRGBA"](*colour), lifetime=t["builtin_interfaces/msg/Duration"](sec=0, nanosec=0),
            frame_locked=False, points=[], colors=[], texture_resource="",
            texture=t["sensor_msgs/msg/CompressedImage"](header=header, format="", data=np.zeros(0, np.uint8)),
            uv_coordinates=[], text=text, mesh_resource="",
            mesh_file=t["visualization_msgs/msg/MeshFile"](filename="", data=np.zeros(0, np.uint8)),
            mesh_use_embedded_materials=False)

    def frontier_poses(self, frontiers) -> list:
        """Per frontier (position (3,), R (3, 3)) in the fixed frame: R's +x along its view direction."""
        T = self.frames.T_out_world
        result = []
        for frontier in frontiers:
            direction = T[:3, :3] @ np.asarray(frontier.direction, np.float64)
            R = rotation_between(np.array([1.0, 0.0, 0.0]), direction / np.linalg.norm(direction))
            result.append((T[:3, :3] @ np.asarray(frontier.position, np.float64) + T[:3, 3], R))
        return result

    def _markers(self, header, frontiers, placed) -> object:
        Marker = self.types["visualization_msgs/msg/Marker"]
        ids = {int(frontier.id) for frontier in frontiers}
        markers = [self._marker(header, kind, namespace, gone, Marker.DELETE) for gone in sorted(self.alive - ids)
                   for kind, namespace in ((Marker.ARROW, "frontiers"), (Marker.TEXT_VIEW_FACING, "frontier_ids"))]
        length = self.arrow_m
        for frontier, (position, R) in zip(frontiers, placed):
            rgb = np.asarray(self.colour(frontier.gain_m3), np.float64) / 255.0
            markers.append(self._marker(header, Marker.ARROW, "frontiers", frontier.id, Marker.ADD,
                                        self._pose(position, R), (length, 0.1 * length, 0.2 * length), (*rgb, 1.0)))
            label = self._pose(position + np.array([0.0, 0.0, 0.3 * length]), np.eye(3))
            markers.append(self._marker(header, Marker.TEXT_VIEW_FACING, "frontier_ids", frontier.id, Marker.ADD, label,
                                        (0.0, 0.0, 0.25 * length), (1.0, 1.0, 1.0, 1.0),
                                        f"{frontier.id}: {frontier.gain_m3:.1f} m3"))
        self.alive = ids
        return self.types["visualization_msgs/msg/MarkerArray"](markers=markers)

    def _image(self, header, rgb: np.ndarray):
        rgb = np.ascontiguousarray(rgb, np.uint8)
        return self.types["sensor_msgs/msg/Image"](header=header, height=rgb.shape[0], width=rgb.shape[1],
                                                   encoding="rgb8", is_bigendian=0, step=rgb.shape[1] * 3,
                                                   data=rgb.reshape(-1))

    def _camera_info(self, header, K: np.ndarray, width: int, height: int):
        t = self.types
        P = np.zeros((3, 4))
        P[:, :3] = K
        return t["sensor_msgs/msg/CameraInfo"](
            header=header, height=int(height), width=int(width), distortion_model="plumb_bob", d=np.zeros(5),
            k=np.asarray(K, np.float64).ravel(), r=np.eye(3).ravel(), p=P.ravel(), binning_x=0, binning_y=0,
            roi=t["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))

    def _cloud(self, header, points: np.ndarray, colours: np.ndarray):
        """PointCloud2 of (N, 3) fixed-frame points and (N, 3) uint8 colours: x, y, z float32 and
        PCL's rgb (0x00RRGGBB as the bits of a float32)."""
        t = self.types
        cloud = np.zeros(len(points), [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4")])
        for axis, name in enumerate("xyz"):
            cloud[name] = points[:, axis]
        colours = np.asarray(colours, np.uint32)
        cloud["rgb"] = (colours[:, 0] << 16) | (colours[:, 1] << 8) | colours[:, 2]
        Field = t["sensor_msgs/msg/PointField"]
        fields = [Field(name=name, offset=4 * i, datatype=Field.FLOAT32, count=1) for i, name in enumerate("xyz")]
        fields.append(Field(name="rgb", offset=12, datatype=Field.FLOAT32, count=1))
        return t["sensor_msgs/msg/PointCloud2"](header=header, height=1, width=len(cloud), fields=fields,
                                                is_bigendian=False, point_step=16, row_step=16 * len(cloud),
                                                data=cloud.view(np.uint8).reshape(-1), is_dense=True)

    def _tf(self, header, T_world_cam: np.ndarray):
        from scipy.spatial.transform import Rotation

        t = self.types
        T = self.frames.T_out_world @ T_world_cam
        transform = t["geometry_msgs/msg/Transform"](
            translation=t["geometry_msgs/msg/Vector3"](*map(float, T[:3, 3])),
            rotation=t["geometry_msgs/msg/Quaternion"](*map(float, Rotation.from_matrix(T[:3, :3]).as_quat())))
        stamped = t["geometry_msgs/msg/TransformStamped"](header=header, child_frame_id=self.frames.camera_frame,
                                                          transform=transform)
        return t["tf2_msgs/msg/TFMessage"](transforms=[stamped])

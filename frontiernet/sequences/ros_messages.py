"""Decoding the ROS messages a robot recording holds (issue 57): images, depth, camera info, poses.

Messages come deserialised by ``rosbags`` (ROS 1 and ROS 2 alike; ROS 1 names its CameraInfo
fields ``K``, ``D``, ROS 2 ``k``, ``d``). Every decoder raises :class:`~frontiernet.errors.InputError`
naming the topic when a message is not one it reads.

Conventions: time stamps are integer nanoseconds (``header.stamp``); images come out as
(H, W, 3) uint8 RGB; depth as (H, W) uint16 millimetres (16UC1) or float32 metres (32FC1);
ROS poses (``geometry_msgs/Pose``, ``Transform``) as (4, 4) float64 ``T_parent_child``. A ROS
*optical* frame (REP 103: x right, y down, z forward) has the axes of our OpenCV camera frame, so
an optical frame's pose in a fixed frame is ``T_world_cam`` as the other readers give it.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from .frames import Camera

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
TF = "tf2_msgs/msg/TFMessage"
POSE_TYPES = ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped")
COLOUR_ENCODINGS = ("rgb8", "bgr8", "rgba8", "bgra8", "mono8", "8UC3")
DEPTH_ENCODINGS = {"16UC1": "<u2", "mono16": "<u2", "32FC1": "<f4"}
"""Raw depth encodings read: 16UC1 / mono16 millimetres, 32FC1 metres (REP 118)."""
# Body axes (REP 103: x forward, y left, z up) to optical axes (x right, y down, z forward):
# the columns are the optical axes in body coordinates.
R_BODY_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def stamp_ns(header) -> int:
    """A ``std_msgs/Header``'s stamp in integer nanoseconds."""
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def frame_id(header) -> str:
    """A header's frame id without ROS 1's leading ``/`` (tf2 drops it too)."""
    return str(header.frame_id).lstrip("/")


def transform_matrix(translation, rotation, what: str) -> np.ndarray:
    """(4, 4) float64 from a ROS translation (``x, y, z``, metres) and unit quaternion (``x, y, z, w``);
    InputError naming `what` (the topic and the transform or message) for numbers that are not finite
    or a quaternion of zero length."""
    from ..geometry import quaternion_rotations

    T = np.eye(4)
    T[:3, :3] = quaternion_rotations([rotation.x, rotation.y, rotation.z, rotation.w], what).as_matrix()
    T[:3, 3] = [translation.x, translation.y, translation.z]
    if not np.all(np.isfinite(T[:3, 3])):
        raise InputError(f"{what}: the translation is not finite, got {T[:3, 3].tolist()}")
    return T


def pose_of(message, msgtype: str, topic: str):
    """(``T_frame_body`` (4, 4) float64, body frame or None) of an Odometry (body: its
    ``child_frame_id``), PoseStamped or PoseWithCovarianceStamped (body unnamed) message of `topic`."""
    pose = message.pose if msgtype == "geometry_msgs/msg/PoseStamped" else message.pose.pose
    body = str(message.child_frame_id).lstrip("/") if msgtype == POSE_TYPES[0] else ""
    what = f"topic {topic}: the pose at {stamp_ns(message.header) / 1e9:.3f} s"
    return transform_matrix(pose.position, pose.orientation, what), body or None


def _rows(message, topic: str, channels: int, itemsize: int) -> np.ndarray:
    """(H, W * channels * itemsize) uint8: the image's rows without their padding."""
    height, width, step = int(message.height), int(message.width), int(message.step)
    data = np.asarray(message.data, np.uint8)
    row = width * channels * itemsize
    if height < 1 or width < 1 or step < row or len(data) < height * step:
        raise InputError(f"topic {topic}: image message is truncated or malformed ({width} x {height} px, step "
                         f"{step}, {len(data)} bytes)")
    return data[:height * step].reshape(height, step)[:, :row]


def colour_image(message, topic: str) -> np.ndarray:
    """(H, W, 3) uint8 RGB of a raw ``sensor_msgs/Image`` in one of :data:`COLOUR_ENCODINGS`."""
    encoding = str(message.encoding)
    if encoding not in COLOUR_ENCODINGS:
        kind = "a depth image" if encoding in DEPTH_ENCODINGS else "an image"
        raise InputError(f"topic {topic}: {kind} with encoding '{encoding}'; colour images must be "
                         f"{', '.join(COLOUR_ENCODINGS)}")
    channels = {"mono8": 1, "rgba8": 4, "bgra8": 4}.get(encoding, 3)
    pixels = _rows(message, topic, channels, 1).reshape(int(message.height), int(message.width), channels)
    if channels == 1:
        return np.repeat(pixels, 3, axis=2)
    pixels = pixels[..., :3]
    return np.ascontiguousarray(pixels[..., ::-1] if encoding.startswith("bgr") or encoding == "8UC3" else pixels)


def compressed_suffix(message, topic: str) -> str:
    """``.jpg`` or ``.png``: the file type of a colour ``sensor_msgs/CompressedImage`` (its
    ``format``, else its first bytes)."""
    text = str(message.format).lower()
    head = bytes(np.asarray(message.data[:8], np.uint8))
    if "compresseddepth" in text:
        raise InputError(f"topic {topic}: a compressed depth image (format '{message.format}'); colour images must "
                         "be jpeg or png")
    if head.startswith(b"\x89PNG"):
        return ".png"
    if head.startswith(b"\xff\xd8"):
        return ".jpg"
    raise InputError(f"topic {topic}: compressed image format '{message.format}' is not read (jpeg or png)")


def depth_image(message, msgtype: str, topic: str) -> np.ndarray:
    """(H, W) uint16 millimetres or float32 metres of a depth message: a raw Image in one of
    :data:`DEPTH_ENCODINGS`, or a CompressedImage of 16-bit PNG (``16UC1; png``, or
    ``compressedDepth``: a 12-byte header before the PNG)."""
    if msgtype == COMPRESSED:
        return _compressed_depth(message, topic)
    encoding = str(message.encoding)
    if encoding not in DEPTH_ENCODINGS:
        raise InputError(f"topic {topic}: depth encoding '{encoding}' is not read (16UC1 or mono16 millimetres, "
                         f"32FC1 metres)")
    dtype = np.dtype(DEPTH_ENCODINGS[encoding])
    if message.is_bigendian:
        dtype = dtype.newbyteorder(">")
    rows = _rows(message, topic, 1, dtype.itemsize)
    return np.ascontiguousarray(rows).view(dtype).astype(dtype.newbyteorder("="))


def _compressed_depth(message, topic: str) -> np.ndarray:
    import cv2

    text, data = str(message.format), np.asarray(message.data, np.uint8)
    if not text.startswith(("16UC1", "mono16")):
        raise InputError(f"topic {topic}: compressed depth format '{text}' is not read (16UC1 or mono16 as PNG)")
    if "compressedDepth" in text:
        data = data[12:]  # compressed_depth_image_transport's ConfigHeader (format, 2 quantisation floats)
    from ..array_files import native_stderr

    with native_stderr():  # libpng's own line for a damaged PNG: the refusal below says it
        depth = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if depth is None or depth.dtype != np.uint16 or depth.ndim != 2:
        raise InputError(f"topic {topic}: compressed depth image (format '{text}') is not a 16-bit PNG")
    return depth


def camera_from_info(message, topic: str, size: tuple[int, int]) -> Camera:
    """The :class:`Camera` of a ``sensor_msgs/CameraInfo`` for images of `size` (width, height) px.

    ``K`` is the pinhole matrix of the raw image. A non-zero distortion (``plumb_bob``,
    ``rational_polynomial``: OpenCV's model; ``equidistant``: OpenCV's fisheye) gives remap
    tables to an undistorted image with the same ``K``, as the COLMAP reader does.
    """
    import cv2

    K = np.asarray(message.k if hasattr(message, "k") else message.K, np.float64).reshape(3, 3)
    D = np.asarray(message.d if hasattr(message, "d") else message.D, np.float64).ravel()
    width, height = int(message.width) or size[0], int(message.height) or size[1]
    if (width, height) != tuple(size):
        raise InputError(f"topic {topic}: CameraInfo is for {width} x {height} px images but the colour images are "
                         f"{size[0]} x {size[1]}")
    if not (K[0, 0] > 0 and K[1, 1] > 0 and np.all(np.isfinite(K))):
        raise InputError(f"topic {topic}: CameraInfo has no intrinsics (K = {K.ravel().tolist()}, an uncalibrated "
                         "camera); give them with --intrinsics FX,FY,CX,CY")
    model = str(message.distortion_model) or "plumb_bob"
    camera = Camera(width, height, K, model=f"ROS {model}").checked(f"topic {topic}: CameraInfo")
    if not np.any(D):
        return camera
    if model in ("plumb_bob", "rational_polynomial"):
        maps = cv2.initUndistortRectifyMap(K, D, None, K, (width, height), cv2.CV_32FC1)
    elif model == "equidistant" and len(D) >= 4:
        maps = cv2.fisheye.initUndistortRectifyMap(K, D[:4], np.eye(3), K, (width, height), cv2.CV_32FC1)
    else:
        raise InputError(f"topic {topic}: distortion model '{model}' is not read (plumb_bob, rational_polynomial, "
                         "equidistant)")
    camera.remap = (maps[0], maps[1])
    return camera

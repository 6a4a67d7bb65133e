"""The one type every sequence reader returns: frames with images, optional depth, intrinsics
and ``T_world_cam`` poses (issue "Real captured data").

Frames load their images lazily (a sequence may hold thousands). Images come out undistorted:
a camera with lens distortion carries OpenCV remap tables from the raw image to a pinhole image
with intrinsics ``K``, and both RGB and depth go through them (depth with nearest-neighbour
sampling, so no depth is blended across an edge).

Conventions: ``T_world_cam`` (4, 4) float64 maps OpenCV camera coordinates (x right, y down,
z forward) into the world; metres when :attr:`Sequence.metric` (else up to one unknown scale);
depth maps (H, W) float32 metres, NaN invalid.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError
from ..geometry import check_intrinsics_fit, intrinsics_matrix
from .images import read_depth, read_rgb


@dataclass
class Camera:
    """Intrinsics of the images as :meth:`SequenceFrame.rgb` returns them.

    Attributes:
        width, height: image size in pixels.
        K: (3, 3) float64 pinhole intrinsics (after undistortion).
        model: the source camera model's name (``PINHOLE``, COLMAP's ``OPENCV``, ...), for reports.
        remap: None (the raw images are pinhole already) or (map_x, map_y), each (height, width)
            float32: the raw-image pixel that each undistorted pixel samples (``cv2.remap``).
    """

    width: int
    height: int
    K: np.ndarray
    model: str = "PINHOLE"
    remap: tuple | None = None

    @classmethod
    def pinhole(cls, fx: float, fy: float, cx: float, cy: float, width: int, height: int) -> Camera:
        return cls(int(width), int(height), intrinsics_matrix(fx, fy, cx, cy))

    def checked(self, what: str) -> Camera:
        """This camera if its intrinsics fit its image as typed ``--intrinsics`` must
        (:func:`~frontiernet.geometry.check_intrinsics_fit`: finite, the principal point inside, a focal
        length within 0.04 to 100 x the larger side) and if the image has a size; InputError naming `what` (the
        file it was read from) otherwise."""
        if not (self.width >= 1 and self.height >= 1):  # (was "the principal point ... lies outside the 0 x 480 image")
            raise InputError(f"{what}: an image of {self.width} x {self.height} px; width and height must be at "
                             "least 1 px")
        K = self.K
        check_intrinsics_fit(K[0, 0], K[1, 1], K[0, 2], K[1, 2], self.width, self.height, what)
        return self

    def undistort(self, image: np.ndarray, nearest: bool = False) -> np.ndarray:
        """The raw `image` (any dtype, (H, W) or (H, W, C)) as seen by the pinhole camera ``K``."""
        if self.remap is None:
            return image
        interpolation = cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR
        return cv2.remap(image, self.remap[0], self.remap[1], interpolation, borderMode=cv2.BORDER_CONSTANT)


@dataclass
class SequenceFrame:
    """One frame of a sequence.

    Attributes:
        index: position in the sequence (0-based).
        name: the frame's name (its image file name relative to the sequence's image folder).
        rgb_path: the raw colour image.
        camera: its :class:`Camera`.
        T_world_cam: (4, 4) float64 pose, or None where the source has none for it.
        depth_path: the depth image, or None.
        depth_scale, depth_encoding: how :func:`~frontiernet.sequences.images.read_depth` decodes it.
        timestamp: seconds, where the source records it.
    """

    index: int
    name: str
    rgb_path: Path
    camera: Camera
    T_world_cam: np.ndarray | None = None
    depth_path: Path | None = None
    depth_scale: float = 1000.0
    depth_encoding: str = "scale"
    timestamp: float | None = None

    def rgb(self) -> np.ndarray:
        """(height, width, 3) uint8 RGB, undistorted; InputError if its size is not the camera's."""
        image = read_rgb(self.rgb_path)
        if image.shape[:2] != (self.camera.height, self.camera.width):
            raise InputError(f"{self.rgb_path}: image is {image.shape[1]} x {image.shape[0]} px but its camera is "
                             f"{self.camera.width} x {self.camera.height} (images of mixed sizes?)")
        return self.camera.undistort(image)

    def depth(self) -> np.ndarray | None:
        """(height, width) float32 metres, NaN invalid, undistorted; None without a depth file."""
        if self.depth_path is None:
            return None
        depth = read_depth(self.depth_path, self.depth_scale, self.depth_encoding)
        if depth.shape != (self.camera.height, self.camera.width):
            raise InputError(f"{self.depth_path}: depth is {depth.shape[1]} x {depth.shape[0]} px but the colour "
                             f"image is {self.camera.width} x {self.camera.height}")
        depth = self.camera.undistort(depth, nearest=True)
        depth[~(depth > 0)] = np.nan
        return depth


@dataclass
class RosFrames:
    """Where the frames of a ROS recording sit, so outputs can use its own frame ids and stamps.

    Attributes:
        fixed_frame: the frame the poses are given in (the camera's tf root, or a pose topic's
            ``header.frame_id``); ``map`` when pycolmap posed the frames (``posed`` False).
        camera_frame: the colour images' ``header.frame_id`` (an optical frame: x right, y down,
            z forward).
        stamps_ns: frame name -> the colour image's ``header.stamp`` in integer nanoseconds.
        posed: whether the poses come from the recording (tf or a pose topic).
    """

    fixed_frame: str
    camera_frame: str
    stamps_ns: dict
    posed: bool = True


@dataclass
class Sequence:
    """A posed image sequence.

    Attributes:
        frames: the frames in order.
        format: the reader that produced it (``tum``, ``redwood``, ``colmap``, ``images``, ``rosbag``).
        root: the folder (or file) it was read from.
        metric: whether poses are in metres (False: up to one unknown scale, e.g. COLMAP
            without depth).
        notes: what the reader wants the user to know (registration rate, skipped frames).
        reconstruction: the ``pycolmap.Reconstruction`` the poses came from (COLMAP models and
            image folders), whose points give an up-to-scale sequence its metric scale; else None.
        ros: :class:`RosFrames` of a ROS recording (``rosbag``), else None.
    """

    frames: list
    format: str
    root: Path
    metric: bool = True
    notes: list = field(default_factory=list)
    reconstruction: object = None
    ros: RosFrames | None = None

    def __len__(self) -> int:
        return len(self.frames)

    def __iter__(self):
        return iter(self.frames)

    @property
    def has_poses(self) -> bool:
        return bool(self.frames) and all(frame.T_world_cam is not None for frame in self.frames)

    @property
    def has_depth(self) -> bool:
        return bool(self.frames) and all(frame.depth_path is not None for frame in self.frames)

    def poses(self) -> np.ndarray:
        """(N, 4, 4) float64 ``T_world_cam`` of all frames (InputError if one has none)."""
        missing = [frame.name for frame in self.frames if frame.T_world_cam is None]
        if missing:
            raise InputError(f"{self.root}: {len(missing)} frame(s) have no pose (first: {missing[0]})")
        return np.stack([frame.T_world_cam for frame in self.frames])

    def subset(self, indices) -> Sequence:
        """The frames at `indices` (re-indexed from 0), e.g. every n-th frame."""
        frames = [replace(self.frames[i], index=k) for k, i in enumerate(indices)]
        return replace(self, frames=frames, notes=list(self.notes))

"""Poses of a robot recording (issue 57): ``/tf`` + ``/tf_static`` chains and pose topics.

* :class:`Track`: time-stamped samples of one moving transform ``T_parent_child`` (a ``/tf``
  edge, or a pose topic: ``nav_msgs/Odometry``, ``geometry_msgs/PoseStamped``), interpolated at
  any time (linear in translation, slerp in rotation, as the TUM reader does).
* :class:`TransformBuffer`: the tf tree of a recording (each frame has one parent); the chain of
  a frame up to its root, and that chain's ``T_root_frame`` at given times.

Frames are tf2's: ``T_parent_child`` maps child coordinates into the parent frame, metres.
Times are integer nanoseconds; interpolation runs in seconds relative to the first time asked
for (float64 keeps ~1e-15 s there, where seconds since 1970 keep only ~2e-7 s).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import InputError
from .readers import _interpolated_poses, _nearest
from .ros_messages import frame_id, transform_matrix


class Track:
    """Samples of a moving transform ``T_parent_child`` from one source (a topic).

    Attributes:
        parent, child: frame ids (child None: a PoseStamped's unnamed body).
        source: the topic the samples came from (for messages).
    """

    def __init__(self, parent: str, child: str | None, source: str) -> None:
        self.parent, self.child, self.source = parent, child, source
        self._stamps: list[int] = []
        self._values: list[np.ndarray] = []  # (7,): x, y, z, qx, qy, qz, qw

    def __len__(self) -> int:
        return len(self._stamps)

    def add(self, stamp: int, T: np.ndarray) -> None:
        """One sample: `stamp` ns, `T` (4, 4) float64 ``T_parent_child``."""
        self._stamps.append(int(stamp))
        self._values.append(np.r_[T[:3, 3], Rotation.from_matrix(T[:3, :3]).as_quat()])

    def span_ns(self) -> tuple[int, int]:
        return min(self._stamps), max(self._stamps)

    def at(self, times_ns: np.ndarray, max_time_difference_s: float) -> tuple[np.ndarray, np.ndarray]:
        """(poses (N, 4, 4) float64 ``T_parent_child`` at `times_ns` (N,) interpolated between the
        samples around each time (held at the ends), found (N,) bool: the nearest sample within
        `max_time_difference_s`)."""
        times_ns = np.asarray(times_ns, np.int64)
        origin = int(times_ns.min()) if len(times_ns) else 0
        stamps = (np.asarray(self._stamps, np.int64) - origin) / 1e9
        stamps, unique = np.unique(stamps, return_index=True)
        values = np.asarray(self._values)[unique]
        times = (times_ns - origin) / 1e9
        poses = _interpolated_poses((stamps, values[:, :3], Rotation.from_quat(values[:, 3:])), times)
        return poses, _nearest(stamps, times)[1] <= max_time_difference_s


class TransformBuffer:
    """The tf tree of a recording: static edges (``/tf_static``: one transform each) and moving
    edges (``/tf``: a :class:`Track` each), keyed by child frame."""

    def __init__(self) -> None:
        self.static: dict[str, tuple[str, np.ndarray]] = {}
        self.moving: dict[str, Track] = {}
        self.reparented = 0  # /tf samples that gave a frame a second parent (ignored)

    def __bool__(self) -> bool:
        return bool(self.static or self.moving)

    def add(self, message, static: bool, stamp: int, topic: str) -> None:
        """The transforms of a ``tf2_msgs/TFMessage`` (`stamp`: the message's time, used where a
        transform's own stamp is zero)."""
        for transform in message.transforms:
            parent, child = frame_id(transform.header), str(transform.child_frame_id).lstrip("/")
            T = transform_matrix(transform.transform.translation, transform.transform.rotation,
                                 f"topic {topic}: transform {parent} -> {child}")
            if static:
                self.static[child] = (parent, T)
                continue
            track = self.moving.setdefault(child, Track(parent, child, topic))
            if track.parent != parent:
                self.reparented += 1
                continue
            own = int(transform.header.stamp.sec) * 1_000_000_000 + int(transform.header.stamp.nanosec)
            track.add(own or stamp, T)

    def parent(self, frame: str):
        """(parent frame, Track or (4, 4) static T) of `frame`, or None at a root."""
        if frame in self.moving:
            return self.moving[frame].parent, self.moving[frame]
        if frame in self.static:
            return self.static[frame]
        return None

    def chain(self, frame: str, stop: str | None = None) -> list[tuple[str, str, object]]:
        """The edges (parent, child, Track or static T) from `frame` up to its root (or up to
        `stop`), nearest first; InputError on a loop."""
        edges, seen = [], [frame]
        while frame != stop and (edge := self.parent(frame)) is not None:
            parent, transform = edge
            if parent in seen:
                raise InputError(f"tf: the frames {' -> '.join([*seen, parent])} form a loop")
            edges.append((parent, frame, transform))
            seen.append(parent)
            frame = parent
        return edges

    def moving_frames(self) -> list[str]:
        """The frames of the moving edges (parents and children), sorted."""
        return sorted({frame for track in self.moving.values() for frame in (track.parent, track.child)})


def chain_poses(edges, times_ns: np.ndarray, max_time_difference_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(``T_top_frame`` (N, 4, 4) float64 at `times_ns` (N,), found (N,) bool) of a chain from
    :meth:`TransformBuffer.chain` (top: its last edge's parent); found where every moving edge
    has a sample within `max_time_difference_s`."""
    poses = np.tile(np.eye(4), (len(times_ns), 1, 1))
    found = np.ones(len(times_ns), bool)
    for _, _, transform in reversed(edges):  # from the top down: T_top_a @ T_a_b @ ...
        if isinstance(transform, Track):
            step, ok = transform.at(times_ns, max_time_difference_s)
            found &= ok
        else:
            step = transform
        poses = poses @ step
    return poses, found


def describe(edges, frame: str) -> str:
    """``a -> b -> c``: the chain from `frame` upward."""
    return " -> ".join([frame, *(parent for parent, _, _ in edges)])

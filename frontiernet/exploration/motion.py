"""Motion increments: how the robot follows a route, one paper step at a time.

The robot keeps its camera at a fixed height and pitch and turns in yaw only. Each
increment moves at most ``motion.translation_m`` and turns at most ``motion.rotation_deg``
(just above the paper's step thresholds, so one increment is one step, docs/design.md item 7).
When the next waypoint lies more than ``turn_in_place_deg`` off the heading the robot
first turns on the spot, so the camera looks where the robot is about to go.
"""

from __future__ import annotations

import numpy as np

from ..errors import positive_number
from ..geometry import atan2, pose_from_heading


def wrap_angle(angle: float) -> float:
    """`angle` (radians) wrapped to (-pi, pi]."""
    return float(np.pi - (np.pi - angle) % (2 * np.pi))


def yaw_of(T_world_cam: np.ndarray) -> float:
    """Heading (radians about world z, 0 = +x) of a (4, 4) camera pose's optical axis."""
    forward = T_world_cam[:3, 2]
    return atan2(forward[1], forward[0])


class Motion:
    """Builds the next pose towards a target; configured by the ``motion`` section.

    Args:
        conf: the ``motion`` section of ``configs/explore.yaml``.
        z: camera height (world metres) kept throughout.
    """

    def __init__(self, conf, z: float) -> None:
        self.max_translation = positive_number(conf["translation_m"], "motion.translation_m", "metres")
        self.max_rotation = np.radians(positive_number(conf["rotation_deg"], "motion.rotation_deg", "degrees"))
        self.turn_in_place = np.radians(positive_number(conf["turn_in_place_deg"], "motion.turn_in_place_deg",
                                                        "degrees", allow_zero=True))
        self.pitch = np.radians(float(conf["pitch_deg"]))
        self.reach = positive_number(conf["waypoint_tolerance_m"], "motion.waypoint_tolerance_m", "metres")
        self.z = float(z)

    def pose(self, xy: np.ndarray, yaw: float) -> np.ndarray:
        """(4, 4) ``T_world_cam`` at world (x, y), the camera height, heading `yaw`, the pitch."""
        return pose_from_heading(float(xy[0]), float(xy[1]), self.z, float(yaw), self.pitch)

    def reached(self, xy: np.ndarray, target_xy: np.ndarray) -> bool:
        return float(np.linalg.norm(np.asarray(target_xy)[:2] - np.asarray(xy)[:2])) <= self.reach

    def towards(self, T_world_cam: np.ndarray, target_xy: np.ndarray) -> np.ndarray:
        """The next pose from `T_world_cam` towards `target_xy` (2,): turn first if it is far off
        the heading, else move and turn together (each within one step's limits)."""
        xy, yaw = T_world_cam[:2, 3], yaw_of(T_world_cam)
        offset = np.asarray(target_xy, np.float64)[:2] - xy
        distance = float(np.linalg.norm(offset))
        if distance <= 1e-9:
            return self.pose(xy, yaw)
        error = wrap_angle(atan2(offset[1], offset[0]) - yaw)
        new_yaw = yaw + float(np.clip(error, -self.max_rotation, self.max_rotation))
        if abs(error) > self.turn_in_place:
            return self.pose(xy, new_yaw)
        return self.pose(xy + offset * min(1.0, self.max_translation / distance), new_yaw)

    def turn_by(self, T_world_cam: np.ndarray, angle: float) -> np.ndarray:
        """The next pose turning on the spot by `angle` radians (counter-clockwise), at most one
        increment's ``rotation_deg``."""
        step = float(np.clip(angle, -self.max_rotation, self.max_rotation))
        return self.pose(T_world_cam[:2, 3], yaw_of(T_world_cam) + step)

    def turn_to(self, T_world_cam: np.ndarray, yaw: float) -> tuple[np.ndarray, bool]:
        """The next pose turning on the spot towards heading `yaw`; and whether it gets there."""
        error = wrap_angle(float(yaw) - yaw_of(T_world_cam))
        return self.turn_by(T_world_cam, error), abs(error) <= self.max_rotation

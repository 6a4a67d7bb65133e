"""GLEAM's "vacuum" baseline: moves of its own, no frontiers and no planner.

Straight on while the map allows it; when it does not (or after a collision) a random turn to a
new heading 90-270 deg away, like a robot vacuum. The explorer asks :class:`VacuumMoves` for each
increment in place of a planned route (:attr:`~frontiernet.exploration.methods.Method.moves`).
"""

from __future__ import annotations

import numpy as np

from .motion import Motion, wrap_angle, yaw_of


class VacuumMoves:
    """The vacuum's heading and its next increment.

    Args:
        rng: the run's random generator (:attr:`~frontiernet.exploration.methods.MethodContext.rng`):
            the turns.
    """

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.yaw: float | None = None  # radians about world z; the first pose's heading until a turn

    def next_pose(self, T_world_cam: np.ndarray, motion: Motion, check_move) -> np.ndarray:
        """The next increment from the (4, 4) pose `T_world_cam`: turn to the heading, else one
        ``motion.translation_m`` straight on when ``check_move(T, target)`` (the explorer's move
        check, ``(verdict, xy)``) says ``ok``, else turn to a new random heading."""
        if self.yaw is None:
            self.yaw = yaw_of(T_world_cam)
        pose, aligned = motion.turn_to(T_world_cam, self.yaw)
        if not aligned:
            return pose
        ahead = T_world_cam[:2, 3] + motion.max_translation * np.array([np.cos(self.yaw), np.sin(self.yaw)])
        target = motion.pose(ahead, self.yaw)
        if check_move(T_world_cam, target)[0] == "ok":
            return target
        self.bumped(T_world_cam)
        return motion.turn_to(T_world_cam, self.yaw)[0]

    def bumped(self, T_world_cam: np.ndarray) -> None:
        """Blocked (by the map, or a collision at (4, 4) pose `T_world_cam`): a new heading 90-270
        deg from the current one."""
        current = yaw_of(T_world_cam) if self.yaw is None else self.yaw
        self.yaw = wrap_angle(current + float(self.rng.uniform(np.pi / 2, 3 * np.pi / 2)))


__all__ = ["VacuumMoves"]

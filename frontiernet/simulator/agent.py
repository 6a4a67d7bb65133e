"""Moving the camera: collision-checked motion along poses, and the paper's step count.

Frames and units (docs/design.md): world Z-up, metres, radians; ``T_world_cam`` (4, 4)
float64 camera-to-world poses, OpenCV camera axes.

* **Collision.** The agent is a sphere of ``agent.radius_m`` around the camera centre.
  A move is checked at samples along the straight segment at most
  ``radius_m * substep_fraction`` apart (one batched distance query); consecutive safe
  samples (distance >= radius) are so close that the sphere cannot pass through a
  surface between them (every point of the segment is within radius/4 of a sample, so
  it stays >= 0.75 radius from the mesh). A move into an obstacle stops at the last safe
  pose (refined by bisection towards the first colliding sample) and is reported, never
  passes through. Orientation is interpolated by slerp along the same parameter.
* **Steps** (paper, docs/design.md section 7): a new step is counted when the pose differs
  from the pose of the last counted step by more than ``step_translation_m`` in position
  or ``step_rotation_deg`` in rotation (geodesic angle). The :class:`Agent` feeds its
  :class:`StepCounter` the end pose of every move (the waypoints a planner gives it), not
  intermediate collision samples: planners discretise their paths into waypoints as the
  paper's planners do.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Iterable

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from ..errors import InputError, positive_number
from ..geometry import rotation_angle
from .raycast import distance_to_surface
from .voxels import VoxelGrid

if TYPE_CHECKING:
    from omegaconf import DictConfig

    from ..scenes import Scene

_TOL = 1e-9  # poses exactly at a threshold (0.05 + 0.05 m) do not count as a step


def agent_config(conf: "DictConfig") -> "DictConfig":
    """The ``agent`` section from `conf` (a whole sim config or the section)."""
    return conf["agent"] if "agent" in conf else conf


def _as_pose(T, what: str) -> np.ndarray:
    T = np.asarray(T, np.float64)
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise InputError(f"{what} must be a finite 4x4 T_world_cam, got shape {T.shape}")
    R = T[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-4) or not np.isclose(np.linalg.det(R), 1.0, atol=1e-4):
        raise InputError(f"{what} must have a rotation matrix in its upper-left 3x3 block")
    return T.copy()


class StepCounter:
    """The paper's step count over a sequence of poses.

    Args:
        translation_m: a pose more than this from the last counted one (metres) is a step.
        rotation_rad: ... or rotated by more than this (geodesic angle, radians).
        T_start: (4, 4) pose the count starts from (the first update is compared to it);
            when None the first :meth:`update` only sets the reference.
    """

    def __init__(self, translation_m: float, rotation_rad: float, T_start: np.ndarray | None = None) -> None:
        if not (translation_m > 0 and rotation_rad > 0):
            raise InputError(f"step thresholds must be positive, got {translation_m} m and {rotation_rad} rad")
        self.translation_m = float(translation_m)
        self.rotation_rad = float(rotation_rad)
        self.count = 0
        self.reference = None if T_start is None else np.asarray(T_start, np.float64).copy()

    @classmethod
    def from_config(cls, conf: "DictConfig", T_start: np.ndarray | None = None) -> "StepCounter":
        """Thresholds from the ``agent`` section (``step_translation_m``, ``step_rotation_deg``) of
        ``configs/sim.yaml`` (or the whole sim config)."""
        conf = agent_config(conf)
        return cls(float(conf.step_translation_m), float(np.deg2rad(conf.step_rotation_deg)), T_start)

    def reset(self, T_start: np.ndarray | None = None) -> None:
        """Zero the count and restart from `T_start`."""
        self.count = 0
        self.reference = None if T_start is None else np.asarray(T_start, np.float64).copy()

    def is_step(self, T_a: np.ndarray, T_b: np.ndarray) -> bool:
        """Whether (4, 4) pose `T_b` is a new step relative to `T_a`."""
        moved = float(np.linalg.norm(T_b[:3, 3] - T_a[:3, 3]))
        turned = rotation_angle(T_a[:3, :3], T_b[:3, :3])
        return moved > self.translation_m + _TOL or turned > self.rotation_rad + _TOL

    def update(self, T: np.ndarray) -> bool:
        """Feed the next (4, 4) pose; return True (and count it) if it is a new step."""
        T = np.asarray(T, np.float64)
        if self.reference is None:
            self.reference = T.copy()
            return False
        if self.is_step(self.reference, T):
            self.count += 1
            self.reference = T.copy()
            return True
        return False

    def count_path(self, poses: Iterable[np.ndarray]) -> int:
        """Feed every (4, 4) pose of `poses` in order; return the number of steps they added."""
        before = self.count
        for T in poses:
            self.update(T)
        return self.count - before


@dataclass
class MoveResult:
    """What one :meth:`Agent.move_to` did.

    Attributes:
        reached: the agent is at the target pose.
        collided: the sphere would have touched the mesh; the move stopped before it.
        left_free_space: the move would have left the explorable volume (agent built with
            voxels); the move stopped before it.
        T_world_cam: (4, 4) float64 final pose.
        distance_m: metres travelled by the camera centre.
        steps_added: steps counted by this move (0 or 1).
        blocked_at: (3,) float64 first sample of the segment found unsafe, or None.
        clearance_m: distance from the final position to the mesh (metres).
        contact_point: (3,) float64 world metres, what a bump sensor reports when the move was
            stopped (None otherwise): the mesh point the sphere touched at `blocked_at`, or
            `blocked_at` itself where the move would have left the free space
            (:meth:`Agent.contact_point`).
    """

    reached: bool
    collided: bool
    left_free_space: bool
    T_world_cam: np.ndarray
    distance_m: float
    steps_added: int
    blocked_at: np.ndarray | None
    clearance_m: float
    contact_point: np.ndarray | None = None


CONTACT_PROBE_M = 0.005
"""Step of the central differences that give a contact's direction (:meth:`Agent.contact_point`):
well under the agent's radius and a voxel, well over float error."""


class Agent:
    """A camera that moves through a scene without passing through its surfaces.

    Args:
        scene: the scene (world frame, Z-up, metres).
        T_start: (4, 4) start pose; its centre must be at least ``radius_m`` from the mesh.
        conf: the ``agent`` section of ``configs/sim.yaml`` (or the whole sim config).
        voxels: optional voxel grid; when given, moves also stop before leaving the free
            space (a sample neither explorable nor in an occupied voxel, e.g. flying out of
            a house without a ceiling).
    Raises:
        InputError: bad config values or a start pose inside an obstacle.
    """

    def __init__(self, scene: "Scene", T_start: np.ndarray, conf: "DictConfig",
                 voxels: VoxelGrid | None = None) -> None:
        conf = agent_config(conf)
        self.scene, self.voxels = scene, voxels
        self.radius = positive_number(conf.radius_m, "agent.radius_m", "metres")
        fraction = float(conf.substep_fraction)
        if not 0 < fraction <= 0.5:
            raise InputError(f"agent.substep_fraction must be in (0, 0.5], got {conf.substep_fraction!r}")
        self.substep = self.radius * fraction
        self.refine_iterations = int(conf.refine_iterations)
        T_start = _as_pose(T_start, "start pose")
        clearance = self._clearance(T_start[None, :3, 3])[0]
        if clearance < self.radius:
            raise InputError(f"start pose inside an obstacle: position {np.round(T_start[:3, 3], 3).tolist()} m is "
                             f"{clearance:.3f} m from the mesh (agent radius {self.radius} m)")
        if voxels is not None and not self._in_free_space(T_start[None, :3, 3])[0]:
            raise InputError(f"start pose outside the scene's free space: position "
                             f"{np.round(T_start[:3, 3], 3).tolist()} m is not in the explorable volume")
        self._pose = T_start
        self._trajectory = [T_start.copy()]
        self.counter = StepCounter.from_config(conf, T_start)
        self.distance_m = 0.0
        self.collisions = 0

    @property
    def pose(self) -> np.ndarray:
        """(4, 4) float64 current ``T_world_cam`` (a copy)."""
        return self._pose.copy()

    @property
    def position(self) -> np.ndarray:
        """(3,) float64 current camera centre, world metres."""
        return self._pose[:3, 3].copy()

    @property
    def steps(self) -> int:
        """Steps counted so far (paper's rule)."""
        return self.counter.count

    @property
    def trajectory(self) -> np.ndarray:
        """(N, 4, 4) float64 poses: the start and the end pose of every move that changed the pose."""
        return np.stack(self._trajectory)

    def _clearance(self, points: np.ndarray) -> np.ndarray:
        return distance_to_surface(self.scene, points).astype(np.float64)

    def _in_free_space(self, points: np.ndarray) -> np.ndarray:
        if self.voxels is None:
            return np.ones(len(points), bool)
        return self.voxels.is_explorable(points) | self.voxels.is_occupied(points)

    def _safe(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(N, 3) points -> (safe, touches_mesh, leaves_free_space, clearance) per point."""
        clearance = self._clearance(points)
        touches = clearance < self.radius
        leaves = ~touches & ~self._in_free_space(points)
        return ~(touches | leaves), touches, leaves, clearance

    def move_to(self, T_target: np.ndarray) -> MoveResult:
        """Move in a straight line (slerped orientation) to (4, 4) `T_target`, stopping before obstacles."""
        T_target = _as_pose(T_target, "target pose")
        start, end = self._pose[:3, 3], T_target[:3, 3]
        length = float(np.linalg.norm(end - start))
        n = max(1, int(np.ceil(length / self.substep)))
        t = np.arange(1, n + 1) / n
        safe, touches, leaves, clearance = self._safe(start + t[:, None] * (end - start))
        bad = np.flatnonzero(~safe)
        blocked_at, reached = None, len(bad) == 0
        collided = left = False
        if reached:
            t_final, final_clearance = 1.0, float(clearance[-1])
        else:
            i = int(bad[0])
            blocked_at = start + t[i] * (end - start)
            collided, left = bool(touches[i]), bool(leaves[i])
            t_safe = t[i - 1] if i > 0 else 0.0
            t_bad, final_clearance = t[i], float(clearance[i - 1]) if i > 0 else None
            for _ in range(self.refine_iterations):  # bisect towards the contact
                mid = 0.5 * (t_safe + t_bad)
                ok, _, _, c = self._safe((start + mid * (end - start))[None])
                if ok[0]:
                    t_safe, final_clearance = mid, float(c[0])
                else:
                    t_bad = mid
            t_final = t_safe
            if final_clearance is None:
                final_clearance = float(self._clearance(start[None])[0])
            self.collisions += 1
        T_final = T_target.copy() if reached else self._interpolate(T_target, t_final)
        moved = length * t_final
        self.distance_m += moved
        steps = 0
        if not np.array_equal(T_final, self._pose):
            self._pose = T_final
            self._trajectory.append(T_final.copy())
            steps = int(self.counter.update(T_final))
        return MoveResult(reached=reached, collided=collided, left_free_space=left, T_world_cam=T_final.copy(),
                          distance_m=moved, steps_added=steps, blocked_at=blocked_at, clearance_m=final_clearance,
                          contact_point=None if blocked_at is None else self.contact_point(blocked_at, collided))

    def contact_point(self, point: np.ndarray, touches_mesh: bool) -> np.ndarray:
        """Where the sphere centred at `point` ((3,) world metres, a sample a move stopped before)
        meets what stopped it, as a bump sensor reports it: with `touches_mesh`, the nearest
        point of the mesh, along the distance field's gradient (central differences of
        :data:`CONTACT_PROBE_M`) at the clearance; otherwise (the sample leaves the free space)
        `point` itself. (3,) float64 world metres."""
        point = np.asarray(point, np.float64)
        if not touches_mesh:
            return point.copy()
        offsets = np.vstack([np.eye(3), -np.eye(3)]) * CONTACT_PROBE_M
        distances = self._clearance(np.vstack([point[None], point + offsets]))
        gradient = (distances[1:4] - distances[4:7]) / (2.0 * CONTACT_PROBE_M)
        norm = float(np.linalg.norm(gradient))
        if norm < 1e-9:  # (inside a thin gap: no direction) the sample itself
            return point.copy()
        return point - gradient / norm * float(distances[0])

    def _interpolate(self, T_target: np.ndarray, t: float) -> np.ndarray:
        """Pose at fraction `t` of the way from the current pose to `T_target` (lerp + slerp)."""
        T = np.eye(4)
        T[:3, 3] = self._pose[:3, 3] + t * (T_target[:3, 3] - self._pose[:3, 3])
        if t <= 0:
            T[:3, :3] = self._pose[:3, :3]
        else:
            slerp = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([self._pose[:3, :3], T_target[:3, :3]])))
            T[:3, :3] = slerp([t]).as_matrix()[0]
        return T

    def follow(self, poses: Iterable[np.ndarray]) -> list[MoveResult]:
        """Move through (4, 4) poses in order; stop at the first move that does not reach its pose.

        Returns the :class:`MoveResult` of every move made (the last one tells why it stopped).
        """
        results = []
        for T in poses:
            result = self.move_to(T)
            results.append(result)
            if not result.reached:
                break
        return results

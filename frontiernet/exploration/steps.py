"""Where the steps go: a per-step account of an exploration run (``metrics.json``'s ``step_account``).

Every step of a run falls into exactly one category, and the budget steps a run left unused
when it stopped early into one of two more, so the categories sum to the step budget. A *step*
is a :class:`~frontiernet.exploration.explorer.StepRecord` whose ``step`` count rose over the
record before (records with the same count are increments that did not count as steps,
docs/design.md item 7). A step's motion is taken from the pose of the step before (record 0
for the first step: the pose the step counter compares with), its coverage gain likewise
(coverage x the scene's explorable volume, m^3). Thresholds are the ``steps`` section of
``configs/explore.yaml`` (:class:`AccountSettings`); the account is reporting only and changes
no run. In order of precedence:

- ``start_turn``: the leading steps that turn on the spot with no goal while the turn since the
  start is at most ``motion.start_turn_deg`` (the explorer's start turn);
- ``livelock``: a step in a window of ``livelock_window_steps`` consecutive steps that together
  gain at most ``livelock_gain_m3``, with frontiers listed after every step of it, whose
  positions all lie within ``livelock_radius_m`` of their mean, and in which the robot comes back
  (enters a cell, as for ``revisit``, that it left at least ``revisit_after_steps`` steps before
  within the window) or translates less than ``revisit_cell_m`` in all (turns on the spot): the
  robot stays in a small area going back and forth or round, seeing nothing new, with somewhere
  left to go (the union of all such windows; it takes precedence over every category below);
- ``look_around``: a turn on the spot (moved at most ``translation_m``) with no goal after it
  (``goal`` None: no route; a method with moves of its own, ``vacuum``, never has one);
- ``turn``: a turn on the spot with a goal (turning towards a waypoint, the move check's looks,
  the final alignment with the frontier's direction);
- ``move_new``: a translation (moved more than ``translation_m``) gaining more than ``new_volume_m3``;
- ``revisit``: a translation gaining at most that whose position lies in a cell (``revisit_cell_m``
  squares of the world xy, from 0) that the robot left at least ``revisit_after_steps`` steps
  before: back-and-forth;
- ``move_none``: any other translation gaining at most ``new_volume_m3``;
- ``unused_premature``: the budget steps not taken, when the run stopped with "no frontiers
  left" while more than ``premature_unseen`` of the explorable volume was unseen and reachable
  (``unseen_reachable``: unseen explorable voxels in the columns the robot can reach,
  :func:`reachable_columns`, that the camera never saw at its own height,
  :meth:`~frontiernet.exploration.score.GroundTruthScore.unseen_in`): a premature stop;
- ``unused_done``: the budget steps not taken otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import positive_number, whole_number
from .motion import wrap_angle

CATEGORIES = ("start_turn", "look_around", "turn", "move_new", "move_none", "revisit", "livelock",
              "unused_premature", "unused_done")
"""The account's categories, in the order ``step_account`` lists them (see the module docstring)."""
NO_FRONTIERS = "no frontiers left"  # the explorer's stop reason when nothing is left to explore
_TURN_TOLERANCE_RAD = 1e-3  # record yaws are rounded to 1e-4 rad: 36 increments err by < 2e-3 rad


@dataclass(frozen=True)
class AccountSettings:
    """The ``steps`` section of ``configs/explore.yaml`` (see the module docstring)."""

    translation_m: float
    new_volume_m3: float
    revisit_cell_m: float
    revisit_after_steps: int
    livelock_window_steps: int
    livelock_gain_m3: float
    livelock_radius_m: float
    premature_unseen: float
    reachable_dilation_m: float

    @classmethod
    def from_config(cls, conf) -> AccountSettings:
        """From the ``steps`` section; raises :class:`~frontiernet.errors.InputError` on a bad value."""
        def metres(key: str, zero: bool = True) -> float:
            return positive_number(conf[key], f"steps.{key}", "metres", allow_zero=zero)

        return cls(metres("translation_m"),
                   positive_number(conf["new_volume_m3"], "steps.new_volume_m3", "m^3", allow_zero=True),
                   metres("revisit_cell_m", zero=False),
                   whole_number(conf["revisit_after_steps"], "steps.revisit_after_steps", 1),
                   whole_number(conf["livelock_window_steps"], "steps.livelock_window_steps", 1),
                   positive_number(conf["livelock_gain_m3"], "steps.livelock_gain_m3", "m^3", allow_zero=True),
                   metres("livelock_radius_m"),
                   positive_number(conf["premature_unseen"], "steps.premature_unseen", allow_zero=True),
                   metres("reachable_dilation_m"))


@dataclass(frozen=True)
class Steps:
    """The counted steps of a run, S of them, as arrays (index s: step s + 1).

    Attributes:
        xy: (S, 2) float64 camera position after the step, world metres.
        moved_m: (S,) float64 xy distance from the position of the step before, metres.
        turned_rad: (S,) float64 cumulative |yaw change| since record 0 (unwrapped, radians).
        gain_m3: (S,) float64 coverage gained since the step before x the explorable volume.
        has_goal: (S,) bool a goal (``goal`` not None) after the step.
        frontiers: (S,) int64 frontiers listed after the step.
    """

    xy: np.ndarray
    moved_m: np.ndarray
    turned_rad: np.ndarray
    gain_m3: np.ndarray
    has_goal: np.ndarray
    frontiers: np.ndarray

    def __len__(self) -> int:
        return len(self.moved_m)


def counted_steps(records, explorable_m3: float) -> Steps:
    """The :class:`Steps` of `records` (StepRecords in order, record 0 before any move; or any
    objects with their ``step``, ``position``, ``yaw``, ``coverage``, ``goal``, ``frontiers``).
    A record whose count rose by k > 1 (never, one increment is one step at most) gives k steps."""
    xy, moved, turned, gain, goal, frontiers = [], [], [], [], [], []
    if not records:
        return Steps(np.zeros((0, 2)), *(np.zeros(0) for _ in range(3)), np.zeros(0, bool), np.zeros(0, np.int64))
    last, total_turn = records[0], 0.0
    for before, record in zip(records, records[1:]):
        total_turn += abs(wrap_angle(float(record.yaw) - float(before.yaw)))
        for k in range(int(record.step) - int(last.step)):
            here = np.asarray(record.position[:2], np.float64)
            xy.append(here)
            moved.append(float(np.linalg.norm(here - np.asarray(last.position[:2], np.float64))) if k == 0 else 0.0)
            turned.append(total_turn)
            gain.append((float(record.coverage) - float(last.coverage)) * float(explorable_m3) if k == 0 else 0.0)
            goal.append(record.goal is not None)
            frontiers.append(int(record.frontiers))
        if int(record.step) > int(last.step):
            last = record
    return Steps(np.reshape(xy, (-1, 2)), np.asarray(moved), np.asarray(turned), np.asarray(gain),
                 np.asarray(goal, bool), np.asarray(frontiers, np.int64))


def start_turn_mask(steps: Steps, start_xy: np.ndarray, start_turn_deg: float,
                    settings: AccountSettings) -> np.ndarray:
    """(S,) bool: the leading steps that turn on the spot at `start_xy` ((2,) position of record 0,
    metres) with no goal, the turn since the start at most `start_turn_deg` (``motion.start_turn_deg``;
    0: none)."""
    if float(start_turn_deg) <= 0 or not len(steps):
        return np.zeros(len(steps), bool)
    at_start = np.linalg.norm(steps.xy - np.reshape(start_xy, (1, 2)), axis=1) <= settings.translation_m
    limit = np.radians(float(start_turn_deg)) + _TURN_TOLERANCE_RAD
    turning = at_start & (steps.moved_m <= settings.translation_m) & ~steps.has_goal & (steps.turned_rad <= limit)
    return np.cumprod(turning).astype(bool)


def livelock_mask(steps: Steps, settings: AccountSettings) -> np.ndarray:
    """(S,) bool: the steps of any livelock window (module docstring): ``livelock_window_steps``
    consecutive steps gaining at most ``livelock_gain_m3`` in all, frontiers listed after each,
    positions within ``livelock_radius_m`` of their mean, and the robot either coming back within
    the window (:func:`comes_back`) or translating less than ``revisit_cell_m`` in all (turning on
    the spot). A transit over seen ground, however bent, never comes back: it is no livelock."""
    width, count = settings.livelock_window_steps, len(steps)
    mask = np.zeros(count, bool)
    if count < width:
        return mask
    gains = np.concatenate([[0.0], np.cumsum(steps.gain_m3)])
    listed = np.concatenate([[0], np.cumsum(steps.frontiers > 0)])
    cells = np.floor(steps.xy / settings.revisit_cell_m).astype(np.int64)
    for start in range(count - width + 1):
        end = start + width
        if gains[end] - gains[start] > settings.livelock_gain_m3 or listed[end] - listed[start] < width:
            continue
        window = steps.xy[start:end]
        if np.max(np.linalg.norm(window - window.mean(axis=0), axis=1)) > settings.livelock_radius_m:
            continue
        still = float(steps.moved_m[start + 1:end].sum()) < settings.revisit_cell_m
        if still or comes_back(cells[start:end], settings.revisit_after_steps):
            mask[start:end] = True
    return mask


def comes_back(cells: np.ndarray, after_steps: int) -> bool:
    """Whether a sequence of (N, 2) int cells, one per step, returns to a cell it left at least
    `after_steps` steps before (see :func:`revisit_mask`)."""
    left_at: dict[tuple, int] = {}
    for index in range(1, len(cells)):
        here, before = tuple(cells[index]), tuple(cells[index - 1])
        if here != before:
            left_at[before] = index - 1
        if here in left_at and left_at[here] <= index - after_steps:
            return True
    return False


def revisit_mask(steps: Steps, start_xy: np.ndarray, settings: AccountSettings) -> np.ndarray:
    """(S,) bool: steps whose position lies in a cell (``revisit_cell_m`` squares) that the robot
    left at least ``revisit_after_steps`` steps before (it was there, went elsewhere, came back;
    wavering along a cell border within fewer steps is not a revisit). `start_xy`: (2,) position
    of record 0."""
    cells = np.floor(np.vstack([np.reshape(start_xy, (1, 2)), steps.xy]) / settings.revisit_cell_m).astype(np.int64)
    left_at: dict[tuple, int] = {}  # cell -> the step count when the robot last left it
    mask = np.zeros(len(steps), bool)
    for index in range(1, len(cells)):
        here, before = tuple(cells[index]), tuple(cells[index - 1])
        if here != before:
            left_at[before] = index - 1
        mask[index - 1] = here in left_at and left_at[here] <= index - settings.revisit_after_steps
    return mask


def classify(steps: Steps, start_xy: np.ndarray, start_turn_deg: float, settings: AccountSettings) -> np.ndarray:
    """(S,) category names (``<U16``) of the taken steps, by the precedence of the module docstring."""
    translating = steps.moved_m > settings.translation_m
    new = steps.gain_m3 > settings.new_volume_m3
    names = np.where(translating, np.where(new, "move_new", np.where(revisit_mask(steps, start_xy, settings),
                                                                     "revisit", "move_none")),
                     np.where(steps.has_goal, "turn", "look_around")).astype("<U16")
    names[livelock_mask(steps, settings)] = "livelock"
    names[start_turn_mask(steps, start_xy, start_turn_deg, settings)] = "start_turn"
    return names


def is_premature(stop_reason: str, unseen_reachable: float | None, settings: AccountSettings) -> bool:
    """Whether a run stopped with "no frontiers left" while more than ``premature_unseen`` of the
    explorable volume was unseen and reachable (None: not known, not premature)."""
    return stop_reason == NO_FRONTIERS and unseen_reachable is not None and unseen_reachable > settings.premature_unseen


def step_account(records, budget: int, explorable_m3: float, start_turn_deg: float, settings: AccountSettings,
                 premature: bool) -> dict[str, int]:
    """Steps per category of :data:`CATEGORIES` (every one, zeros too), summing to `budget` (or to
    the steps taken, should they exceed it): the taken steps classified (:func:`classify`), the
    rest ``unused_premature`` when `premature`, else ``unused_done``."""
    steps = counted_steps(records, explorable_m3)
    start_xy = np.asarray(records[0].position[:2], np.float64) if records else np.zeros(2)
    names = classify(steps, start_xy, start_turn_deg, settings)
    account = {name: int(np.count_nonzero(names == name)) for name in CATEGORIES}
    account["unused_premature" if premature else "unused_done"] = max(int(budget) - len(steps), 0)
    return account


def run_account(records, budget: int, stop_reason: str, explorable_m3: float, unseen_reachable: float | None,
                conf) -> dict:
    """What ``metrics.json`` gets: ``step_account`` (:func:`step_account`), ``unseen_reachable``
    (the fraction of the explorable volume unseen at the end in the reachable columns, rounded to
    5 decimals; None when unknown) and ``premature_stop`` (:func:`is_premature`).

    Args:
        records: the run's StepRecords; budget: its step budget; stop_reason: why it stopped.
        explorable_m3: the scene's explorable volume. conf: the run config (``steps``,
            ``motion.start_turn_deg``).
    """
    settings = AccountSettings.from_config(conf.steps)
    premature = is_premature(stop_reason, unseen_reachable, settings)
    account = step_account(records, budget, explorable_m3, float(conf.motion.start_turn_deg), settings, premature)
    return {"step_account": account,
            "unseen_reachable": None if unseen_reachable is None else round(float(unseen_reachable), 5),
            "premature_stop": premature}


def dilated_columns(columns: np.ndarray, voxel_size: float, radius_m: float) -> np.ndarray:
    """(X, Y) bool: `columns` ((X, Y) bool) grown by a disk of `radius_m` (cells of `voxel_size` m): the
    cells within ``floor(radius / voxel)`` cells (Euclidean, centre to centre) of a column. Taken from the
    distance transform, whose cost does not grow with the radius (a dilation by the disk's structure
    allocated it whole: 1e9 m asked for 149 GiB)."""
    from scipy import ndimage

    reach = int(np.floor(float(radius_m) / float(voxel_size) + 1e-9))
    if reach <= 0 or not columns.any():
        return columns.copy()
    return ndimage.distance_transform_edt(~columns) <= reach + 1e-9


def reachable_columns(scene, voxels, conf) -> tuple[np.ndarray, slice]:
    """The columns of the scene grid the robot can reach and the voxel layers of its camera's
    height band, for :meth:`~frontiernet.exploration.score.GroundTruthScore.unseen_in`.

    Returns:
        (columns, band): columns, (X, Y) bool: the main region of
        :func:`~frontiernet.exploration.region.start_sampler` (columns at camera height at least
        ``planner.clearance_m`` from obstacles, the largest connected part) grown by
        ``steps.reachable_dilation_m``: the growth adds back the band the clearance cuts off along
        the walls of the same rooms, which the camera sees from a step away; it is kept that small
        (not the sensor range) because a wider disk reaches through walls into rooms the robot
        cannot enter and outdoors. band: the z slice of the layers within ``planner.height_band_m``
        of the camera (the planning band, as the region's clearance is taken over).
    """
    from .region import camera_z, start_sampler

    region = start_sampler(scene, voxels, conf)[0]
    columns = dilated_columns(region, voxels.voxel_size, AccountSettings.from_config(conf.steps).reachable_dilation_m)
    k = voxels.layer(camera_z(scene, voxels, conf))
    half = max(1, int(np.ceil(float(conf.planner.height_band_m) / voxels.voxel_size)))
    return columns, slice(max(k - half, 0), k + half + 1)


__all__ = ["CATEGORIES", "AccountSettings", "Steps", "counted_steps", "classify", "start_turn_mask", "livelock_mask",
           "comes_back", "revisit_mask", "is_premature", "step_account", "run_account", "dilated_columns",
           "reachable_columns"]

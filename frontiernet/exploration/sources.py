"""What an exploration method is made of (:mod:`.methods` builds and registers them): a frontier
source, the candidate goals it proposes each frame, and a goal rule, how the planner ranks them
(or, without frontiers, the method's own moves)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError
from .perception import Perception, PerceptionResult, plain_view

GOAL_RULES = ("utility", "nearest", "random", "rate", "vacuum")


class FrontierSource:
    """Proposes one frame's frontier observations.

    ``source(frame, depth, stopwatch) -> (observations, view)``: `observations` are
    :class:`~frontiernet.frontiers.anchoring.FrontierObservation`-like records in the world
    frame; `view` a :class:`~frontiernet.exploration.perception.PerceptionResult` for the
    video (frontier pixels, or none). `frame` is the rendered
    :class:`~frontiernet.simulator.camera.Frame` (its pose ``T_world_cam``), `depth` (H, W)
    float32 metres, NaN invalid, the robot's depth. `stopwatch` is the explorer's
    :class:`~frontiernet.timing.Stopwatch`: ``with stopwatch("perception"): ...`` times a stage of
    the step (``perception``, ``anchoring``). The run's map already holds this frame.
    """

    def __call__(self, frame, depth: np.ndarray, stopwatch) -> tuple[list, PerceptionResult]:
        raise NotImplementedError

    def widen(self) -> bool:
        """Called when the run would stop with no frontier left: from now on, propose what was held
        back as noise too. Returns whether anything changes (the loop then looks around again); the
        default holds nothing back."""
        return False


class ImageSource(FrontierSource):
    """Frontier pixels from a perception, lifted to 3D by anchoring (paper III-E).

    Args:
        perception: frame, depth -> :class:`~frontiernet.exploration.perception.PerceptionResult`.
        anchoring: the ``anchoring`` section of the run config.
        rng: the generator of anchoring's pixel subset (the run's).
    """

    def __init__(self, perception: Perception, anchoring, rng: np.random.Generator) -> None:
        self.perception, self.anchoring, self.rng = perception, anchoring, rng

    def __call__(self, frame, depth, stopwatch):
        from ..frontiers import anchor_prediction

        with stopwatch("perception"):
            seen = self.perception(frame, depth)
        with stopwatch("anchoring"):
            observations = anchor_prediction(seen.distance_field, seen.gain_class, seen.depth, seen.K,
                                             frame.T_world_cam, self.anchoring, seen.labels, self.rng, seen.gain_logits)
        return observations, seen


class MapSource(FrontierSource):
    """Frontiers of the occupancy map at the camera's height (Yamauchi 1997): free cells next
    to unknown ones, clustered; gain ``uniform`` or ``unknown_volume`` (the unknown volume a
    camera at the frontier would see). Timed as ``anchoring`` (frontier extraction).

    Args:
        gain: ``uniform`` or ``unknown_volume``.
        occupancy: the run's map (:attr:`MethodContext.map`).
        conf: the run config (``map_frontiers``, ``planner.height_band_m``, ``tracking.gain_view``).
    """

    def __init__(self, gain: str, occupancy, conf) -> None:
        if occupancy is None:
            raise ValueError("map frontiers need the run's map (a MethodContext with voxels)")
        self.gain, self.map, self.conf = gain, occupancy, conf
        self.widened_conf = None  # the config of the small regions, once widened

    def __call__(self, frame, depth, stopwatch):
        from ..frontiers.map_frontiers import map_frontiers

        z = float(frame.T_world_cam[2, 3])  # the camera height the robot keeps
        with stopwatch("anchoring"):
            conf = self.conf if self.widened_conf is None else self.widened_conf
            observations = map_frontiers(self.map, z, conf, frame.T_world_cam, self.gain)
        return observations, plain_view(frame, depth)

    def widen(self) -> bool:
        """``map_frontiers.min_cells_before_stop``: from now on, every frame proposes the regions down
        to that many cells (once; null: never). A door the monocular map half-shuts shows a frontier of
        two or three cells, dropped as noise, and the run stopped with a quarter of the building behind
        it (docs/results/2026-12-07-small-frontiers-before-stop.md). (The regions of ``min_cells``
        may still be proposed then, every one of them a view the robot has had: the tracker drops them.)"""
        from omegaconf import OmegaConf

        smallest = widened_min_cells(self.conf, self.conf.map_frontiers.min_cells)
        if self.widened_conf is not None or smallest is None:
            return False
        self.widened_conf = OmegaConf.merge(self.conf, {"map_frontiers": {"min_cells": smallest}})
        return True


def widened_min_cells(conf, min_cells: int) -> int | None:
    """The size (cells) down to which a map-frontier source proposes its regions once a run would stop,
    ``map_frontiers.min_cells_before_stop`` of run config `conf`; None where that widens nothing (null, or
    not below the source's own `min_cells`). Every source of map frontier regions reads it (:class:`MapSource`,
    mapex's, seer's clusters): a door the monocular map half-shuts is a region of 2-3 cells."""
    smallest = conf.map_frontiers.get("min_cells_before_stop")
    return None if smallest is None or int(smallest) >= int(min_cells) else int(smallest)


@dataclass
class Method:
    """An exploration method (see the module docstring).

    Attributes:
        name: as on the command line.
        source: its frontier source (None: no frontiers, e.g. ``vacuum``).
        goal: ``utility`` (gain^e / distance, paper Eq. 8), ``nearest`` (1 / distance),
            ``random`` (a random score drawn once per frontier), ``rate`` (gain / distance: volume
            per metre, whatever ``planner.gain_exponent``) or ``vacuum`` (no planner: the
            method's own `moves`).
        fresh_frontiers: the frontier set is this frame's proposals only (map frontiers are
            recomputed from the whole map every frame); otherwise observations are merged
            into the tracked frontiers across frames (image frontiers).
        map_regions: its frontiers are regions of the map's frontier cells
            (:func:`~frontiernet.frontiers.map_frontiers.map_frontiers`), proposed afresh each frame,
            whose direction follows the robot where their steps to unknown cells cancel: a visited one
            proposed still buries its place (``tracking.bury_visited``). Views (nbvp, omniscient, seer)
            are not: their heading is the view's own.
        uses_model: it runs the FrontierNet model file (a run records which file).
        moves: the method's own moves, which the explorer follows instead of planned routes
            (goal rule ``vacuum``): ``next_pose(T_world_cam, motion, check_move) -> (4, 4) pose``
            for each increment (`check_move` the explorer's move check) and ``bumped(T_world_cam)``
            after a collision, e.g. :class:`~frontiernet.exploration.vacuum.VacuumMoves`. None:
            the planner's route to the chosen frontier.
    """

    name: str
    source: FrontierSource | None
    goal: str = "utility"
    fresh_frontiers: bool = False
    map_regions: bool = False
    uses_model: bool = False
    moves: Any = None

    def __post_init__(self) -> None:
        if self.goal not in GOAL_RULES:
            raise InputError(f"method {self.name!r}: goal rule must be one of {', '.join(GOAL_RULES)}, got {self.goal!r}")
        if self.source is None and self.goal != "vacuum":
            raise InputError(f"method {self.name!r} has no frontier source: only the vacuum goal rule works without one")
        if (self.goal == "vacuum") != (self.moves is not None):
            raise InputError(f"method {self.name!r}: the vacuum goal rule and a method's own moves go together")

    def propose(self, frame, depth: np.ndarray, stopwatch) -> tuple[list, PerceptionResult]:
        """This frame's frontier observations and the view for the video (see :class:`FrontierSource`;
        none and the plain camera view without a source)."""
        if self.source is None:
            return [], plain_view(frame, depth)
        return self.source(frame, depth, stopwatch)


__all__ = ["GOAL_RULES", "FrontierSource", "ImageSource", "MapSource", "Method", "widened_min_cells"]

"""MapEx, ``--method mapex``: map frontiers scored by the ensemble variance of a predicted map over
what each would see (Ho, Kim et al., "MapEx: Indoor Structure Exploration with Probabilistic
Information Gain from Global Map Predictions", ICRA 2025; castacks/MapEx ``scripts/explore.py`` and
``scripts/sim_utils.py``, score mode ``visvarprob``).

Each frame (numbers: the ``mapex`` section of ``configs/explore.yaml``, with their sources):

1. **Prediction.** The ``mapex`` ensemble predicts the top-down map at the camera's height
   (:meth:`~frontiernet.mapprediction.MapPredictor.predict_topdown_states`: the mean occupancy over
   the members and their variance; MapEx's ``mean_map`` and ``var_map = torch.var`` over its LaMa
   ensemble), as a prediction of the whole map would, but only around the cells mapped since the last
   prediction (:class:`~.predicted.TopdownPrediction`): cells farther than ``visibility_range_m`` from a
   known cell are never read. Cells the map now knows keep their state (mean 0 or 1, variance 0).
2. **Frontiers** (``FrontierPlanner.get_frontier_centers_given_obs_map``): free cells beside unknown
   ones, 8-connected regions of at least ``min_cells`` cells (``region_size_threshold`` 10: more than
   10), each represented by its cell nearest the region's mean (:mod:`~frontiernet.frontiers.map_frontiers`).
3. **Visibility** (``get_vis_mask``, ``raycast_mode='probabilistic'``, ``hit_prob_threshold=0.8``):
   ``num_rays`` rays around the frontier cell, up to ``visibility_range_m``, through the *mean
   predicted* map; a ray stops at the first cell whose mean occupancy is at least
   ``hit_probability`` (MapEx's ``get_free_points`` resets its accumulated probability at every
   cell, so its test is this per-cell one), which is not seen.
4. **Score** (``get_frontier_val``, ``visvarprob``): the sum of the variance over the visible cells
   that are still unknown in the robot's map, divided by the distance to the frontier.

How it fits the shared loop: the frontiers are proposed with ``fresh_frontiers`` and the
variance sum as their gain, ranked by the planner's ``rate`` rule (gain / route length; MapEx divides
by the straight-line distance). A frame's gains get one common factor so that the smallest reaches
``tracking.min_gain_m3`` (the tracker drops a proposal below it; MapEx never drops a frontier for its
score), and each gets ``value_floor`` first, so that frontiers with no variance in sight rank by
distance. A common factor leaves the ranking as it is.

Cost per step: one ray cast of ``num_rays`` x (range / half a cell) samples per frontier (NumPy), and a
prediction of the box the robot has mapped since the last one, grown by the rays' range and the
network's reach (three 127k-parameter UNets), only when the map's band has learnt
``repredict_new_cells`` cells since the last one (MapEx predicts once per goal choice); in between the
cached mean and variance are read with the current map's known cells.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from omegaconf import OmegaConf

from ..errors import InputError, positive_number
from ..frontiers.map_frontiers import map_frontiers
from ..mapprediction import map_topdown_states
from .perception import plain_view
from .predicted import check_predictor, open_predictor, topdown_prediction
from .sources import FrontierSource, Method, widened_min_cells


def visible_cells(mean: np.ndarray, start: np.ndarray, num_rays: int, range_cells: float,
                  hit_probability: float, angles: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The cells `num_rays` rays from cell `start` ((2,) int) see in the (X, Y) occupancy probability
    `mean`, each up to `range_cells` cells, stopping before the first cell of probability >=
    `hit_probability` or off the map (MapEx's ``get_free_points`` with ``use_prob``), as a pair of
    (K,) int64 index arrays, each cell once (``array[seen]`` reads them; the cost is the rays', not the
    map's). `angles`: the rays' directions ((R,) radians in the map's x-y frame; None: `num_rays`
    spread evenly around)."""
    if angles is None:
        angles = np.linspace(0.0, 2 * np.pi, int(num_rays), endpoint=False)
    steps = np.arange(0.0, float(range_cells) + 1e-9, 0.5)  # half a cell: no cell of a ray is skipped
    points = np.asarray(start, np.float64) + 0.5 + steps[None, :, None] \
        * np.stack([np.cos(angles), np.sin(angles)], axis=1)[:, None, :]
    cells = np.floor(points).astype(np.int64)
    inside = np.all((cells >= 0) & (cells < np.asarray(mean.shape)), axis=2)
    clipped = np.clip(cells, 0, np.asarray(mean.shape) - 1)
    stop = ~inside | (mean[clipped[..., 0], clipped[..., 1]] >= hit_probability)
    stop[:, 0] = ~inside[:, 0]  # the frontier cell itself is free (the robot stands there)
    first = np.where(stop.any(axis=1), np.argmax(stop, axis=1), stop.shape[1])
    seen = np.arange(stop.shape[1])[None, :] < first[:, None]
    flat = np.unique(np.ravel_multi_index((clipped[seen][:, 0], clipped[seen][:, 1]), mean.shape))
    return np.unravel_index(flat, mean.shape)


class MapexSource(FrontierSource):
    """MapEx's frontiers and scores (see the module docstring); prediction timed as ``perception``,
    the rest as ``anchoring``.

    Args:
        predictor: a loaded ``mapex`` :class:`~frontiernet.mapprediction.MapPredictor`.
        occupancy: the run's map. conf: the run config (``mapex``, ``map_frontiers``, ``planner``,
            ``tracking``).
    """

    def __init__(self, predictor, occupancy, conf) -> None:
        if occupancy is None:
            raise InputError("mapex needs the run's map (a MethodContext with voxels)")
        s = conf.mapex
        self.predictor, self.map, self.conf = predictor, occupancy, conf
        self.topdown = topdown_prediction(conf, predictor, occupancy.voxel_size)
        self.range_cells = self.topdown.range_cells
        self.num_rays = int(positive_number(s.get("num_rays"), "mapex.num_rays"))
        self.hit = positive_number(s.get("hit_probability"), "mapex.hit_probability")
        self.floor = positive_number(s.get("value_floor"), "mapex.value_floor")
        self.min_gain = float(conf.tracking.min_gain_m3)
        self._values: dict[tuple[int, int], float] = {}  # frontier cell -> value, kept until the maps change near it
        self._values_from = None  # the (mean, variance) they were computed on
        # MapEx's frontier regions: its size threshold, no cutting of long regions
        self.frontier_conf = OmegaConf.merge(conf, {"map_frontiers": {
            "min_cells": int(positive_number(s.get("min_cells"), "mapex.min_cells")),
            "max_extent_m": positive_number(s.get("max_extent_m"), "mapex.max_extent_m", "metres")}})

    def __call__(self, frame, depth, stopwatch):
        T = frame.T_world_cam
        z = float(T[2, 3])
        states = map_topdown_states(self.map, z, self.predictor.spec.band_m)
        with stopwatch("perception"):
            mean, variance = self.prediction(states)
        with stopwatch("anchoring"):
            observations = map_frontiers(self.map, z, self.frontier_conf, T, "uniform")
            observations = self.scored(observations, mean, variance)
        return observations, plain_view(frame, depth)

    def widen(self) -> bool:
        """Once a run would stop: MapEx's regions down to ``map_frontiers.min_cells_before_stop`` cells from
        then on (:func:`~.sources.widened_min_cells`; once: the next stop is the run's end)."""
        smallest = widened_min_cells(self.conf, self.frontier_conf.map_frontiers.min_cells)
        if smallest is None:
            return False
        self.frontier_conf = OmegaConf.merge(self.frontier_conf, {"map_frontiers": {"min_cells": smallest}})
        return True

    def prediction(self, states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(mean, variance) (X, Y) of the map with top-down `states` (:class:`~.predicted.TopdownPrediction`)."""
        return self.topdown(states)

    def values(self, positions: np.ndarray, mean: np.ndarray, variance: np.ndarray) -> np.ndarray:
        """(F,) MapEx's frontier value before the distance: the variance summed over the unknown cells
        visible from each of the (F, 2) world xy `positions` in the mean map. A cell's value is kept
        while `mean` and `variance` stay the same within the rays' range of it (:meth:`_forget_values`):
        a frame changes them near the robot, so most frontiers cast no ray."""
        cells = np.floor((positions - np.asarray(self.map.origin[:2])) / float(self.map.voxel_size)).astype(np.int64)
        self._forget_values(mean, variance)
        out = np.zeros(len(positions))
        for index, cell in enumerate(cells):
            key = (int(cell[0]), int(cell[1]))
            if key not in self._values:
                seen = visible_cells(mean, cell, self.num_rays, self.range_cells, self.hit)
                self._values[key] = float(variance[seen].sum())  # the variance is 0 where the map knows the cell
            out[index] = self._values[key]
        self._values = {(int(i), int(j)): self._values[(int(i), int(j))] for i, j in cells}  # this frame's
        return out

    def _forget_values(self, mean: np.ndarray, variance: np.ndarray) -> None:
        """Drop the kept values of cells within the rays' range of a cell whose mean or variance differs
        from the last call's (all of them when the map's shape changed)."""
        last = self._values_from
        self._values_from = (mean.copy(), variance.copy())
        if last is None or last[0].shape != mean.shape:
            self._values = {}
            return
        changed = (mean != last[0]) | (variance != last[1])
        if not changed.any() or not self._values:
            return
        rows, cols = np.flatnonzero(changed.any(axis=1)), np.flatnonzero(changed.any(axis=0))
        reach = int(np.ceil(self.range_cells)) + 1
        self._values = {(i, j): value for (i, j), value in self._values.items()
                        if not (rows[0] - reach <= i <= rows[-1] + reach and cols[0] - reach <= j <= cols[-1] + reach)}

    def scored(self, observations: list, mean: np.ndarray, variance: np.ndarray) -> list:
        """`observations` with their gain set to MapEx's value (see the module docstring)."""
        if not observations:
            return []
        values = self.values(np.array([o.position[:2] for o in observations]), mean, variance) + self.floor
        values *= max(1.0, self.min_gain / values.min())
        return [replace(o, gain_m3=float(value)) for o, value in zip(observations, values)]


def make_mapex(context) -> Method:
    """The ``mapex`` method (:data:`~frontiernet.exploration.methods.METHODS`): map frontiers by the
    visible predicted variance per metre, goal rule ``rate``; its predictor is ``--model`` or
    ``mapex.predictor``."""
    predictor = open_predictor(context.conf, "mapex", context.model)
    return Method("mapex", MapexSource(predictor, context.map, context.conf), "rate", fresh_frontiers=True,
                  map_regions=True, uses_model=True)


make_mapex.uses_model = True  # --model names its predictor file (methods.uses_model)
make_mapex.model_kind = "mapex predictor"  # not a FrontierNet model: bench --model is not for it
make_mapex.topdown_prediction = True  # its source's `topdown`, which explore --show-prediction alone draws
make_mapex.check = check_predictor("mapex")  # before the scene loads (methods.check_method)
make_mapex.needs_map = "scores the map's frontiers by predicted maps"  # no --map-free (methods.check_method)

__all__ = ["MapexSource", "make_mapex", "visible_cells"]

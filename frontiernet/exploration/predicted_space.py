"""``--method frontiernet-mapex``: FrontierNet's frontiers, each gain also counting the unseen space a map
predictor expects behind it (issue 56 item 5; no reference implementation: ours).

FrontierNet's gain is what the image shows of the space behind a frontier; a map predictor (MapEx's
ensemble, :mod:`.mapex`) completes the top-down map from the whole map's structure, so it can see a room
the image only hints at (a door at the end of a corridor). Each frame (numbers: ``frontiernet_mapex``
and ``mapex`` of ``configs/explore.yaml``):

1. The frame's frontiers as ``frontiernet`` has them (the model on the image, anchored: gain ``g_model``).
2. The ``mapex`` predictor's mean map (:class:`~.predicted.TopdownPrediction`, predicted anew as
   ``mapex`` does).
3. For each frontier, the cells visible from its cell in the mean predicted map (rays stop at mean
   occupancy >= ``mapex.hit_probability``, out to ``mapex.visibility_range_m``) within the camera's
   horizontal field of view around the frontier's direction, that the robot's map does not know yet;
   ``g_pred`` = the sum of their predicted free probability (1 - mean) x the cell's area x
   ``frontiernet_mapex.column_height_m`` (the volume above a free cell that a view would add).
4. The gain becomes ``(1 - w) g_model + w g_pred``, ``w = frontiernet_mapex.weight``: two estimates of
   the same unseen volume, one from the image and one from the map. ``w = 0`` is ``frontiernet``.

Goals by the same rule as ``frontiernet`` (gain^e / distance, paper Eq. 8).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import InputError, positive_number
from ..mapping.occupancy import UNKNOWN
from ..mapprediction import map_topdown_states
from .mapex import visible_cells
from .predicted import open_predictor, topdown_prediction
from .sources import FrontierSource


class PredictedSpaceGain(FrontierSource):
    """Wraps a frontier source: its observations' gains blended with the predicted unseen volume behind
    them (see the module docstring); the prediction timed as ``perception``, the rays as ``anchoring``.

    Args:
        source: the frontier source whose gains are blended (FrontierNet's :class:`~.sources.ImageSource`).
        prediction: a :class:`~.predicted.TopdownPrediction` of a ``mapex`` predictor.
        occupancy: the run's map. conf: the run config (``frontiernet_mapex``, ``mapex``).
        hfov_rad: the camera's horizontal field of view, radians (the rays fan over it).
    """

    def __init__(self, source, prediction, occupancy, conf, hfov_rad: float) -> None:
        if occupancy is None:
            raise InputError("frontiernet-mapex needs the run's map (a MethodContext with voxels)")
        s = conf.frontiernet_mapex
        self.source, self.topdown, self.map = source, prediction, occupancy
        self.weight = float(s.weight)
        if not 0.0 <= self.weight <= 1.0:
            raise InputError(f"frontiernet_mapex.weight must be in [0, 1], got {s.weight}")
        self.column_m = positive_number(s.get("column_height_m"), "frontiernet_mapex.column_height_m", "metres")
        self.num_rays = int(positive_number(conf.mapex.get("num_rays"), "mapex.num_rays"))
        self.hit = positive_number(conf.mapex.get("hit_probability"), "mapex.hit_probability")
        self.hfov = float(hfov_rad)

    def __call__(self, frame, depth, stopwatch):
        observations, seen = self.source(frame, depth, stopwatch)
        if not observations or self.weight == 0.0:
            return observations, seen
        states = map_topdown_states(self.map, float(frame.T_world_cam[2, 3]), self.topdown.predictor.spec.band_m)
        with stopwatch("perception"):
            mean, _ = self.topdown(states)
        with stopwatch("anchoring"):
            predicted = self.predicted_volume(np.array([o.position[:2] for o in observations]),
                                              np.array([o.direction[:2] for o in observations]), mean, states)
        w = self.weight
        return [replace(o, gain_m3=float((1.0 - w) * o.gain_m3 + w * g)) for o, g in zip(observations, predicted)], seen

    def predicted_volume(self, positions: np.ndarray, directions: np.ndarray, mean: np.ndarray,
                         states: np.ndarray) -> np.ndarray:
        """(F,) m^3: the predicted free unseen volume in view of (F, 2) world `positions` looking along
        (F, 2) `directions`, in the (X, Y) `mean` predicted map whose (X, Y) int8 `states` are the robot's."""
        cell = float(self.map.voxel_size)
        cells = np.floor((positions - np.asarray(self.map.origin[:2])) / cell).astype(np.int64)
        unknown_free = np.where(states == UNKNOWN, 1.0 - mean, 0.0)
        rays = max(2, int(round(self.num_rays * self.hfov / (2 * np.pi))))  # the same angular density
        out = np.zeros(len(positions))
        for index, (start, (dx, dy)) in enumerate(zip(cells, directions)):
            yaw = np.arctan2(dy, dx)
            angles = yaw + np.linspace(-self.hfov / 2, self.hfov / 2, rays)
            seen = visible_cells(mean, start, rays, self.topdown.range_cells, self.hit, angles)
            out[index] = float(unknown_free[seen].sum()) * cell * cell * self.column_m
        return out


def predicted_space_gain(source, context) -> PredictedSpaceGain:
    """`source` (FrontierNet's frontiers) with the predicted space of the run's ``mapex.predictor``
    (null: the shipped one) blended into its gains, for the run of `context`."""
    conf, camera = context.conf, context.sim_conf.camera
    hfov = 2.0 * np.arctan(float(camera.width) / 2.0 / float(camera.focal_px))
    prediction = topdown_prediction(conf, open_predictor(conf, "mapex"), context.map.voxel_size)
    return PredictedSpaceGain(source, prediction, context.map, conf, hfov)


__all__ = ["PredictedSpaceGain", "predicted_space_gain"]

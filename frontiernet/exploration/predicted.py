"""The map predictor a ``seer`` or ``mapex`` run uses (docs/mapprediction.md, "Exploring with the
predictors"): which file, loaded and checked before any scene work.

The file is ``--model FILE`` when given, else the config key ``seer.predictor`` / ``mapex.predictor``
of ``configs/explore.yaml`` (null: the shipped ``frontiernet/weights/mappredictor_<kind>.safetensors``,
:data:`~frontiernet.mapprediction.predictor.SHIPPED`). A missing file, a file of another kind or
architecture, or a predictor trained on another voxel size than the run's map (``map.voxel_size``) is
an :class:`~frontiernet.errors.InputError` naming the file: one line and exit 2 from the command line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError, positive_number
from ..mapping.occupancy import FREE, OCCUPIED, UNKNOWN
from ..mapprediction import MapPredictor, load_predictor


def predictor_file(conf, kind: str, model=None) -> Path | None:
    """The predictor file of a `kind` run: `model` (``--model``), else ``<kind>.predictor`` of the run
    config `conf`; None: the shipped one."""
    if model is not None:
        return Path(model)
    section = conf.get(kind) if hasattr(conf, "get") else None
    if section is None or "predictor" not in section:
        raise InputError(f"{kind}.predictor is missing from the explore config")
    value = section.get("predictor")
    return None if value in (None, "") else Path(str(value))


def open_predictor(conf, kind: str, model=None) -> MapPredictor:
    """The loaded predictor of a `kind` run (:func:`predictor_file`), checked against the run's map.

    Raises:
        InputError naming the file: missing, not a predictor, of another kind or architecture
            (:func:`~frontiernet.mapprediction.load_predictor`), or trained on other voxels than
            ``map.voxel_size``.
    """
    predictor = load_predictor(predictor_file(conf, kind, model), kind)
    voxel = float(conf.map.voxel_size)
    if not np.isclose(predictor.spec.voxel_size, voxel, rtol=1e-6, atol=0.0):
        raise InputError(f"{predictor.path}: a predictor of {predictor.spec.voxel_size} m voxels, but the run's map "
                         f"has {voxel} m (map.voxel_size)")
    return predictor


class TopdownPrediction:
    """A ``mapex`` predictor's mean and variance of a map's top-down cells, predicted anew only once the map
    knows `repredict_new_cells` more cells than at the last prediction (MapEx predicts once per goal
    choice), and then only where it can change: around the cells whose state changed since the last
    prediction, within the network's receptive field (``receptive_radius``) and the rays' range
    `range_cells` (cells within range of a known cell are read; farther ones keep 0.5 and no variance).
    The predicted window and its context are aligned to the network's ``multiple`` on the map's grid, so
    a cell's prediction is the one a prediction of the whole map would give it: the cost of a prediction
    is that of the box the robot has just mapped, not of the map. In between, the cached prediction is
    read with the cells the map now knows (mean 0 free, 1 occupied; variance 0). ``--method mapex``
    scores its frontiers with it; ``explore --show-prediction`` draws it.

    Args:
        predictor: a loaded ``mapex`` :class:`~frontiernet.mapprediction.MapPredictor` (or anything with
            ``predict_topdown_states(states, voxel_size)``, and optionally ``receptive_radius`` and
            ``multiple``: 0 and 1 without them); cell_m: the map's voxel size, metres.
    Attributes:
        predictions: how many predictions were made.
    """

    def __init__(self, predictor, cell_m: float, range_cells: float, repredict_new_cells: int) -> None:
        self.predictor, self.cell_m = predictor, float(cell_m)
        self.range_cells, self.repredict = float(range_cells), int(repredict_new_cells)
        self.context = int(getattr(predictor, "receptive_radius", 0))
        self.multiple = max(1, int(getattr(predictor, "multiple", 1)))
        self.mean = self.variance = None  # (X, Y) float32, the last prediction over the whole map
        self.states = None  # (X, Y) int8, the states it was made from
        self.known_at = -1  # known cells at the last prediction
        self.predictions = 0

    def __call__(self, states: np.ndarray, predict: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """(mean, variance), (X, Y) float32, for (X, Y) int8 top-down `states`
        (:func:`~frontiernet.mapprediction.map_topdown_states`). `predict` False: never predict anew, only
        read the last prediction (none yet: 0.5 and no variance in the unknown), as a second reader of a
        method's prediction does, so that reading it changes nothing of the run."""
        known = states != UNKNOWN
        count = int(known.sum())
        stale = self.mean is None or self.mean.shape != states.shape
        if predict and (stale or count - self.known_at >= self.repredict):
            if stale:
                self.mean = np.full(states.shape, 0.5, np.float32)
                self.variance = np.zeros(states.shape, np.float32)
                self.states = np.full(states.shape, UNKNOWN, np.int8)
            changed = states != self.states
            if changed.any():
                self._predict(states, changed)
            self.states = states.copy()
            self.known_at, self.predictions, stale = count, self.predictions + 1, False
        # a reader before any prediction: 0.5 and no variance, nothing stored (the owner's next call predicts)
        last_mean, last_variance = (0.5, 0.0) if stale else (self.mean, self.variance)
        mean = np.where(states == FREE, 0.0, np.where(states == OCCUPIED, 1.0, last_mean)).astype(np.float32)
        return mean, np.where(known, 0.0, last_variance).astype(np.float32)

    def _predict(self, states: np.ndarray, changed: np.ndarray) -> None:
        """Predict the cells that the (X, Y) bool `changed` cells can change or bring into range: the box
        of them grown by the rays' range and the receptive field, from that box grown by the field again
        (its context), both aligned to the network's multiple."""
        rows, cols = np.flatnonzero(changed.any(axis=1)), np.flatnonzero(changed.any(axis=0))
        lo, hi = np.array([rows[0], cols[0]]), np.array([rows[-1], cols[-1]]) + 1
        grow = max(int(np.ceil(self.range_cells)) + 1, self.context)
        window = self._aligned(lo - grow, hi + grow, states.shape)
        context = self._aligned(window[0] - self.context, window[1] + self.context, states.shape)
        region = tuple(slice(a, b) for a, b in zip(*context))
        mean, variance = self.predictor.predict_topdown_states(states[region], self.cell_m)
        inner = tuple(slice(a - c, b - c) for a, b, c in zip(*window, context[0]))
        target = tuple(slice(a, b) for a, b in zip(*window))
        self.mean[target], self.variance[target] = mean[inner], variance[inner]

    def _aligned(self, lo: np.ndarray, hi: np.ndarray, shape) -> tuple[np.ndarray, np.ndarray]:
        """The index box [lo, hi) grown to multiples of :attr:`multiple` and clipped to the map `shape`."""
        m = self.multiple
        return np.maximum(lo // m * m, 0), np.minimum(-(-hi // m) * m, np.asarray(shape))


def topdown_prediction(conf, predictor, cell_m: float) -> TopdownPrediction:
    """The :class:`TopdownPrediction` of a run with config `conf` (``mapex.visibility_range_m``,
    ``mapex.repredict_new_cells``), a loaded ``mapex`` `predictor` and the run's map of `cell_m` voxels."""
    s, cell = conf.mapex, float(cell_m)
    range_cells = positive_number(s.get("visibility_range_m"), "mapex.visibility_range_m", "metres") / cell
    repredict = int(positive_number(s.get("repredict_new_cells"), "mapex.repredict_new_cells"))
    return TopdownPrediction(predictor, cell, range_cells, repredict)


def check_predictor(kind: str, model_is_predictor: bool = True):
    """``check(conf, model)``: what :func:`~frontiernet.exploration.methods.check_method` runs before a
    `kind` run's setup (loads the predictor once and drops it; a few milliseconds). `model_is_predictor`
    False: ``--model`` is another file (``frontiernet-mapex``'s FrontierNet model), so the predictor is
    the config key's (``<kind>.predictor``)."""
    def check(conf, model=None) -> None:
        open_predictor(conf, kind, model if model_is_predictor else None)
    return check


__all__ = ["TopdownPrediction", "check_predictor", "open_predictor", "predictor_file", "topdown_prediction"]

"""Predicting the unseen map: SEER's 3D crops and MapEx's top-down ensemble (docs/mapprediction.md).

:mod:`.encodings` turns an :class:`~frontiernet.mapping.OccupancyMap` (and the scene's true voxels)
into what the networks of :mod:`.networks` read and learn; :mod:`.predictor` loads a predictor file and
predicts (:meth:`MapPredictor.predict_crop`, :meth:`MapPredictor.predict_topdown`); :mod:`.quality`
says where a prediction is scored, the two simple predictions it must beat and the scores. The data
(``frontiernet mapgen``), training (``frontiernet train --config configs/train_seer.yaml``) and
evaluation (``frontiernet mapeval``) are in ``datagen`` and ``train``.
"""

from .encodings import (IGNORE, LABEL_FREE, LABEL_OCCUPIED, band_layers, crop_corner, crop_input, crop_states,
                        map_states, map_topdown_states, states_from_masks, take_crop, topdown_input, topdown_labels,
                        topdown_probability, topdown_states, truth_labels)
from .networks import KINDS, Ensemble, NetworkSettings, PredictorSpec, parameter_count
from .predictor import CropPrediction, MapPredictor, load_predictor, save_predictor, shipped_predictor_path
from .quality import confusion, near_frontier, predict_free, predict_wall, scores

__all__ = [
    "IGNORE", "KINDS", "LABEL_FREE", "LABEL_OCCUPIED", "CropPrediction", "Ensemble", "MapPredictor", "NetworkSettings",
    "PredictorSpec", "band_layers", "confusion", "crop_corner", "crop_input", "crop_states", "load_predictor",
    "map_states", "map_topdown_states", "near_frontier", "parameter_count", "predict_free", "predict_wall",
    "save_predictor", "scores", "shipped_predictor_path", "states_from_masks", "take_crop", "topdown_input",
    "topdown_labels", "topdown_probability", "topdown_states", "truth_labels",
]

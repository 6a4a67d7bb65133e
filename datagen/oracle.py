"""The oracle perception: ground-truth frontiers in place of the network.

``frontiernet explore --method oracle`` (registered under the ``frontiernet.perception``
entry point group). Each frame's frontier mask and gain classes are the ground truth of
:class:`~datagen.ground_truth.GroundTruthGenerator` for that view (the labels the network
is trained on), so the run shows what the rest of the pipeline (anchoring, bookkeeping,
planning) achieves with perfect single-view perception: an upper bound for the model.
"""

from __future__ import annotations

import numpy as np

from frontiernet.exploration.perception import Perception, PerceptionResult

from .config import load_datagen_config
from .ground_truth import GroundTruthGenerator


class OraclePerception(Perception):
    """Ground-truth perception for one scene.

    Args:
        scene, voxels: the scene and its voxel grid (the explorer's).
        sim_conf: the sim config the explorer uses (its camera replaces datagen's).
        seed: seed of the gain sampling (ground truth measures gain at a random subset of
            frontier voxels).
    """

    name = "oracle"

    def __init__(self, scene, voxels, sim_conf=None, seed: int = 0) -> None:
        conf = load_datagen_config()
        if sim_conf is not None:
            conf.camera = sim_conf.camera
        self.generator = GroundTruthGenerator(scene, voxels, conf)
        gt = conf.ground_truth
        self.labels = {"truncation_px": float(gt.truncation_px), "frontier_threshold_px": 0.5,
                       "bin_edges": list(gt.gain.bin_edges), "bin_unit_m3": float(gt.gain.bin_unit_m3),
                       "num_classes": len(gt.gain.bin_edges)}
        self.rng = np.random.default_rng(seed)

    def __call__(self, frame, depth: np.ndarray) -> PerceptionResult:
        truth = self.generator.from_frame(frame, self.rng)
        return PerceptionResult(frame.rgb, np.asarray(depth, np.float32), np.asarray(frame.K, np.float64),
                                truth.distance_field, truth.gain_class.astype(np.uint8), self.labels)

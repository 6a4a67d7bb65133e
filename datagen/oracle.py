"""The oracle perception: ground-truth frontiers in place of the network.

``frontiernet explore --method oracle`` (registered under the ``frontiernet.methods`` entry
point group, as every method: :func:`oracle`). Each frame's frontier mask and gain classes are the ground truth of
:class:`~datagen.ground_truth.GroundTruthGenerator` for that view (the labels the network
is trained on), so the run shows what the rest of the pipeline (anchoring, bookkeeping,
planning) achieves with perfect single-view perception: an upper bound for the model.

Two hybrids (also ``frontiernet.methods`` entry points) split it into "where" and "how much"
(issue 27, step 3; docs/benchmark.md, "Where the value of gain is lost"):

* ``oracle-uniform``: the ground truth's frontier pixels, one uniform gain class
  (``ablations.uniform_gain_class``, as ``df-uniform``);
* ``frontiernet-oracle-gain``: the model's frontier pixels, the ground truth's gain classes
  (:class:`~frontiernet.exploration.ablations.GainFrom`).
"""

from __future__ import annotations

import numpy as np

from frontiernet.exploration.ablations import GainFrom, uniform_gain
from frontiernet.exploration.methods import Method, MethodContext, image_method, model_perception
from frontiernet.exploration.perception import Perception, PerceptionResult

from .config import load_datagen_config
from .ground_truth import GroundTruthGenerator


class OraclePerception(Perception):
    """Ground-truth perception for one scene.

    Args:
        scene, voxels: the scene and its voxel grid (the explorer's).
        sim_conf: the sim config the explorer uses (its camera replaces datagen's).
        ground_truth: the run config's ``ground_truth`` section (datagen's, settable per run:
            ``ground_truth.gain.volume=occluded``), which replaces the shipped one. None: the
            shipped one (``configs/datagen.yaml``).
        seed: seed of the gain sampling (ground truth measures gain at a random subset of
            frontier voxels).
    """

    name = "oracle"

    def __init__(self, scene, voxels, sim_conf=None, ground_truth=None, seed: int = 0) -> None:
        conf = load_datagen_config()
        if sim_conf is not None:
            conf.camera = sim_conf.camera
        if ground_truth is not None:
            conf.ground_truth = ground_truth
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


def _oracle_perception(context: MethodContext) -> OraclePerception:
    """The ground truth of the context's scene, camera and run config (its ``ground_truth`` section;
    the shipped one for a run config without it)."""
    return OraclePerception(context.scene, context.voxels, context.sim_conf, context.conf.get("ground_truth"))


def oracle(context: MethodContext) -> Method:
    """``oracle``: ground-truth frontier pixels and gain classes (a ``frontiernet.methods`` factory)."""
    return image_method("oracle", _oracle_perception(context), context)


def oracle_uniform(context: MethodContext) -> Method:
    """``oracle-uniform``: ground-truth frontier pixels, uniform gain (a ``frontiernet.methods`` factory)."""
    return image_method("oracle-uniform", uniform_gain(_oracle_perception(context), context.conf), context)


def frontiernet_oracle_gain(context: MethodContext) -> Method:
    """``frontiernet-oracle-gain``: the model's frontier pixels (the context's model file, None =
    the shipped one), ground-truth gain classes (a ``frontiernet.methods`` factory)."""
    perception = GainFrom(model_perception(context), _oracle_perception(context))
    return image_method("frontiernet-oracle-gain", perception, context, uses_model=True)


frontiernet_oracle_gain.uses_model = True  # it runs the model file: --model applies (exploration.methods.uses_model)

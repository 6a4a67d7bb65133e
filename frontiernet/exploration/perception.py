"""Frontier perception: one camera frame -> per-pixel frontier mask and gain.

The explorer calls a :class:`Perception` with the rendered :class:`~frontiernet.simulator.camera.Frame`
and the depth the robot has (from a depth source); it returns a :class:`PerceptionResult`
at the perception's working size, which anchoring lifts to 3D frontiers.

* :class:`ModelPerception` runs a FrontierNet model (any runtime: torch, ONNX, TorchScript)
  at its inference size (320 px, the public demo's resize + centre crop, intrinsics adjusted).
* :mod:`.ablations`: the paper's Fig. 9 ablations ``df-uniform``, ``discontinuity-gain`` and
  ``discontinuity-uniform`` (uniform gain, depth-discontinuity frontiers), built in.
* Other perceptions register under the entry point group ``frontiernet.perception``
  (``name = "module:Class"``, the class built as ``Class(scene, voxels, sim_conf, conf)`` with the
  run config `conf`), e.g.
  ``datagen``'s ``oracle``: ground-truth frontiers in place of the network, the upper bound
  the issue asks to report. The library never imports those packages.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ..errors import InputError

PERCEPTION_GROUP = "frontiernet.perception"


@dataclass
class PerceptionResult:
    """Per-pixel frontier outputs of one frame at the perception's working size (h, w).

    Attributes:
        rgb: (h, w, 3) uint8, the image as the perception saw it (for overlays).
        depth: (h, w) float32 metres, NaN invalid: the depth prior at this size (for anchoring).
        K: (3, 3) float64 intrinsics at this size.
        distance_field: (h, w) float32 pixels, distance to the nearest frontier pixel (truncated at r).
        gain_class: (h, w) uint8 gain class per pixel (0 = no gain).
        labels: the label encoding (``truncation_px``, ``frontier_threshold_px``, ``bin_edges``,
            ``bin_unit_m3``, ``num_classes``), as in a model file.
    """

    rgb: np.ndarray
    depth: np.ndarray
    K: np.ndarray
    distance_field: np.ndarray
    gain_class: np.ndarray
    labels: dict


class Perception:
    """Base: ``perception(frame, depth) -> PerceptionResult``."""

    name = "perception"

    def __call__(self, frame, depth: np.ndarray) -> PerceptionResult:
        """Args: frame: the rendered Frame (rgb, K, T_world_cam, ground-truth depth);
        depth: (H, W) float32 metres, NaN invalid, the robot's depth for this frame."""
        raise NotImplementedError


class ModelPerception(Perception):
    """FrontierNet on each frame through a runtime (:class:`~frontiernet.model.Runtime`).

    Args:
        runtime: anything with ``conf``, ``labels`` and ``predict_frame`` (torch Predictor, ONNX,
            TorchScript).
        size: working size (None: the model's ``inference.size``).
    """

    name = "frontiernet"

    def __init__(self, runtime, size: int | None = None) -> None:
        self.runtime = runtime
        self.size = int(size or runtime.conf["inference"]["size"])

    def __call__(self, frame, depth: np.ndarray) -> PerceptionResult:
        result, K = self.runtime.predict_frame(frame.rgb, depth, frame.K, size=self.size)
        return PerceptionResult(result["rgb"], result["depth"], K, result["distance_field"], result["gain_class"],
                                dict(self.runtime.labels))


@functools.lru_cache(maxsize=1)
def _model_labels() -> tuple:
    from omegaconf import OmegaConf

    from ..config import load_config

    return tuple(OmegaConf.to_container(load_config("model").labels, resolve=True).items())


def model_labels() -> dict:
    """The label encoding of ``configs/model.yaml`` (``labels:``) as a plain dict (read once)."""
    return {key: list(value) if isinstance(value, list) else value for key, value in _model_labels()}


def plain_view(frame, depth: np.ndarray, size: int | None = None, labels: dict | None = None) -> PerceptionResult:
    """The frame as a :class:`PerceptionResult` without frontier pixels (D = r everywhere, gain
    class 0), for methods that do not look for frontiers in the image (the video shows the plain
    camera view) and as the base of image-free ablations.

    Args:
        frame: the rendered Frame; depth: (H, W) float32 metres, NaN invalid.
        size: working size (resize + centre crop as the model's input, intrinsics adjusted);
            None: the frame's own size.
        labels: the label encoding (None: ``configs/model.yaml``'s).
    """
    labels = dict(labels) if labels is not None else model_labels()
    if size is None:
        rgb, depth, K = frame.rgb, np.asarray(depth, np.float32), frame.K
    else:
        from ..model.inputs import resize_and_crop

        rgb, depth, K = resize_and_crop(frame.rgb, depth, frame.K, int(size))
    return PerceptionResult(rgb, depth, K, np.full(depth.shape, float(labels["truncation_px"]), np.float32),
                            np.zeros(depth.shape, np.uint8), labels)


def perception_plugins() -> dict:
    """Perception classes registered under ``frontiernet.perception``, by name."""
    from importlib.metadata import entry_points

    return {entry.name: entry for entry in entry_points(group=PERCEPTION_GROUP)}


def _model(model) -> ModelPerception:
    from ..model import open_runtime

    return ModelPerception(open_runtime(model))


def _ablations(conf):
    """``ablations:`` of the explore config `conf` (None: the shipped ``configs/explore.yaml``)."""
    from ..config import load_config

    conf = load_config("explore") if conf is None else conf
    section = conf.get("ablations") if hasattr(conf, "get") else None
    if section is None:
        raise InputError("the explore config has no 'ablations' section (configs/explore.yaml has the defaults)")
    return section


def uniform_gain(base: Perception, conf=None) -> Perception:
    """`base`'s frontier pixels with the uniform gain class of ``ablations.uniform_gain_class``
    (explore config `conf`; None: the shipped one): df-uniform's and the plugins' stand-in."""
    from .ablations import UniformGain

    return UniformGain(base, _ablations(conf).uniform_gain_class)


def _df_uniform(model, conf) -> Perception:
    return uniform_gain(_model(model), conf)


def _discontinuity(base, conf) -> Perception:
    from .ablations import DiscontinuityFrontiers, DiscontinuitySettings

    return DiscontinuityFrontiers(base, DiscontinuitySettings.from_config(_ablations(conf).discontinuity))


def _discontinuity_uniform(model, conf) -> Perception:
    return uniform_gain(_discontinuity(None, conf), conf)


#: Built-in methods: name -> ``builder(model, conf) -> Perception``. ``frontiernet`` is the paper's
#: system; the others its Fig. 9 ablations (:mod:`.ablations`); only ``discontinuity-uniform``
#: loads no model.
BUILTIN_PERCEPTIONS = {
    "frontiernet": lambda model, conf: _model(model),
    "df-uniform": _df_uniform,
    "discontinuity-gain": lambda model, conf: _discontinuity(_model(model), conf),
    "discontinuity-uniform": _discontinuity_uniform,
}


def make_perception(method: str, model=None, scene=None, voxels=None, sim_conf=None, *, conf=None) -> Perception:
    """Build the perception of an exploration method.

    Args:
        method: a name of :data:`BUILTIN_PERCEPTIONS` (``frontiernet``, ``df-uniform``,
            ``discontinuity-gain``, ``discontinuity-uniform``) or a plugin name (``oracle``).
        model: model file path or None (the shipped model) for the methods that run one.
        scene, voxels, sim_conf: what plugins are built with (and `conf`).
        conf: the explore config (``configs/explore.yaml``; its ``ablations:`` section; None:
            the shipped one).
    Raises:
        InputError: unknown method (the valid ones are listed) or a model that does not load.
    """
    if method in BUILTIN_PERCEPTIONS:
        perception = BUILTIN_PERCEPTIONS[method](model, conf)
        perception.name = method
        return perception
    plugins = perception_plugins()
    if method not in plugins:
        valid = ", ".join([*BUILTIN_PERCEPTIONS, *sorted(plugins)])
        raise InputError(f"unknown exploration method '{method}'; valid: {valid}")
    return plugins[method].load()(scene, voxels, sim_conf, conf)

"""Frontier perception, the interface: one camera frame -> per-pixel frontier mask and gain.

An image method's source (:class:`~frontiernet.exploration.methods.ImageSource`) calls a
:class:`Perception` with the rendered :class:`~frontiernet.simulator.camera.Frame` and the depth
the robot has (from a depth source); it returns a :class:`PerceptionResult` at the perception's
working size, which anchoring lifts to 3D frontiers. Each perception lives with the methods that
use it:

* :class:`~frontiernet.exploration.methods.ModelPerception` (:mod:`.methods`, with ``frontiernet``):
  a FrontierNet model (any runtime: torch, ONNX, TorchScript) at its inference size (320 px, the
  public demo's resize + centre crop, intrinsics adjusted).
* :mod:`.ablations`: the stand-ins of the paper's Fig. 9 ablations (uniform gain,
  depth-discontinuity frontiers) and the hybrids' :class:`~.ablations.GainFrom`, wrapping a base.
* ``datagen``'s :class:`~datagen.oracle.OraclePerception`: ground-truth frontiers in place of the
  network, the upper bound the issue asks to report.

A perception is part of an image method (:func:`~frontiernet.exploration.methods.image_method`);
methods, not perceptions, are what is registered and named on the command line. This module
holds what they all share: the result type, the base class and the plain camera view
(:func:`plain_view`) that methods without image frontiers show.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np


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
        gain_logits: (K, h, w) float32 gain-class logits of a network (``anchoring.gain_decoding:
            expected`` reads them), or None where the classes are known for certain (labels) or
            replaced (the ablations).
    """

    rgb: np.ndarray
    depth: np.ndarray
    K: np.ndarray
    distance_field: np.ndarray
    gain_class: np.ndarray
    labels: dict
    gain_logits: np.ndarray | None = None


class Perception:
    """Base: ``perception(frame, depth) -> PerceptionResult``."""

    name = "perception"

    def __call__(self, frame, depth: np.ndarray) -> PerceptionResult:
        """Args: frame: the rendered Frame (rgb, K, T_world_cam, ground-truth depth);
        depth: (H, W) float32 metres, NaN invalid, the robot's depth for this frame."""
        raise NotImplementedError


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
        from ..model import resize_and_crop

        rgb, depth, K = resize_and_crop(frame.rgb, depth, frame.K, int(size))
    return PerceptionResult(rgb, depth, K, np.full(depth.shape, float(labels["truncation_px"]), np.float32),
                            np.zeros(depth.shape, np.uint8), labels)


__all__ = ["Perception", "PerceptionResult", "model_labels", "plain_view"]

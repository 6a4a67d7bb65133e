"""The ``anchoring:`` section of ``configs/explore.yaml``, checked once and typed.

Paper section III-E; every value's meaning and source is commented in the YAML file.
:func:`AnchoringSettings.from_config` accepts the section as an OmegaConf ``DictConfig``
or a plain dict and raises :class:`~frontiernet.errors.InputError` naming the first bad key.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..config import ConfigSection, setting
from ..errors import InputError
from .gain import GAIN_DECODINGS

CLUSTER_GAINS = ("robust", "mean", "max")
FEATURE_NAMES = ("pixel", "direction", "depth", "gain")


def _number(value, name: str, *, minimum: float = 0.0, strict: bool = False, integer: bool = False):
    """`value` as a float (int with `integer`) that is >= `minimum` (> with `strict`)."""
    is_number = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if integer:
        is_number = is_number and float(value).is_integer()
    if not is_number or value < minimum or (strict and value == minimum):
        kind = "an integer" if integer else "a number"
        bound = f"> {minimum:g}" if strict else f">= {minimum:g}"
        raise InputError(f"{name} must be {kind} {bound}, got {value!r}")
    return int(value) if integer else float(value)


def _threshold(value, name: str) -> float | None:
    """None (the model's labels value), or a number > 0."""
    return None if value is None else _number(value, name, strict=True)


def _kernel(value, name: str) -> int:
    """An odd Sobel kernel size from 1 to 31 (OpenCV's limit)."""
    kernel = _number(value, name, minimum=1, integer=True)
    if kernel % 2 == 0 or kernel > 31:
        raise InputError(f"{name} must be odd and at most 31, got {kernel}")
    return kernel


def _choice(value, name: str, choices: tuple[str, ...]) -> str:
    if value not in choices:
        raise InputError(f"{name} must be one of {', '.join(choices)}, got {value!r}")
    return str(value)


def _flag(value, name: str) -> bool:
    if not isinstance(value, bool):
        raise InputError(f"{name} must be true or false, got {value!r}")
    return value


@dataclass(frozen=True)
class AnchoringSettings(ConfigSection):
    """Typed anchoring settings (see ``configs/explore.yaml`` ``anchoring:`` for each one).

    Attributes:
        frontier_threshold_px: l (pixels) of F = [D < l]; None: the model's labels value.
        gain_decoding: "lower_bound" | "midpoint" | "expected".
        drop_zero_gain: frontier pixels of gain 0 are dropped.
        gradient_kernel_px: odd Sobel kernel size (1 to 31, OpenCV's limit).
        sample_offset_px: foreground/background sampling distance along the gradient, pixels.
        min_depth_m: nearer frontier pixels are dropped, metres.
        forward_weight: weight of the pixel ray in the view direction.
        horizontal_directions: view directions are levelled (world z = 0).
        max_pixels: at most this many frontier pixels are clustered.
        feature_weights: weight per feature name of :data:`FEATURE_NAMES` (0 = not used).
        min_cluster_size, min_samples, cluster_selection_epsilon, allow_single_cluster:
            HDBSCAN's parameters (the ``hdbscan`` sub-section).
        cluster_gain: "robust" | "mean" | "max".
    """

    SECTION = "anchoring"

    frontier_threshold_px: float | None = setting(_threshold)
    gain_decoding: str = setting(_choice, GAIN_DECODINGS)
    drop_zero_gain: bool = setting(_flag)
    gradient_kernel_px: int = setting(_kernel)
    sample_offset_px: float = setting(_number, strict=True)
    min_depth_m: float = setting(_number)
    forward_weight: float = setting(_number)
    horizontal_directions: bool = setting(_flag)
    max_pixels: int = setting(_number, minimum=2, integer=True)
    feature_weights: dict = setting(_number, each=FEATURE_NAMES)
    min_cluster_size: int = setting(_number, key="hdbscan.min_cluster_size", minimum=2, integer=True)
    min_samples: int = setting(_number, key="hdbscan.min_samples", minimum=1, integer=True)
    cluster_selection_epsilon: float = setting(_number, key="hdbscan.cluster_selection_epsilon")
    allow_single_cluster: bool = setting(_flag, key="hdbscan.allow_single_cluster")
    cluster_gain: str = setting(_choice, CLUSTER_GAINS)

    def __post_init__(self) -> None:
        if not any(self.feature_weights.values()):
            raise InputError(f"{self.SECTION}.feature_weights must give at least one feature a weight > 0")

"""The ``anchoring:`` section of ``configs/explore.yaml``, checked once and typed.

Paper section III-E; every value's meaning and source is commented in the YAML file.
:func:`AnchoringSettings.from_config` accepts the section as an OmegaConf ``DictConfig``
or a plain dict and raises :class:`~frontiernet.errors.InputError` naming the first bad key.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..config import ConfigSection
from ..errors import InputError
from .gain import GAIN_DECODINGS

CLUSTER_GAINS = ("robust", "mean", "max")
FEATURE_NAMES = ("pixel", "direction", "depth", "gain")
_MISSING = object()


def _get(conf, key: str, prefix: str):
    value = conf.get(key, _MISSING) if hasattr(conf, "get") else _MISSING
    if value is _MISSING:
        raise InputError(f"{prefix}{key} is missing from the anchoring config")
    return value


def _number(conf, key: str, prefix: str = "anchoring.", *, minimum: float = 0.0, strict: bool = False,
            integer: bool = False):
    """conf[key] as a float (int with `integer`) that is >= `minimum` (> with `strict`)."""
    value = _get(conf, key, prefix)
    is_number = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if integer:
        is_number = is_number and float(value).is_integer()
    if not is_number or value < minimum or (strict and value == minimum):
        kind = "an integer" if integer else "a number"
        bound = f"> {minimum:g}" if strict else f">= {minimum:g}"
        raise InputError(f"{prefix}{key} must be {kind} {bound}, got {value!r}")
    return int(value) if integer else float(value)


def _choice(conf, key: str, choices: tuple[str, ...], prefix: str = "anchoring.") -> str:
    value = _get(conf, key, prefix)
    if value not in choices:
        raise InputError(f"{prefix}{key} must be one of {', '.join(choices)}, got {value!r}")
    return str(value)


def _flag(conf, key: str, prefix: str = "anchoring.") -> bool:
    value = _get(conf, key, prefix)
    if not isinstance(value, bool):
        raise InputError(f"{prefix}{key} must be true or false, got {value!r}")
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
            HDBSCAN's parameters.
        cluster_gain: "robust" | "mean" | "max".
    """

    frontier_threshold_px: float | None
    gain_decoding: str
    drop_zero_gain: bool
    gradient_kernel_px: int
    sample_offset_px: float
    min_depth_m: float
    forward_weight: float
    horizontal_directions: bool
    max_pixels: int
    feature_weights: dict
    min_cluster_size: int
    min_samples: int
    cluster_selection_epsilon: float
    allow_single_cluster: bool
    cluster_gain: str

    SECTION = "anchoring"

    @classmethod
    def from_section(cls, conf) -> AnchoringSettings:
        """Check and type the ``anchoring`` section (a DictConfig or dict)."""
        threshold = _get(conf, "frontier_threshold_px", "anchoring.")
        kernel = _number(conf, "gradient_kernel_px", minimum=1, integer=True)
        if kernel % 2 == 0 or kernel > 31:
            raise InputError(f"anchoring.gradient_kernel_px must be odd and at most 31, got {kernel}")
        weights_conf, hdb = _get(conf, "feature_weights", "anchoring."), _get(conf, "hdbscan", "anchoring.")
        weights = {name: _number(weights_conf, name, "anchoring.feature_weights.") for name in FEATURE_NAMES}
        if not any(weights.values()):
            raise InputError("anchoring.feature_weights must give at least one feature a weight > 0")
        return cls(
            frontier_threshold_px=None if threshold is None else
            _number(conf, "frontier_threshold_px", strict=True),
            gain_decoding=_choice(conf, "gain_decoding", GAIN_DECODINGS),
            drop_zero_gain=_flag(conf, "drop_zero_gain"),
            gradient_kernel_px=kernel,
            sample_offset_px=_number(conf, "sample_offset_px", strict=True),
            min_depth_m=_number(conf, "min_depth_m"),
            forward_weight=_number(conf, "forward_weight"),
            horizontal_directions=_flag(conf, "horizontal_directions"),
            max_pixels=_number(conf, "max_pixels", minimum=2, integer=True),
            feature_weights=weights,
            min_cluster_size=_number(hdb, "min_cluster_size", "anchoring.hdbscan.", minimum=2, integer=True),
            min_samples=_number(hdb, "min_samples", "anchoring.hdbscan.", minimum=1, integer=True),
            cluster_selection_epsilon=_number(hdb, "cluster_selection_epsilon", "anchoring.hdbscan."),
            allow_single_cluster=_flag(hdb, "allow_single_cluster", "anchoring.hdbscan."),
            cluster_gain=_choice(conf, "cluster_gain", CLUSTER_GAINS),
        )

"""The perceptions of the paper's Fig. 9 ablation (FrontierNet, RA-L 2025, Sec. IV, Fig. 9).

Each replaces one half of FrontierNet's output, the frontier pixels (learned distance field D)
or the gain classes, by an uninformed stand-in; anchoring, bookkeeping and planning are the
same as for ``frontiernet`` (the methods of :data:`~frontiernet.exploration.methods.METHODS`):

=======================  ===========================================  ======================
method                   frontier pixels                              gain classes
=======================  ===========================================  ======================
df-uniform               the model's D < l                            uniform (one class)
discontinuity-gain       F_d of the robot's depth (D = 0 on F_d)      the model's
discontinuity-uniform    F_d of the robot's depth                     uniform (no model)
=======================  ===========================================  ======================

The attribution hybrids (issue 27, step 3) put the oracle's ground truth (``datagen``'s
:class:`~datagen.oracle.OraclePerception`) in one half; they are registered by ``datagen``
(``frontiernet.methods``), since the library never imports it:

=======================  ===========================================  ======================
method                   frontier pixels                              gain classes
=======================  ===========================================  ======================
oracle-uniform           the ground truth's D < l                     uniform (one class)
frontiernet-oracle-gain  the model's D < l                            the ground truth's
                                                                      (:class:`GainFrom`)
=======================  ===========================================  ======================

With a uniform gain the planner's utility gain / distance (paper Eq. 8) ranks frontiers by
distance alone. F_d is datagen's depth-discontinuity mask (:mod:`frontiernet.frontiers.discontinuity`),
the image edges the ground truth's F = F_p & F_d starts from, without the learned selection.
Settings: ``ablations:`` of ``configs/explore.yaml``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError
from ..frontiers.discontinuity import discontinuity_mask, distance_field
from .perception import Perception, PerceptionResult, model_labels, plain_view

#: l given to anchoring with F_d frontiers: D is exactly 0 on F_d and >= 1 px elsewhere, so any
#: l in (0, 1] selects F_d exactly, whatever threshold the model's labels carry for its learned D.
DISCONTINUITY_THRESHOLD_PX = 0.5


def model_size() -> int:
    """The model's working size in pixels (``configs/model.yaml`` ``inference.size``, 320)."""
    from ..config import load_config

    return int(load_config("model").inference.size)


class UniformGain(Perception):
    """The base perception's frontier pixels with one gain class on every pixel.

    Args:
        base: the perception whose distance field (and rgb, depth, K, labels) is kept.
        gain_class: the class every pixel gets, in [1, K - 1] (0 = no gain would drop every
            frontier); checked against the base's labels on the first frame.
    """

    name = "uniform-gain"

    def __init__(self, base: Perception, gain_class: int) -> None:
        if isinstance(gain_class, bool) or not float(gain_class).is_integer() or int(gain_class) < 1:
            raise InputError(f"ablations.uniform_gain_class must be an integer gain class >= 1, got {gain_class!r}")
        self.base, self.gain_class = base, int(gain_class)
        # the model's (or the discontinuities' own) labels, known before the first frame: checked now
        labels = getattr(getattr(base, "runtime", None), "labels", None) or getattr(base, "labels", None)
        if labels is not None:
            self._check(labels)

    def _check(self, labels) -> None:
        classes = len(labels["bin_edges"])
        if self.gain_class >= classes:
            raise InputError(f"ablations.uniform_gain_class {self.gain_class} is not a gain class of this model "
                             f"(0 to {classes - 1})")

    def __call__(self, frame, depth: np.ndarray) -> PerceptionResult:
        seen = self.base(frame, depth)
        self._check(seen.labels)
        # (h, w) of the base's dtype (uint8), the same class everywhere
        uniform = np.full(seen.gain_class.shape, self.gain_class, seen.gain_class.dtype)
        return replace(seen, gain_class=uniform, gain_logits=None)


class GainFrom(Perception):
    """The base perception's frontier pixels with another perception's gain classes.

    The gain source's class image is brought to the base's working size the way the model's
    input is (:func:`~frontiernet.model.predictor.resize_and_crop`: short side to the size, centre
    crop, nearest neighbour) when its shape differs, e.g. the oracle's 480 px labels under the
    model's 320 px field. The labels keep the base's distance-field encoding (``truncation_px``,
    ``frontier_threshold_px``) and take the gain source's class encoding (``bin_edges``,
    ``bin_unit_m3``, ``num_classes``), so the classes decode as their source meant them.

    Args:
        base: the perception whose distance field (and rgb, depth, K) is kept.
        gain_source: the perception whose gain classes replace the base's.
    """

    name = "gain-from"
    GAIN_LABELS = ("bin_edges", "bin_unit_m3", "num_classes")

    def __init__(self, base: Perception, gain_source: Perception) -> None:
        self.base, self.gain_source = base, gain_source

    def __call__(self, frame, depth: np.ndarray) -> PerceptionResult:
        seen, gain = self.base(frame, depth), self.gain_source(frame, depth)
        classes, logits = gain.gain_class, gain.gain_logits  # (h', w') uint8, (K, h', w') or None
        if classes.shape != seen.gain_class.shape:
            logits = None  # not resampled: ``gain_decoding: expected`` decodes these classes to midpoints
            from ..model import resize_and_crop

            height, width = seen.gain_class.shape
            if height != width:
                raise ValueError(f"GainFrom resamples gain classes to a square working size only, got {height} x {width}")
            _, resized, _ = resize_and_crop(None, classes.astype(np.float32), None, height)
            classes = resized.astype(seen.gain_class.dtype)
        labels = {**seen.labels, **{key: gain.labels[key] for key in self.GAIN_LABELS if key in gain.labels}}
        return replace(seen, gain_class=np.ascontiguousarray(classes, seen.gain_class.dtype), labels=labels,
                       gain_logits=logits)


@dataclass(frozen=True)
class DiscontinuitySettings:
    """F_d parameters (:func:`~frontiernet.frontiers.discontinuity.discontinuity_mask`):
    ``ablations.discontinuity`` of ``configs/explore.yaml`` (:meth:`from_config`).

    Datagen's ``ground_truth.discontinuity`` (``configs/datagen.yaml``). ``window_px`` is in
    pixels of an image ``source_size_px`` wide (datagen's renders: configs/sim.yaml camera, 480
    px) and is scaled to the working size (:meth:`window_at`); ``relative_jump`` (a fraction of
    the nearer depth) and ``min_jump_m`` (metres) do not depend on the resolution.
    """

    window_px: int
    source_size_px: int
    relative_jump: float
    min_jump_m: float
    invalid_is_far: bool

    def __post_init__(self) -> None:
        if not (self.window_px >= 2 and self.source_size_px >= 1 and self.relative_jump >= 0
                and self.min_jump_m >= 0):
            raise InputError(f"ablations.discontinuity needs window_px >= 2, source_size_px >= 1 and "
                             f"relative_jump, min_jump_m >= 0, got {self}")

    @classmethod
    def from_config(cls, section) -> DiscontinuitySettings:
        """From ``ablations.discontinuity`` of ``configs/explore.yaml``."""
        try:
            return cls(int(section.window_px), int(section.source_size_px), float(section.relative_jump),
                       float(section.min_jump_m), bool(section.invalid_is_far))
        except (AttributeError, KeyError, TypeError, ValueError) as error:
            raise InputError(f"ablations.discontinuity is incomplete or malformed ({error})") from None

    def window_at(self, size_px: int) -> int:
        """Window in pixels of a `size_px` image: ``round(window_px * size_px / source_size_px)``,
        at least 2 (the smallest window that can see a jump). 3 px at 480 -> 2 px at 320: a 2 x 2
        window (scipy's even filters span offsets -1 and 0) marks one pixel per jump, the one after
        it along u or v, where datagen's 3 px window marks both sides."""
        return max(2, round(self.window_px * size_px / self.source_size_px))


class DiscontinuityFrontiers(Perception):
    """Frontier pixels = F_d of the robot's depth at the working size: ``D = distance_field(F_d, r)``.

    F_d is computed on the :class:`PerceptionResult`'s depth, i.e. the depth the robot has,
    resized (nearest) and cropped to the working size; NaN (invalid: no return within the
    sensor's range) counts as farther than every valid depth when ``invalid_is_far`` (datagen's
    choice), so the end of the sensor's range is an edge. The labels' ``frontier_threshold_px``
    becomes :data:`DISCONTINUITY_THRESHOLD_PX` (``anchoring.frontier_threshold_px``, when set,
    still wins).

    Args:
        base: a perception whose gain classes (and rgb, depth, K, labels) are kept, e.g. the
            model; None: no model, the frame is resized and cropped here and the gain class
            is 0 (no gain) everywhere: wrap it in :class:`UniformGain`.
        settings: the F_d parameters (the run's ``ablations.discontinuity``).
        size: working size without a base (None: the model's ``inference.size``, 320 px).
        labels: label encoding without a base (None: ``configs/model.yaml`` ``labels:``).
    """

    name = "discontinuity"

    def __init__(self, base: Perception | None, settings: DiscontinuitySettings,
                 size: int | None = None, labels: dict | None = None) -> None:
        self.base = base
        self.settings = settings
        self.size = None if base is not None else int(size or model_size())
        self.labels = None if base is not None else dict(labels or model_labels())

    def __call__(self, frame, depth: np.ndarray) -> PerceptionResult:
        seen = plain_view(frame, depth, self.size, self.labels) if self.base is None else self.base(frame, depth)
        s = self.settings
        mask = discontinuity_mask(seen.depth, s.window_at(min(seen.depth.shape)), s.relative_jump, s.min_jump_m,
                                  s.invalid_is_far)
        field = distance_field(mask, float(seen.labels["truncation_px"]))  # (h, w) float32 px, 0 on F_d
        labels = {**seen.labels, "frontier_threshold_px": DISCONTINUITY_THRESHOLD_PX}
        return replace(seen, distance_field=field, labels=labels)


def ablation_settings(conf):
    """``ablations:`` of the run config `conf` (``configs/explore.yaml``'s keys)."""
    section = conf.get("ablations") if hasattr(conf, "get") else None
    if section is None:
        raise InputError("the explore config has no 'ablations' section (configs/explore.yaml has the defaults)")
    return section


def uniform_gain(base: Perception, conf) -> UniformGain:
    """`base`'s frontier pixels with the uniform gain class ``ablations.uniform_gain_class`` of the
    run config `conf`: df-uniform's, discontinuity-uniform's and oracle-uniform's stand-in."""
    return UniformGain(base, ablation_settings(conf).uniform_gain_class)


def discontinuity_frontiers(base: Perception | None, conf) -> DiscontinuityFrontiers:
    """F_d frontier pixels (``ablations.discontinuity`` of the run config `conf`) with `base`'s gain
    classes (None: no model, class 0; see :class:`DiscontinuityFrontiers`)."""
    return DiscontinuityFrontiers(base, DiscontinuitySettings.from_config(ablation_settings(conf).discontinuity))


__all__ = ["DISCONTINUITY_THRESHOLD_PX", "DiscontinuityFrontiers", "DiscontinuitySettings", "GainFrom", "UniformGain",
           "ablation_settings", "discontinuity_frontiers", "model_labels", "uniform_gain"]

"""Information-gain classes: binning gains (m^3) into K classes and decoding them back.

docs/design.md sections 1 and 4, paper sections III-C and III-E. The network's gain head
predicts one of K = ``len(bin_edges)`` classes per pixel; the edges are the classes'
upper bounds in units of ``bin_unit_m3`` (public code: 0.01 m^3, edges 1 ... 3500, so
K = 11). Both the label side (``datagen``) and the decoding side (anchoring) use these
functions, so a model file's ``labels`` dict (``bin_edges``, ``bin_unit_m3``) is all
that is needed to go back and forth.
"""

from __future__ import annotations

import numpy as np
from scipy.special import softmax

from ..errors import InputError

GAIN_DECODINGS = ("lower_bound", "midpoint", "expected")

GAIN_VOLUMES = ("unobserved", "occluded")
GAIN_SPREADS = ("blend", "region")
DEFAULT_GAIN_DEFINITION = "unobserved/blend"
"""The gain definition of datasets and model files that do not name one (made before the choice)."""


def gain_definition(gain_conf) -> str:
    """The gain label's definition, ``"<volume>/<spread>"``, of datagen's ``ground_truth.gain`` section
    (a dict or DictConfig; keys absent: :data:`DEFAULT_GAIN_DEFINITION`'s); InputError naming the key
    for an unknown value. Datagen computes labels by it (``datagen.ground_truth``); a model file
    records the definition it was trained on as ``labels.gain_definition``.

    ``volume``: ``unobserved`` (every V_out voxel the gain view sees) | ``occluded`` (only those
    inside the labelled view's frustum); ``spread``: ``blend`` (inverse-distance blend of the
    nearest measured voxels) | ``region`` (the largest gain measured in each connected region).
    """
    volume, spread = str(gain_conf.get("volume", "unobserved")), str(gain_conf.get("spread", "blend"))
    if volume not in GAIN_VOLUMES:
        raise InputError(f"ground_truth.gain.volume must be one of {', '.join(GAIN_VOLUMES)}, got {volume!r}")
    if spread not in GAIN_SPREADS:
        raise InputError(f"ground_truth.gain.spread must be one of {', '.join(GAIN_SPREADS)}, got {spread!r}")
    return f"{volume}/{spread}"


def labels_gain_definition(labels) -> str:
    """The gain definition a model's ``labels`` record (``gain_definition``; absent or None: a
    model trained before the choice, :data:`DEFAULT_GAIN_DEFINITION`)."""
    return str(labels.get("gain_definition") or DEFAULT_GAIN_DEFINITION)


def _edges_m3(bin_edges, bin_unit_m3: float) -> np.ndarray:
    """(K,) float64 class upper bounds in m^3; InputError unless K >= 2, finite, increasing."""
    try:
        edges = np.asarray(bin_edges, np.float64).reshape(-1) * float(bin_unit_m3)
    except (TypeError, ValueError):
        raise InputError(f"gain bin_edges must be a list of numbers, got {bin_edges!r}") from None
    if len(edges) < 2 or not np.all(np.isfinite(edges)) or np.any(np.diff(edges) <= 0) \
            or not float(bin_unit_m3) > 0:
        raise InputError(f"gain bin_edges must be >= 2 increasing finite numbers with a positive "
                         f"bin_unit_m3, got {np.asarray(bin_edges).reshape(-1).tolist()} x {bin_unit_m3}")
    return edges


def gain_classes(gain_m3: np.ndarray, bin_edges, bin_unit_m3: float = 0.01) -> np.ndarray:
    """Bin gains (cubic metres) into K = len(bin_edges) classes.

    The edges are the classes' upper bounds: class 0 holds ``g <= edge[0]`` (no gain),
    class i holds ``edge[i-1] < g <= edge[i]``, and gains above the last edge fall in the
    last class (K - 1). Edges are in units of `bin_unit_m3` (public code: 0.01 m^3, edges
    1 ... 3500, so K = 11 and the largest class is 25 to 35 m^3, about one full frustum).

    Returns:
        int64 array of the input's shape, values in [0, K - 1].
    """
    edges = _edges_m3(bin_edges, bin_unit_m3)
    classes = np.searchsorted(edges, np.asarray(gain_m3, np.float64), side="left")
    return np.minimum(classes, len(edges) - 1).astype(np.int64)


def class_lower_bounds(bin_edges, bin_unit_m3: float = 0.01) -> np.ndarray:
    """(K,) float64 lower bound (m^3) of each class of :func:`gain_classes`: 0, then edges[:-1]."""
    edges = _edges_m3(bin_edges, bin_unit_m3)
    return np.concatenate([[0.0], edges[:-1]])


def class_midpoints(bin_edges, bin_unit_m3: float = 0.01) -> np.ndarray:
    """(K,) float64 midpoint (m^3) of each class of :func:`gain_classes`.

    Class 0 (no gain) decodes to 0; class i >= 1 to the mean of its lower edge
    ``edge[i-1]`` and upper edge ``edge[i]`` (the last class, which also holds gains above
    the last edge, uses the last edge as its upper bound).
    """
    edges = _edges_m3(bin_edges, bin_unit_m3)
    return np.concatenate([[0.0], 0.5 * (edges[:-1] + edges[1:])])


def class_values(bin_edges, bin_unit_m3: float = 0.01, mode: str = "lower_bound") -> np.ndarray:
    """(K,) float64 gain (m^3) each class decodes to: ``lower_bound`` or ``midpoint`` (also
    ``expected``'s value of a class known for certain, e.g. a label)."""
    if mode == "lower_bound":
        return class_lower_bounds(bin_edges, bin_unit_m3)
    if mode in ("midpoint", "expected"):
        return class_midpoints(bin_edges, bin_unit_m3)
    raise InputError(f"gain decoding must be one of {', '.join(GAIN_DECODINGS)}, got {mode!r}")


def decode_gain(gain_class: np.ndarray, bin_edges, bin_unit_m3: float = 0.01,
                mode: str = "lower_bound", gain_logits: np.ndarray | None = None,
                where: np.ndarray | None = None) -> np.ndarray:
    """Per-pixel gain classes -> gain in cubic metres (paper III-E: G = decoded gain).

    The paper decodes a class to its bin's lower bound (``lower_bound``, the default of
    ``configs/explore.yaml``); ``midpoint`` uses the middle of the bin. ``expected`` reads the
    class probabilities p = softmax(gain_logits) instead of the most likely class alone:
    G = sum_k p_k m_k over the bins' midpoints m_k (m_0 = 0), the expectation of an ordinal
    classifier's output (as DEX, Rothe et al., ICCVW 2015, reads age from 101 age classes);
    without logits (labels, a class known for certain) it is the midpoint. A pixel whose
    most likely class is 0 (no gain) is 0 m^3 in every mode, so ``drop_zero_gain`` drops the
    same pixels whatever the decoding.

    Args:
        gain_class: (H, W) (or any shape) integer classes in [0, K - 1], K = len(bin_edges):
            the most likely class of each pixel.
        bin_edges, bin_unit_m3: the model's ``labels`` (class upper bounds, their unit in m^3).
        mode: "lower_bound" | "midpoint" | "expected".
        gain_logits: (K, H, W) float class logits of the same pixels (``expected`` only).
        where: (H, W) bool, the pixels whose expectation is needed (``expected`` with logits;
            elsewhere the midpoint of the class); None: every pixel.
    Returns:
        float32 array of `gain_class`'s shape, cubic metres.
    """
    values = class_values(bin_edges, bin_unit_m3, mode).astype(np.float32)
    classes = np.asarray(gain_class)
    if classes.dtype.kind not in "iu":
        raise InputError(f"gain classes must be integers, got dtype {classes.dtype}")
    if classes.size and (classes.min() < 0 or classes.max() >= len(values)):
        raise InputError(f"gain classes must lie in [0, {len(values) - 1}], got values in "
                         f"[{classes.min()}, {classes.max()}]")
    gain = values[classes]
    if mode == "expected" and gain_logits is not None:
        logits = np.asarray(gain_logits, np.float32)
        if logits.shape != (len(values), *classes.shape):
            raise InputError(f"gain logits must be (K={len(values)}, {', '.join(map(str, classes.shape))}), "
                             f"got {logits.shape}")
        picked = classes > 0 if where is None else (classes > 0) & np.asarray(where, bool)
        gain[picked] = values @ softmax(logits[:, picked], axis=0)  # (K,) @ (K, N)
    return gain


# -- agreement between two gain-class maps (model vs label, or label vs label) ----------------------

def class_confusion(predicted: np.ndarray, target: np.ndarray, num_classes: int,
                    mask: np.ndarray | None = None) -> np.ndarray:
    """(K, K) int64 confusion matrix: row = target class, column = predicted class.

    Args:
        predicted, target: integer class maps of one shape (any), values in [0, K - 1].
        mask: optional bool array of that shape: only these pixels count.
    """
    predicted, target = np.asarray(predicted).reshape(-1), np.asarray(target).reshape(-1)
    if mask is not None:
        keep = np.asarray(mask, bool).reshape(-1)
        predicted, target = predicted[keep], target[keep]
    K = int(num_classes)
    return np.bincount(target.astype(np.int64) * K + predicted, minlength=K * K).reshape(K, K)


def dice_per_class(confusion: np.ndarray) -> np.ndarray:
    """(K,) float64 hard Dice per class from a (K, K) confusion matrix (rows target, columns
    predicted): ``2 TP / (predicted + target)``; NaN for a class in neither."""
    confusion = np.asarray(confusion, np.float64)
    total = confusion.sum(0) + confusion.sum(1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total > 0, 2.0 * np.diag(confusion) / total, np.nan)


def mean_dice(confusion: np.ndarray, include_class_0: bool = True) -> float:
    """Macro mean of :func:`dice_per_class` over the classes present in the target or the
    prediction (a class predicted but never labelled scores 0; one in neither is left out,
    the ``torchmetrics`` macro convention); NaN when no class is present.

    ``include_class_0=True`` over all pixels of a set is this project's paper-comparable gain
    Dice (docs/model.md says why); ``False`` averages the gain classes 1..K-1 only.
    """
    dice = dice_per_class(confusion)
    dice = dice if include_class_0 else dice[1:]
    dice = dice[np.isfinite(dice)]
    return float(dice.mean()) if dice.size else float("nan")


def class_offsets(confusion: np.ndarray) -> dict:
    """How far off the predicted class is, over the pixels of a confusion matrix (the gain
    classes are ordered bins of volume, so one class off is a near miss).

    Returns ``exact``, ``one_off`` and ``further`` (fractions of the pixels: |predicted -
    target| = 0, 1, >= 2), ``mean_abs_offset`` (classes) and ``pixels``; NaN without pixels.
    """
    confusion = np.asarray(confusion, np.float64)
    K = confusion.shape[0]
    offset = np.abs(np.arange(K)[:, None] - np.arange(K)[None, :])
    pixels = confusion.sum()
    if pixels == 0:
        return {"exact": float("nan"), "one_off": float("nan"), "further": float("nan"),
                "mean_abs_offset": float("nan"), "pixels": 0}
    return {"exact": float(confusion[offset == 0].sum() / pixels),
            "one_off": float(confusion[offset == 1].sum() / pixels),
            "further": float(confusion[offset >= 2].sum() / pixels),
            "mean_abs_offset": float((confusion * offset).sum() / pixels), "pixels": int(pixels)}

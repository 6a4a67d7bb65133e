"""The training loss: ``alpha * L1(normalised D) + CE(Y) + Dice(Y)`` (docs/design.md section 2).

The gain terms are configurable (``loss`` section of ``configs/train.yaml``), because the label
is lopsided: class 0 (no gain) covers ~90 % of the pixels, the ten gain classes live in the band
D < r around frontiers, and a batch holds about half of them. The old loss (CE over every pixel,
soft Dice over all K classes) stays selectable (``ce_outside_band_weight: 1``, ``dice_classes:
all``, ``ordinal_sigma: 0``) so that variants can be compared on equal terms; docs/model.md has
the comparison.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from frontiernet.errors import InputError
from frontiernet.model import encode_distance

DICE_CLASSES = ("all", "present")
# keys added after the first shipped model, with the values that reproduce its loss (checkpoints
# of older runs carry a `loss` section without them)
LEGACY_GAIN_LOSS = {"ce_outside_band_weight": 1.0, "dice_classes": "all", "ordinal_sigma": 0.0}


def loss_settings(loss_conf) -> dict:
    """The ``loss`` section as a plain dict, missing gain keys filled with the old loss's values
    (:data:`LEGACY_GAIN_LOSS`); InputError naming the key for a bad value."""
    conf = {**LEGACY_GAIN_LOSS, **dict(loss_conf)}
    if conf["distance_region"] not in ("all", "band"):
        raise InputError(f"loss.distance_region must be 'all' or 'band', got {conf['distance_region']!r}")
    if conf["dice_classes"] not in DICE_CLASSES:
        raise InputError(f"loss.dice_classes must be one of {', '.join(DICE_CLASSES)}, got {conf['dice_classes']!r}")
    for key, low, high in (("ce_outside_band_weight", 0.0, 1.0), ("ordinal_sigma", 0.0, float("inf")),
                           ("distance_weight", 0.0, float("inf")), ("ce_weight", 0.0, float("inf")),
                           ("dice_weight", 0.0, float("inf"))):
        try:
            value = float(conf[key])
        except (TypeError, ValueError):
            value = float("nan")
        if not low <= value <= high:
            raise InputError(f"loss.{key} must be a number in [{low:g}, {high:g}], got {conf[key]!r}")
        conf[key] = value
    return conf


def dice_loss(logits: torch.Tensor, target: torch.Tensor, eps: float = 1.0, classes: str = "all") -> torch.Tensor:
    """Multi-class soft Dice loss, ``1 - mean_k Dice_k``, over the batch's pixels.

    Args:
        logits: (B, K, H, W) float; target: (B, H, W) int64 in [0, K - 1].
        eps: smoothing added to numerator and denominator.
        classes: ``all``: the mean runs over the K classes; a class absent from the batch's labels
            scores ``eps / (sum of its probabilities + eps)``, so the loss pushes its probability
            to zero on every pixel (the old loss). ``present``: only the classes in the batch's
            labels count (segmentation_models_pytorch's DiceLoss convention), so a rare class is
            not punished for being absent from a batch.
    """
    probabilities = logits.float().softmax(dim=1)
    one_hot = F.one_hot(target, logits.shape[1]).permute(0, 3, 1, 2).to(probabilities.dtype)
    dims = (0, 2, 3)
    intersection = (probabilities * one_hot).sum(dims)
    labelled = one_hot.sum(dims)
    dice = (2.0 * intersection + eps) / (probabilities.sum(dims) + labelled + eps)
    if classes == "present":
        dice = dice[labelled > 0]
    return 1.0 - dice.mean()


def ordinal_targets(target: torch.Tensor, num_classes: int, sigma: float) -> torch.Tensor:
    """(B, K, H, W) float32 soft labels ``q_k ~ exp(-(k - y)^2 / (2 sigma^2))`` (sum 1 over k).

    Soft ordinal labels (SORD, Diaz & Marathe, CVPR 2019): the gain classes are ordered bins of
    log-volume, so a prediction one class off costs less than one far off. Distances are in
    class indices (the bins are log-spaced, so an index is about a constant factor of volume).
    """
    classes = torch.arange(num_classes, device=target.device, dtype=torch.float32)
    offset = classes[None, :, None, None] - target[:, None].float()
    return torch.softmax(-offset.square() / (2.0 * float(sigma) ** 2), dim=1)


def gain_cross_entropy(logits: torch.Tensor, target: torch.Tensor, distance_px: torch.Tensor,
                       truncation_px: float, outside_band_weight: float = 1.0,
                       ordinal_sigma: float = 0.0) -> torch.Tensor:
    """Pixel-weighted cross-entropy of the gain classes (a scalar).

    Args:
        logits: (B, K, H, W); target: (B, H, W) int64; distance_px: (B, H, W) float label D, pixels.
        truncation_px: r; the labelled band is D < r (where datagen writes the gain classes).
        outside_band_weight: weight of a pixel outside the band relative to one inside: 1 = all
            pixels alike (class 0 then makes ~90 % of the loss), 0 = CE masked to the band.
        ordinal_sigma: 0 = one-hot targets; > 0 = :func:`ordinal_targets` of this width.
    Returns the weighted mean ``sum(w * ce) / sum(w)`` (0 when every weight is 0).
    """
    logits = logits.float()
    if ordinal_sigma > 0:
        per_pixel = F.cross_entropy(logits, ordinal_targets(target, logits.shape[1], ordinal_sigma), reduction="none")
    else:
        per_pixel = F.cross_entropy(logits, target, reduction="none")
    if outside_band_weight == 1.0:
        return per_pixel.mean()
    weight = torch.where(distance_px < truncation_px, 1.0, float(outside_band_weight)).to(per_pixel.dtype)
    return (weight * per_pixel).sum() / weight.sum().clamp(min=1e-12)


def frontier_loss(distance: torch.Tensor, gain_logits: torch.Tensor, batch: dict, loss_conf,
                  labels_conf) -> dict[str, torch.Tensor]:
    """Loss terms of one batch.

    Args:
        distance: (B, 1, H, W) predicted normalised distance y >= 0.
        gain_logits: (B, K, H, W) gain-class logits.
        batch: ``distance`` (B, H, W) float pixels, ``gain_class`` (B, H, W) int64.
        loss_conf: ``loss`` section of ``configs/train.yaml``: ``distance_weight`` (alpha),
            ``distance_region`` (``all`` or ``band``: L1 over every pixel, or only D < r as
            DeepLSD masks its line distance field), ``ce_weight``, ``dice_weight``, and the gain
            options ``ce_outside_band_weight``, ``dice_classes``, ``ordinal_sigma`` (see
            :func:`gain_cross_entropy`, :func:`dice_loss`; missing keys take the old loss's values).
    Returns:
        ``loss`` (the weighted sum) and its terms ``distance``, ``ce``, ``dice`` (scalars).
    """
    conf = loss_settings(loss_conf)
    truncation = float(labels_conf["truncation_px"])
    target = encode_distance(batch["distance"], labels_conf)
    error = (distance[:, 0].float() - target).abs()
    if conf["distance_region"] == "band":
        band = batch["distance"] < truncation
        distance_term = (error * band).sum() / band.sum().clamp(min=1)
    else:
        distance_term = error.mean()
    ce = gain_cross_entropy(gain_logits, batch["gain_class"], batch["distance"], truncation,
                            conf["ce_outside_band_weight"], conf["ordinal_sigma"])
    dice = dice_loss(gain_logits, batch["gain_class"], classes=conf["dice_classes"])
    loss = conf["distance_weight"] * distance_term + conf["ce_weight"] * ce + conf["dice_weight"] * dice
    return {"loss": loss, "distance": distance_term.detach(), "ce": ce.detach(), "dice": dice.detach()}

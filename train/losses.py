"""The training loss: ``alpha * L1(normalised D) + CE(Y) + Dice(Y)`` (DESIGN.md section 2)."""

from __future__ import annotations

import torch
import torch.nn.functional as F

from frontiernet.model import encode_distance


def dice_loss(logits: torch.Tensor, target: torch.Tensor, eps: float = 1.0) -> torch.Tensor:
    """Multi-class soft Dice loss, ``1 - mean_k Dice_k`` over the classes.

    Args:
        logits: (B, K, H, W) float; target: (B, H, W) int64 in [0, K - 1].
        eps: smoothing added to numerator and denominator (classes absent from both the batch's
            labels and predictions score 1, so they do not pull the loss).
    """
    probabilities = logits.float().softmax(dim=1)
    one_hot = F.one_hot(target, logits.shape[1]).permute(0, 3, 1, 2).to(probabilities.dtype)
    dims = (0, 2, 3)
    intersection = (probabilities * one_hot).sum(dims)
    total = probabilities.sum(dims) + one_hot.sum(dims)
    return 1.0 - ((2.0 * intersection + eps) / (total + eps)).mean()


def frontier_loss(distance: torch.Tensor, gain_logits: torch.Tensor, batch: dict, loss_conf,
                  labels_conf) -> dict[str, torch.Tensor]:
    """Loss terms of one batch.

    Args:
        distance: (B, 1, H, W) predicted normalised distance y >= 0.
        gain_logits: (B, K, H, W) gain-class logits.
        batch: ``distance`` (B, H, W) float pixels, ``gain_class`` (B, H, W) int64.
        loss_conf: ``loss`` section of ``configs/train.yaml``: ``distance_weight`` (alpha),
            ``distance_region`` (``all`` or ``band``: L1 over every pixel, or only D < r as
            DeepLSD masks its line distance field), ``ce_weight``, ``dice_weight``.
    Returns:
        ``loss`` (the weighted sum) and its terms ``distance``, ``ce``, ``dice`` (scalars).
    """
    target = encode_distance(batch["distance"], labels_conf)
    error = (distance[:, 0].float() - target).abs()
    region = loss_conf["distance_region"]
    if region == "band":
        band = batch["distance"] < float(labels_conf["truncation_px"])
        distance_term = (error * band).sum() / band.sum().clamp(min=1)
    elif region == "all":
        distance_term = error.mean()
    else:
        raise ValueError(f"loss.distance_region must be 'all' or 'band', got {region!r}")
    ce = F.cross_entropy(gain_logits.float(), batch["gain_class"])
    dice = dice_loss(gain_logits, batch["gain_class"])
    loss = (float(loss_conf["distance_weight"]) * distance_term + float(loss_conf["ce_weight"]) * ce
            + float(loss_conf["dice_weight"]) * dice)
    return {"loss": loss, "distance": distance_term.detach(), "ce": ce.detach(), "dice": dice.detach()}

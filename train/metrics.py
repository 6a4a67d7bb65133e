"""Validation metrics: the paper's Table II and the frontier-mask baseline comparison.

All are ``torchmetrics.Metric`` sums, so they add up correctly over batches and over
processes (DDP). Images are (B, H, W); distances in pixels.

- :class:`DistanceError`: mean |D_pred - D| in pixels over all pixels (Table II's DF error)
  and over the band D < r.
- :class:`GainDice`: confusion matrices of the gain classes (argmax vs label) over the whole
  set, over the labelled band D < r and over the label's frontier pixels F, and from them: hard
  Dice per class; its macro mean over the classes present with class 0 included (the
  paper-comparable gain Dice, see docs/model.md) and over the foreground classes 1..K-1 only;
  the Dice at frontier pixels (where the gain is read); how often the band is one class off.
- :class:`FrontierCurves`: precision/recall of frontier masks with a 1-pixel tolerance (a
  predicted pixel is right when a label pixel is in its 3 x 3 neighbourhood; a label pixel is
  found when a predicted one is in its 3 x 3 neighbourhood), for the model's ``D_pred < l``
  over a sweep of l, and for the raw depth-discontinuity mask F_d over a sweep of its jump
  threshold (the baseline the model must beat: precision at equal recall).
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn
from torchmetrics import Metric

from frontiernet.frontiers.gain import class_offsets, dice_per_class, mean_dice
from frontiernet.model import decode_distance

MODEL_THRESHOLDS_PX = (0.1, 0.2, 0.3, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0)
# relative depth jump thresholds; 0.1 with a 0.1 m floor is datagen's F_d
JUMP_THRESHOLDS = (0.02, 0.05, 0.1, 0.2, 0.3, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 5.0)


class DistanceError(Metric):
    full_state_update = False

    def __init__(self, truncation_px: float):
        super().__init__()
        self.truncation_px = float(truncation_px)
        for name in ("error_sum", "count", "band_error_sum", "band_count"):
            self.add_state(name, default=torch.tensor(0.0, dtype=torch.float64), dist_reduce_fx="sum")

    def update(self, predicted_px: torch.Tensor, target_px: torch.Tensor) -> None:
        error = (predicted_px.float() - target_px.float()).abs().double()
        band = target_px < self.truncation_px
        self.error_sum += error.sum()
        self.count += error.numel()
        self.band_error_sum += (error * band).sum()
        self.band_count += band.sum()

    def compute(self) -> dict:
        return {"df_error_px": float(self.error_sum / self.count.clamp(min=1)),
                "df_error_band_px": float(self.band_error_sum / self.band_count.clamp(min=1))}


class GainDice(Metric):
    """Gain-class agreement, accumulated as (K, K) confusion matrices (rows label, columns
    prediction) over all pixels, the labelled band D < r and the label's frontier pixels F.

    ``update(predicted_class, target_class, distance_px=None, frontier=None)``: (B, H, W) int64
    classes; the label's D in pixels and F (bool), when given, fill the band and frontier
    matrices. The scores come from :mod:`frontiernet.frontiers.gain` (the same ones the label
    consistency check of ``frontiernet datagen consistency`` uses).
    """

    full_state_update = False
    REGIONS = ("all", "band", "frontier")

    def __init__(self, num_classes: int, truncation_px: float = 10.0):
        super().__init__()
        self.num_classes = int(num_classes)
        self.truncation_px = float(truncation_px)
        for region in self.REGIONS:
            self.add_state(f"confusion_{region}", default=torch.zeros(self.num_classes, self.num_classes,
                                                                      dtype=torch.float64), dist_reduce_fx="sum")

    def _add(self, region: str, predicted: torch.Tensor, target: torch.Tensor) -> None:
        K = self.num_classes
        counts = torch.bincount((target.reshape(-1) * K + predicted.reshape(-1)).long(), minlength=K * K)
        getattr(self, f"confusion_{region}").add_(counts.reshape(K, K).double())

    def update(self, predicted_class: torch.Tensor, target_class: torch.Tensor,
               distance_px: torch.Tensor | None = None, frontier: torch.Tensor | None = None) -> None:
        self._add("all", predicted_class, target_class)
        if distance_px is not None:
            band = distance_px < self.truncation_px
            self._add("band", predicted_class[band], target_class[band])
        if frontier is not None:
            self._add("frontier", predicted_class[frontier], target_class[frontier])

    def compute(self) -> dict:
        confusion = {region: getattr(self, f"confusion_{region}").cpu().numpy() for region in self.REGIONS}
        band, at_frontier = class_offsets(confusion["band"]), class_offsets(confusion["frontier"])
        return {"gain_dice": mean_dice(confusion["all"], include_class_0=False),
                "gain_dice_with_class_0": mean_dice(confusion["all"], include_class_0=True),
                "gain_dice_per_class": [float(v) for v in dice_per_class(confusion["all"])],
                "gain_dice_frontier": mean_dice(confusion["frontier"], include_class_0=True),
                "gain_band_exact": band["exact"], "gain_band_one_off": band["one_off"],
                "gain_band_mean_abs_offset": band["mean_abs_offset"],
                "gain_frontier_exact": at_frontier["exact"], "gain_frontier_one_off": at_frontier["one_off"],
                "gain_offsets": {"band": band, "frontier": at_frontier},
                "gain_confusion": {region: matrix.astype(np.int64).tolist() for region, matrix in confusion.items()}}


def depth_jump_score(depth: torch.Tensor, min_jump_m: float = 0.1, relative_jump: float = 0.1) -> torch.Tensor:
    """Per-pixel score s such that ``s > t`` is F_d of datagen at relative jump t.

    ``s = (max - min) / max(min, min_jump_m / relative_jump)`` over the 3 x 3 window, invalid
    (0) pixels counting as farther than any valid one (datagen's ``invalid_is_far``).
    Args: depth (B, H, W) metres, 0 = invalid. Returns (B, H, W) float32.
    """
    valid = depth > 0
    far = torch.full_like(depth, 1e4)
    high = F.max_pool2d(torch.where(valid, depth, far)[:, None], 3, 1, 1)[:, 0]
    low = -F.max_pool2d(-torch.where(valid, depth, far)[:, None], 3, 1, 1)[:, 0]
    score = (high - low) / low.clamp(min=min_jump_m / relative_jump)
    return torch.where(low < 1e4, score, torch.zeros_like(score))


def _near(mask: torch.Tensor) -> torch.Tensor:
    """(B, H, W) bool: pixels with a set pixel in their 3 x 3 neighbourhood."""
    return F.max_pool2d(mask[:, None].float(), 3, 1, 1)[:, 0] > 0


class FrontierCurves(Metric):
    full_state_update = False

    def __init__(self):
        super().__init__()
        for prefix, thresholds in (("model", MODEL_THRESHOLDS_PX), ("jump", JUMP_THRESHOLDS)):
            for name in ("correct", "predicted", "found"):
                self.add_state(f"{prefix}_{name}", default=torch.zeros(len(thresholds), dtype=torch.float64),
                               dist_reduce_fx="sum")
        self.add_state("labelled", default=torch.tensor(0.0, dtype=torch.float64), dist_reduce_fx="sum")

    def _count(self, prefix: str, index: int, mask: torch.Tensor, near_label: torch.Tensor,
               label: torch.Tensor) -> None:
        getattr(self, f"{prefix}_correct")[index] += (mask & near_label).sum()
        getattr(self, f"{prefix}_predicted")[index] += mask.sum()
        getattr(self, f"{prefix}_found")[index] += (label & _near(mask)).sum()

    def update(self, predicted_px: torch.Tensor, frontier: torch.Tensor, depth: torch.Tensor) -> None:
        near_label = _near(frontier)
        self.labelled += frontier.sum()
        for index, threshold in enumerate(MODEL_THRESHOLDS_PX):
            self._count("model", index, predicted_px < threshold, near_label, frontier)
        score = depth_jump_score(depth)
        for index, threshold in enumerate(JUMP_THRESHOLDS):
            self._count("jump", index, score > threshold, near_label, frontier)

    def curve(self, prefix: str) -> tuple[np.ndarray, np.ndarray]:
        """(precision, recall) arrays over the prefix's thresholds (precision NaN where nothing is predicted)."""
        predicted = getattr(self, f"{prefix}_predicted")
        precision = torch.where(predicted > 0, getattr(self, f"{prefix}_correct") / predicted.clamp(min=1), torch.nan)
        recall = getattr(self, f"{prefix}_found") / self.labelled.clamp(min=1)
        return precision.cpu().numpy(), recall.cpu().numpy()

    def compute(self) -> dict:
        model_p, model_r = self.curve("model")
        jump_p, jump_r = self.curve("jump")
        index_l = MODEL_THRESHOLDS_PX.index(0.3)
        index_fd = JUMP_THRESHOLDS.index(0.1)
        result = {"frontier_precision": float(model_p[index_l]), "frontier_recall": float(model_r[index_l]),
                  "fd_precision": float(jump_p[index_fd]), "fd_recall": float(jump_r[index_fd]),
                  "model_curve": {"threshold_px": list(MODEL_THRESHOLDS_PX), "precision": model_p.tolist(),
                                  "recall": model_r.tolist()},
                  "fd_curve": {"jump_threshold": list(JUMP_THRESHOLDS), "precision": jump_p.tolist(),
                               "recall": jump_r.tolist()}}
        # the threshold l with the best F1 (the paper's l = 0.3 px is its public model's choice)
        f1 = np.nan_to_num(2 * model_p * model_r / np.maximum(model_p + model_r, 1e-12))
        best = int(np.argmax(f1))
        result.update(best_f1_threshold_px=MODEL_THRESHOLDS_PX[best], best_f1=float(f1[best]),
                      best_f1_precision=float(model_p[best]), best_f1_recall=float(model_r[best]))
        # the model's precision at F_d's recall and F_d's precision at the model's recall (operating
        # points l = 0.3 px and jump 0.1), interpolated along the other's curve
        result["model_precision_at_fd_recall"] = precision_at_recall(model_p, model_r, result["fd_recall"])
        result["fd_precision_at_model_recall"] = precision_at_recall(jump_p, jump_r, result["frontier_recall"])
        result["fd_precision_at_best_f1_recall"] = precision_at_recall(jump_p, jump_r, result["best_f1_recall"])
        return result


def precision_at_recall(precision: np.ndarray, recall: np.ndarray, wanted: float) -> float:
    """Precision interpolated at recall `wanted` along a curve (NaN outside its recall range;
    thresholds where nothing is predicted are left out)."""
    keep = np.isfinite(precision)
    precision, recall = np.asarray(precision)[keep], np.asarray(recall)[keep]
    order = np.argsort(recall)
    recall, precision = recall[order], precision[order]
    if not len(recall) or wanted < recall[0] - 1e-9 or wanted > recall[-1] + 1e-9:
        return float("nan")
    return float(np.interp(wanted, recall, precision))


class FrontierMetrics(nn.Module):
    """The three metrics above, fed from one batch of network outputs (a module, so Lightning
    moves and syncs them with the model).

    ``update(distance, logits, batch)``: distance (B, 1, H, W) normalised y, logits (B, K, H, W),
    batch with ``distance`` px, ``gain_class``, ``frontier`` and ``depth`` (B, H, W).
    The gain is also scored as the pipeline reads it (``gain_dice_read*``): the argmax class where
    the predicted D < r, class 0 elsewhere (anchoring only looks at pixels with D < l < r).
    """

    def __init__(self, labels_conf):
        super().__init__()
        self.labels = dict(labels_conf)
        self.distance_error = DistanceError(self.labels["truncation_px"])
        self.gain_dice = GainDice(self.labels["num_classes"], self.labels["truncation_px"])
        self.gain_dice_read = GainDice(self.labels["num_classes"], self.labels["truncation_px"])
        self.frontier_curves = FrontierCurves()

    def update(self, distance: torch.Tensor, logits: torch.Tensor, batch: dict) -> None:
        predicted_px = decode_distance(distance[:, 0].float(), self.labels)
        self.distance_error.update(predicted_px, batch["distance"])
        predicted_class = logits.argmax(1)
        self.gain_dice.update(predicted_class, batch["gain_class"], batch["distance"], batch["frontier"])
        read = torch.where(predicted_px < float(self.labels["truncation_px"]), predicted_class, 0)
        self.gain_dice_read.update(read, batch["gain_class"])
        self.frontier_curves.update(predicted_px, batch["frontier"], batch["depth"])

    def compute(self) -> dict:
        read = self.gain_dice_read.compute()
        return {**self.distance_error.compute(), **self.gain_dice.compute(), **self.frontier_curves.compute(),
                "gain_dice_read_with_class_0": read["gain_dice_with_class_0"], "gain_dice_read": read["gain_dice"]}

    def reset(self) -> None:
        for metric in (self.distance_error, self.gain_dice, self.gain_dice_read, self.frontier_curves):
            metric.reset()

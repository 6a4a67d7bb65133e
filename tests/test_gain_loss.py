"""The gain loss options (band-weighted CE, Dice over the classes present, soft ordinal labels), the
old loss still selectable, and the gain metrics of `frontiernet evaluate` (confusion matrices,
per-class and paper-comparable Dice, how often a class is one off)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from frontiernet.cli.main import main
from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.frontiers.gain import class_confusion, class_offsets, dice_per_class, mean_dice
from frontiernet.model import encode_distance
from train.losses import LEGACY_GAIN_LOSS, dice_loss, frontier_loss, gain_cross_entropy, loss_settings
from train.metrics import GainDice

LABELS = OmegaConf.to_container(load_config("model").labels)
K = 11


def one_hot_logits(classes: torch.Tensor, scale: float = 20.0) -> torch.Tensor:
    return torch.nn.functional.one_hot(classes, K).permute(0, 3, 1, 2).float() * scale


def band_batch() -> dict:
    """One 16 x 16 view: a frontier row at v = 8, its band D < 10 px labelled class 4 or 5."""
    distance = torch.full((1, 16, 16), 10.0)
    distance[0, 4:13] = (torch.arange(4, 13) - 8).abs().float()[:, None]
    gain = torch.zeros(1, 16, 16, dtype=torch.long)
    gain[0, 4:13, :8], gain[0, 4:13, 8:] = 4, 5
    return {"distance": distance, "gain_class": gain}


def test_dice_over_present_classes_does_not_punish_absent_ones():
    batch = band_batch()
    right = one_hot_logits(batch["gain_class"], scale=4.0)  # the right class, some mass on all the others
    # over all K classes, the nine absent classes score ~0 however right the answer is ...
    assert dice_loss(right, batch["gain_class"], classes="all") > 0.5
    # ... over the present ones only, the right answer is nearly perfect
    assert dice_loss(right, batch["gain_class"], classes="present") < 0.15
    wrong = one_hot_logits(torch.where(batch["gain_class"] > 0, 9, 0), scale=4.0)
    assert dice_loss(wrong, batch["gain_class"], classes="present") > 0.4


def test_ce_outside_band_weight_masks_the_pixels_outside_the_band():
    batch = band_batch()
    logits = one_hot_logits(batch["gain_class"], 5.0)
    outside = batch["distance"] >= 10
    changed = logits.clone()
    changed[:, 7][outside] = 30.0  # confidently class 7 everywhere outside the band
    args = (batch["gain_class"], batch["distance"], 10.0)
    assert gain_cross_entropy(changed, *args, outside_band_weight=0.0) == pytest.approx(
        float(gain_cross_entropy(logits, *args, outside_band_weight=0.0)))
    assert gain_cross_entropy(changed, *args, outside_band_weight=1.0) > 3 * gain_cross_entropy(logits, *args)
    # weight w: the outside pixels count w times as much as band pixels
    inside_ce = gain_cross_entropy(logits, *args, outside_band_weight=0.0)
    half = gain_cross_entropy(changed, *args, outside_band_weight=0.5)
    assert inside_ce < half < gain_cross_entropy(changed, *args, outside_band_weight=1.0)


def test_ordinal_labels_make_a_near_miss_cheaper_than_a_far_one():
    batch = band_batch()
    target = batch["gain_class"]
    near = one_hot_logits(torch.where(target > 0, target + 1, 0), 6.0)
    far = one_hot_logits(torch.where(target > 0, target + 5, 0), 6.0)
    args = (target, batch["distance"], 10.0)
    plain_near, plain_far = (gain_cross_entropy(x, *args, ordinal_sigma=0.0) for x in (near, far))
    assert plain_near == pytest.approx(float(plain_far))  # one-hot CE: every wrong class costs the same
    in_band = {"ordinal_sigma": 1.0, "outside_band_weight": 0.0}
    assert gain_cross_entropy(near, *args, **in_band) < 0.85 * gain_cross_entropy(far, *args, **in_band)


def test_old_loss_is_the_default_for_sections_without_the_gain_keys():
    torch.manual_seed(0)
    batch = band_batch()
    distance, logits = torch.rand(1, 1, 16, 16), torch.randn(1, K, 16, 16)
    old_section = {"distance_weight": 1.0, "distance_region": "all", "ce_weight": 1.0, "dice_weight": 1.0}
    old = frontier_loss(distance, logits, batch, old_section, LABELS)
    explicit = frontier_loss(distance, logits, batch, {**old_section, **LEGACY_GAIN_LOSS}, LABELS)
    assert float(old["loss"]) == float(explicit["loss"])
    # by hand: mean CE over every pixel plus 1 - mean soft Dice over all K classes
    ce = torch.nn.functional.cross_entropy(logits, batch["gain_class"])
    assert float(old["ce"]) == pytest.approx(float(ce), rel=1e-6)
    new = frontier_loss(distance, logits, batch, {**old_section, "ce_outside_band_weight": 0.1,
                                                  "dice_classes": "present", "ordinal_sigma": 1.0}, LABELS)
    assert float(new["loss"]) != float(old["loss"])


@pytest.mark.parametrize("key, value", [("dice_classes", "some"), ("ce_outside_band_weight", 2.0),
                                        ("ordinal_sigma", -1.0), ("ordinal_sigma", "wide")])
def test_bad_loss_option_names_the_key(key, value):
    with pytest.raises(InputError, match=f"loss.{key}"):
        loss_settings({**load_config("train").loss, key: value})


def test_bad_loss_option_on_the_command_line_is_one_line_exit_2(tmp_path, one_line_error):
    assert main(["train", f"data.path={tmp_path}", f"out={tmp_path}", "loss.dice_classes=most"]) == 2
    assert "loss.dice_classes must be one of all, present" in one_line_error()


def test_confusion_dice_and_offsets_by_hand():
    target = np.array([0, 0, 0, 0, 2, 2, 3, 3])
    predicted = np.array([0, 0, 0, 2, 2, 3, 3, 5])
    confusion = class_confusion(predicted, target, 6)
    assert confusion[0, 0] == 3 and confusion[0, 2] == 1 and confusion[2, 3] == 1 and confusion.sum() == 8
    dice = dice_per_class(confusion)
    # class 0: 2*3/(3+4); class 2: 2*1/(2+2); class 3: 2*1/(2+2); class 5: predicted only -> 0; 1, 4 absent
    assert dice[0] == pytest.approx(6 / 7) and dice[2] == dice[3] == 0.5 and dice[5] == 0
    assert np.isnan(dice[1]) and np.isnan(dice[4])
    assert mean_dice(confusion) == pytest.approx((6 / 7 + 0.5 + 0.5 + 0) / 4)
    assert mean_dice(confusion, include_class_0=False) == pytest.approx(1 / 3)
    offsets = class_offsets(class_confusion(predicted, target, 6, mask=target > 0))
    assert offsets["exact"] == 0.5 and offsets["one_off"] == 0.25 and offsets["further"] == 0.25
    assert offsets["mean_abs_offset"] == pytest.approx((0 + 1 + 0 + 2) / 4)


def test_gain_metric_reports_band_frontier_and_confusion():
    batch = band_batch()
    frontier = batch["distance"] == 0
    one_off = torch.where(batch["gain_class"] > 0, batch["gain_class"] + 1, 0)
    metric = GainDice(K, truncation_px=10.0)
    metric.update(one_off, batch["gain_class"], batch["distance"], frontier)
    result = metric.compute()
    assert result["gain_band_exact"] == 0 and result["gain_band_one_off"] == 1
    assert result["gain_frontier_one_off"] == 1
    confusion = np.array(result["gain_confusion"]["all"])
    assert confusion[4, 5] == 9 * 8 and confusion[0, 0] == 16 * 16 - 9 * 16
    # every gain pixel one class off: hard Dice 0 for classes 4, 5, 6 (a near miss counts as a miss),
    # class 0 perfect, so the paper-comparable mean is 1/4, while the band is 100 % one off
    assert result["gain_dice_per_class"][4:7] == [0, 0, 0] and result["gain_dice_per_class"][0] == 1
    assert result["gain_dice_with_class_0"] == 0.25 and result["gain_dice"] == 0
    perfect = GainDice(K)
    perfect.update(batch["gain_class"], batch["gain_class"], batch["distance"], frontier)
    assert perfect.compute()["gain_dice_with_class_0"] == 1 and perfect.compute()["gain_dice_frontier"] == 1


def test_gain_read_in_the_predicted_band_ignores_classes_outside_it():
    from train.metrics import FrontierMetrics

    batch = band_batch()
    batch["frontier"] = batch["distance"] == 0
    batch["depth"] = torch.full((1, 16, 16), 2.0)
    distance_y = encode_distance(batch["distance"], LABELS)[:, None]  # the right distance field
    logits = one_hot_logits(batch["gain_class"])
    logits[:, 7][(batch["distance"] >= 10)] = 40.0  # class 7 everywhere outside the band
    metrics = FrontierMetrics(LABELS)
    metrics.update(distance_y, logits, batch)
    result = metrics.compute()
    assert result["gain_dice_read_with_class_0"] == 1.0 and result["gain_dice_read"] == 1.0
    assert result["gain_dice_with_class_0"] < 0.8  # the raw argmax map pays for class 7 outside

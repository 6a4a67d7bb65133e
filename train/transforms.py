"""Training samples: labels at the training resolution, crops, flips, photometric jitter.

A *training sample* is a dict of numpy arrays of one size (H, W):

- ``rgb`` (H, W, 3) uint8; ``depth`` (H, W) float32 metres, 0 = invalid (NaN mapped to 0);
- ``far_depth`` (H, W) float32 metres of surfaces beyond the sensor's range, 0 elsewhere (all 0
  for a dataset written before datagen stored it);
- ``frontier`` (H, W) bool, F; ``distance`` (H, W) float32 pixels, D truncated at r;
- ``gain_class`` (H, W) int64 in [0, K - 1];
- ``discontinuity`` (H, W) bool, F_d (for the baseline of the evaluation).

Labels are recomputed at the training resolution rather than interpolated: D is a distance
in *pixels* (truncated at r = 10 px), so a 480 px dataset view resized to the public model's
320 px input gets F resampled (a low-resolution pixel is in F when a full-resolution F pixel
falls in it), then D by an exact distance transform, then the gain band (D < r takes the gain
of its nearest F pixel, as in datagen). Crops and flips keep D and the gain band consistent
(a crop keeps pixel scale; D near a crop border still counts F outside it).
"""

from __future__ import annotations

import cv2
import numpy as np

from datagen.labels import distance_field, gain_classes
from frontiernet.model import invalid_to_zero


def _scatter_indices(shape: tuple[int, int], size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Row and column of the (size) pixel that each (shape) pixel's centre falls in."""
    rows = np.minimum(((np.arange(shape[0]) + 0.5) * size[0] / shape[0]).astype(np.int64), size[0] - 1)
    cols = np.minimum(((np.arange(shape[1]) + 0.5) * size[1] / shape[1]).astype(np.int64), size[1] - 1)
    return rows, cols


def resample_mask(mask: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(H', W') bool: a pixel is set when a set (H, W) pixel's centre falls inside it."""
    rows, cols = _scatter_indices(mask.shape, size)
    out = np.zeros(size, bool)
    v, u = np.nonzero(mask)
    out[rows[v], cols[u]] = True
    return out


def training_sample(sample: dict, size: int | None, labels_conf) -> dict:
    """A training sample (module docstring) at ``size x size`` from a dataset sample.

    Args:
        sample: ``datagen.open_dataset(...)[i]``.
        size: training resolution (None: the dataset's own).
        labels_conf: ``labels`` section of ``configs/model.yaml`` (r, K, bin edges).
    """
    r = float(labels_conf["truncation_px"])
    rgb, depth = sample["rgb"], invalid_to_zero(sample["depth"])
    far = sample.get("far_depth")
    far = np.zeros_like(depth) if far is None else invalid_to_zero(far)
    frontier, gain = sample["frontier_mask"], sample["gain"]
    discontinuity = sample["discontinuity"]
    height, width = depth.shape
    if size is not None and (height, width) != (size, size):
        target = (int(size), int(size))
        rows, cols = _scatter_indices((height, width), target)
        v, u = np.nonzero(frontier)
        frontier_gain = np.zeros(target, np.float32)
        np.maximum.at(frontier_gain, (rows[v], cols[u]), gain[v, u])
        frontier = resample_mask(frontier, target)
        discontinuity = resample_mask(discontinuity, target)
        rgb = cv2.resize(rgb, target[::-1], interpolation=cv2.INTER_AREA)
        depth = cv2.resize(depth, target[::-1], interpolation=cv2.INTER_NEAREST)
        far = cv2.resize(far, target[::-1], interpolation=cv2.INTER_NEAREST)
        distance, nearest = distance_field(frontier, r, return_nearest=True)
        band_gain = np.where(distance < r, frontier_gain[nearest[0], nearest[1]], 0.0)
        gain_class = gain_classes(band_gain, list(labels_conf["bin_edges"]), float(labels_conf["bin_unit_m3"]))
    else:
        distance = distance_field(frontier, r)
        gain_class = sample["gain_class"].astype(np.int64)
    return {"rgb": np.ascontiguousarray(rgb), "depth": depth.astype(np.float32), "far_depth": far.astype(np.float32),
            "frontier": frontier,
            "distance": distance.astype(np.float32), "gain_class": gain_class, "discontinuity": discontinuity}


JITTER_NAMES = ("brightness", "contrast", "saturation", "gamma", "depth_scale")
"""Per-view augmentation factors, in the order of a training item's ``jitter`` vector."""


def _draw_jitter(conf, rng: np.random.Generator | None) -> np.ndarray:
    """(5,) float32 factors (``JITTER_NAMES``): photometric ones uniform in ``[1 - a, 1 + a]`` for
    ``a = conf.<name>``, the depth prior's global scale ``exp(N(0, conf.depth_scale_sigma))``
    (a monocular model's scale error); all 1 without augmentation."""
    factors = np.ones(len(JITTER_NAMES), np.float32)
    if rng is None:
        return factors
    for i, name in enumerate(JITTER_NAMES[:4]):
        amount = float(conf[name])
        factors[i] = rng.uniform(1.0 - amount, 1.0 + amount) if amount > 0 else 1.0
    factors[4] = np.exp(rng.normal(0.0, float(conf["depth_scale_sigma"])))
    return factors


def training_item(view: dict, augment_conf=None, rng: np.random.Generator | None = None,
                  depth_source=None) -> dict:
    """One loader item from a view's cache arrays (``train.cache.pack_sample`` layout, full size).

    With `rng` (training): a random ``augment_conf.crop_size`` window (pixel scale kept: D near a
    crop border still counts F outside it), a horizontal flip with probability
    ``augment_conf.hflip`` (both heads' labels flip with the image), and the view's jitter factors;
    the per-pixel part of the augmentation runs batched on the training device
    (:func:`network_batch`). `view` may hold memory-mapped arrays: only the window is read.
    `depth_source` (``frontiernet.depth``, e.g. emulated monocular depth) replaces the depth prior of
    the window (labels stay the scene's); a source that ``sees_past_range`` (as a monocular network
    does) is given the view's far depth too, as the explorer gives it ``Frame.hit_depth``.

    Returns a dict of tensors (h, w = the window): ``rgb`` (3, h, w) uint8, ``depth`` (h, w) float32
    metres (0 invalid), ``distance_sq``, ``gain_class``, ``masks`` (h, w) uint8 (cache encoding),
    ``jitter`` (5,) float32.
    """
    import torch

    height, width = view["depth_mm"].shape
    rows, cols, flip = slice(None), slice(None), False
    if rng is not None:
        crop = augment_conf["crop_size"]
        if crop and int(crop) < min(height, width):
            crop = int(crop)
            top, left = int(rng.integers(0, height - crop + 1)), int(rng.integers(0, width - crop + 1))
            rows, cols = slice(top, top + crop), slice(left, left + crop)
        flip = bool(rng.random() < float(augment_conf["hflip"]))

    def window(array: np.ndarray) -> np.ndarray:  # a copy: `array` may be a read-only memory map
        part = array[rows, cols]
        return np.array(part[:, ::-1] if flip else part, order="C")

    rgb = window(view["rgb"])
    depth = window(view["depth_mm"]).astype(np.float32) * np.float32(1e-3)
    if depth_source is not None:
        truth = depth
        if depth_source.sees_past_range:
            truth = np.maximum(depth, window(view["far_depth_mm"]).astype(np.float32) * np.float32(1e-3))
        estimate = depth_source.estimate(rgb, None, np.where(truth > 0, truth, np.nan))
        depth = invalid_to_zero(estimate)
    item = {"rgb": np.ascontiguousarray(rgb.transpose(2, 0, 1)), "depth": depth,
            "distance_sq": window(view["distance_sq"]), "gain_class": window(view["gain_class"]),
            "masks": window(view["masks"]), "jitter": _draw_jitter(augment_conf, rng)}
    return {key: torch.from_numpy(value) for key, value in item.items()}


def network_batch(batch: dict, model_conf, augment_conf=None) -> dict:
    """The training batch of a collated batch of :func:`training_item`, on the batch's device.

    Augmentation (with `augment_conf`): each view's brightness, contrast, saturation and gamma
    factors on its RGB in [0, 1] (clipped before the gamma), its depth-prior scale, and
    multiplicative per-pixel depth noise ``N(0, augment_conf.depth_noise_sigma)`` drawn from torch's
    generator (seeded by ``seed_everything``); a share ``augment_conf.no_depth_fraction`` of the
    views gets no depth prior at all (every pixel 0, as a camera without depth gives). Then the
    network's normalisation (``frontiernet.model.normalise_images``).

    Returns ``image`` (B, C, h, w) float32, ``distance`` (B, h, w) float32 px, ``gain_class``
    (B, h, w) int64, ``frontier`` and ``discontinuity`` (B, h, w) bool, ``depth`` (B, h, w) float32
    metres before jitter (the F_d baseline of the metrics reads it).
    """
    import torch

    from frontiernet.model import normalise_images

    from .packed import DISCONTINUITY_BIT, FRONTIER_BIT, unpack_distance

    inputs = model_conf["network"]["inputs"]
    rgb = batch["rgb"].float().div_(255.0)  # a new tensor: the in-place steps below touch no input
    depth = batch["depth"].float()
    prior = depth
    if augment_conf is not None:
        factor = batch["jitter"].float()[:, :, None, None, None]  # (B, 5, 1, 1, 1)
        rgb.mul_(factor[:, 0])
        mean = rgb.mean(dim=(1, 2, 3), keepdim=True)
        rgb.sub_(mean).mul_(factor[:, 1]).add_(mean)
        grey = rgb.mean(dim=1, keepdim=True)
        rgb.sub_(grey).mul_(factor[:, 2]).add_(grey)
        rgb.clamp_(0.0, 1.0).pow_(factor[:, 3])
        prior = depth * factor[:, 4, 0]
        sigma = float(augment_conf["depth_noise_sigma"])
        if sigma > 0:
            prior.mul_(torch.randn_like(prior).mul_(sigma).add_(1.0))
        prior.masked_fill_(depth <= 0, 0.0)
        withheld = float(augment_conf["no_depth_fraction"])
        if withheld > 0:  # these views' prior is all "no return": the network learns to read RGB alone
            prior.mul_((torch.rand(len(prior), device=prior.device) >= withheld)[:, None, None])
    masks = batch["masks"]
    return {"image": normalise_images(rgb, prior, inputs, model_conf["input"]),
            "distance": unpack_distance(batch["distance_sq"], float(model_conf["labels"]["truncation_px"])),
            "gain_class": batch["gain_class"].long(), "frontier": (masks & FRONTIER_BIT) > 0,
            "discontinuity": (masks & DISCONTINUITY_BIT) > 0, "depth": depth}

"""Training samples: labels at the training resolution, crops, flips, photometric jitter.

A *training sample* is a dict of numpy arrays of one size (H, W):

- ``rgb`` (H, W, 3) uint8; ``depth`` (H, W) float32 metres, 0 = invalid (NaN mapped to 0);
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
        distance, nearest = distance_field(frontier, r, return_nearest=True)
        band_gain = np.where(distance < r, frontier_gain[nearest[0], nearest[1]], 0.0)
        gain_class = gain_classes(band_gain, list(labels_conf["bin_edges"]), float(labels_conf["bin_unit_m3"]))
    else:
        distance = distance_field(frontier, r)
        gain_class = sample["gain_class"].astype(np.int64)
    return {"rgb": np.ascontiguousarray(rgb), "depth": depth.astype(np.float32), "frontier": frontier,
            "distance": distance.astype(np.float32), "gain_class": gain_class, "discontinuity": discontinuity}


def random_crop(sample: dict, crop: int, rng: np.random.Generator) -> dict:
    """The same random ``crop x crop`` window of every array of a training sample."""
    height, width = sample["depth"].shape
    if crop >= min(height, width):
        return sample
    top, left = int(rng.integers(0, height - crop + 1)), int(rng.integers(0, width - crop + 1))
    return {key: np.ascontiguousarray(value[top:top + crop, left:left + crop]) for key, value in sample.items()}


def horizontal_flip(sample: dict) -> dict:
    """Mirror every array left-right (both heads' labels flip with the image)."""
    return {key: np.ascontiguousarray(value[:, ::-1]) for key, value in sample.items()}


def photometric(rgb: np.ndarray, conf, rng: np.random.Generator) -> np.ndarray:
    """Brightness, contrast, saturation and gamma jitter of an (H, W, 3) uint8 image.

    Each factor is drawn uniformly in ``[1 - a, 1 + a]`` for ``a = conf.<name>``; labels are
    unchanged (they depend on geometry only).
    """
    image = rgb.astype(np.float32) / 255.0

    def factor(amount: float) -> float:
        return float(rng.uniform(1.0 - amount, 1.0 + amount)) if amount > 0 else 1.0

    image = image * factor(float(conf["brightness"]))
    mean = image.mean()
    image = (image - mean) * factor(float(conf["contrast"])) + mean
    grey = image.mean(axis=2, keepdims=True)
    image = (image - grey) * factor(float(conf["saturation"])) + grey
    image = np.clip(image, 0.0, 1.0) ** factor(float(conf["gamma"]))
    return (image * 255.0 + 0.5).astype(np.uint8)


def depth_jitter(depth: np.ndarray, conf, rng: np.random.Generator) -> np.ndarray:
    """A depth prior as a monocular model would give it: a global log-normal scale error and
    multiplicative per-pixel noise (``conf.depth_scale_sigma``, ``conf.depth_noise_sigma``)."""
    valid = depth > 0
    scale = float(np.exp(rng.normal(0.0, float(conf["depth_scale_sigma"]))))
    noise_sigma = float(conf["depth_noise_sigma"])
    noise = 1.0 + rng.normal(0.0, noise_sigma, depth.shape).astype(np.float32) if noise_sigma > 0 else 1.0
    return np.where(valid, depth * scale * noise, 0.0).astype(np.float32)


def augment(sample: dict, conf, rng: np.random.Generator) -> dict:
    """Crop, flip, photometric and depth jitter of a training sample (``train.yaml: augment``).

    The depth before jitter is kept as ``clean_depth`` (the F_d baseline of the metrics uses it)."""
    if conf["crop_size"]:
        sample = random_crop(sample, int(conf["crop_size"]), rng)
    if rng.random() < float(conf["hflip"]):
        sample = horizontal_flip(sample)
    sample = dict(sample)
    sample["rgb"] = photometric(sample["rgb"], conf, rng)
    sample["clean_depth"] = sample["depth"]
    sample["depth"] = depth_jitter(sample["depth"], conf, rng)
    return sample

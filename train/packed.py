"""The packed training record: one view's inputs and labels at the training size as six small
arrays (the training cache's rows, :mod:`train.cache`; what the loaders deliver and
:func:`train.transforms.network_batch` unpacks on the device).

``rgb`` (S, S, 3) uint8; ``depth_mm`` (S, S) uint16 millimetres, 0 = invalid; ``far_depth_mm``
(S, S) uint16 millimetres of surfaces beyond the sensor's range, 0 elsewhere; ``distance_sq``
(S, S) uint8, D^2 in px^2 below the truncation r and :data:`TRUNCATED` where D = r (D is a
distance between pixel centres, so D^2 < r^2 is an integer: exact); ``gain_class`` (S, S) uint8;
``masks`` (S, S) uint8, :data:`FRONTIER_BIT` F and :data:`DISCONTINUITY_BIT` F_d.
"""

from __future__ import annotations

import numpy as np

TRUNCATED = 255
"""``distance_sq`` value of a pixel at the truncation distance (D = r)."""
FRONTIER_BIT, DISCONTINUITY_BIT = 1, 2


def array_specs(size: int) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """Per-view shape and dtype of each packed array at training size `size`."""
    return {"rgb": ((size, size, 3), np.dtype(np.uint8)), "depth_mm": ((size, size), np.dtype(np.uint16)),
            "far_depth_mm": ((size, size), np.dtype(np.uint16)),
            "distance_sq": ((size, size), np.dtype(np.uint8)), "gain_class": ((size, size), np.dtype(np.uint8)),
            "masks": ((size, size), np.dtype(np.uint8))}


def pack_sample(sample: dict, truncation_px: float) -> dict[str, np.ndarray]:
    """The packed arrays (module docstring) of one training sample (``train.transforms.training_sample``)."""
    distance = sample["distance"]
    distance_sq = np.where(distance >= truncation_px, TRUNCATED, np.rint(np.square(distance)))
    masks = sample["frontier"].astype(np.uint8) * FRONTIER_BIT | sample["discontinuity"].astype(np.uint8) * DISCONTINUITY_BIT
    return {"rgb": sample["rgb"], "depth_mm": millimetres(sample["depth"]), "far_depth_mm": millimetres(sample["far_depth"]),
            "distance_sq": distance_sq.astype(np.uint8), "gain_class": sample["gain_class"].astype(np.uint8),
            "masks": masks}


def millimetres(depth: np.ndarray) -> np.ndarray:
    """(S, S) uint16 millimetres (clipped to 65.535 m) of float metres, 0 = invalid."""
    return np.rint(depth * 1000.0).clip(0, 65535).astype(np.uint16)


def unpack_distance(distance_sq, truncation_px: float):
    """D in pixels (float32, numpy array or torch tensor) from ``distance_sq`` values."""
    if isinstance(distance_sq, np.ndarray):
        distance = np.sqrt(distance_sq.astype(np.float32))
        return np.where(distance_sq == TRUNCATED, np.float32(truncation_px), distance)
    distance = distance_sq.float().sqrt()
    return distance.masked_fill(distance_sq == TRUNCATED, float(truncation_px))

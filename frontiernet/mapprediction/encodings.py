"""The two encodings of an :class:`~frontiernet.mapping.OccupancyMap` that the predictors read, and of
the ground truth they learn.

Voxel states are :data:`~frontiernet.mapping.UNKNOWN` (0), :data:`~frontiernet.mapping.FREE` (1) and
:data:`~frontiernet.mapping.OCCUPIED` (2), as :meth:`OccupancyMap.state_at` returns them. Grids are
indexed (x, y, z) as the map's (``origin + index * voxel_size`` is a voxel's corner, metres).

* **Crop** (SEER, tyuezhan/SEER ``frontier_finder.cpp`` ``predOnFrontiers``): an ``(X, Y, Z)`` box of
  voxels centred on a frontier cluster in x and y and standing on the floor in z (SEER's box spans
  z = 0 .. Z * resolution), voxels off the map unknown (SEER fills them with the map default).
  The network reads it one-hot: ``(3, X, Y, Z)`` float32, channels unknown, free, occupied
  (:func:`crop_input`; SEER feeds one channel with UNKNOWN = -1, FREE = 0, OCC = 1).
* **Top-down** (MapEx, castacks/MapEx ``lama_pred_utils.py``): the map's columns over a height band
  around the camera (the planner's band, ``OccupancyMap.slice_2d``'s rule: occupied when a band voxel
  is occupied, free when all are free, else unknown) as an occupancy probability, 0 free, 0.5 unknown,
  1 occupied (MapEx's observed map); the network reads it with its unknown mask, ``(2, X, Y)``
  (:func:`topdown_input`; LaMa's image and mask).

Labels (:func:`truth_labels`, :func:`topdown_labels`) come from the scene's
:class:`~frontiernet.simulator.voxels.VoxelGrid`: occupied voxels are 1, explorable (free interior)
ones 0, and the rest (outside the building, inside walls) :data:`IGNORE`: neither is space a robot
explores, so neither is scored.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..mapping.bands import band_layers as grid_band_layers
from ..mapping.occupancy import FREE, OCCUPIED, UNKNOWN

LABEL_FREE, LABEL_OCCUPIED, IGNORE = 0, 1, 255
"""Values of the label grids (uint8)."""


def map_states(occupancy) -> np.ndarray:
    """(X, Y, Z) int8 UNKNOWN / FREE / OCCUPIED of every voxel of an :class:`~frontiernet.mapping.OccupancyMap`."""
    return states_from_masks(occupancy.observed, occupancy.occupied_mask())


def states_from_masks(observed: np.ndarray, occupied: np.ndarray) -> np.ndarray:
    """States from (..., ) bool `observed` and `occupied` (occupied counts only where observed)."""
    observed = np.asarray(observed, bool)
    states = np.where(observed, FREE, UNKNOWN).astype(np.int8)
    states[observed & np.asarray(occupied, bool)] = OCCUPIED
    return states


# --------------------------------------------------------------------------- crops (SEER)

def crop_corner(origin, voxel_size: float, centre, crop_shape, floor_z: float | None = None) -> np.ndarray:
    """(3,) int64 voxel index of the crop's lowest corner: the crop's x and y centred on `centre`
    ((2,) or (3,) world metres; its z is not read), its z starting at the layer of `floor_z` (None:
    the grid's bottom layer)."""
    origin = np.asarray(origin, np.float64)
    centre = np.asarray(centre, np.float64).reshape(-1)
    if centre.size < 2 or not np.all(np.isfinite(centre[:2])):
        raise InputError(f"a crop centre must be a finite world point (x, y[, z]), got {centre.tolist()}")
    shape = np.asarray(crop_shape, np.int64)
    xy = np.floor((centre[:2] - origin[:2]) / voxel_size).astype(np.int64) - shape[:2] // 2
    k = 0 if floor_z is None else int(np.floor((float(floor_z) - origin[2]) / voxel_size + 0.5))
    return np.array([xy[0], xy[1], k], np.int64)


def take_crop(grid: np.ndarray, corner, crop_shape, fill) -> np.ndarray:
    """The ``crop_shape`` box of (X, Y, Z) `grid` from voxel index `corner`; cells off the grid get `fill`."""
    shape = tuple(int(n) for n in crop_shape)
    out = np.full(shape, fill, grid.dtype)
    corner = np.asarray(corner, np.int64)
    lo = np.maximum(corner, 0)
    hi = np.minimum(corner + np.asarray(shape), np.asarray(grid.shape))
    if np.all(hi > lo):
        inside = tuple(slice(a, b) for a, b in zip(lo, hi))
        out[tuple(slice(a - c, b - c) for a, b, c in zip(lo, hi, corner))] = grid[inside]
    return out


def crop_states(occupancy, centre, crop_shape, floor_z: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(crop (X, Y, Z) int8 states, (3,) int64 corner index) of a map around `centre` (see
    :func:`crop_corner`); only the crop's box of the map is read."""
    corner = crop_corner(occupancy.origin, occupancy.voxel_size, centre, crop_shape, floor_z)
    shape = np.asarray(crop_shape, np.int64)
    lo = np.clip(corner, 0, occupancy.shape)
    hi = np.clip(corner + shape, 0, occupancy.shape)
    box = tuple(slice(a, b) for a, b in zip(lo, hi))
    window = states_from_masks(occupancy.observed[box],
                               occupancy.log_odds[box] > occupancy.settings.occupied_threshold)
    out = np.full(tuple(shape), UNKNOWN, np.int8)
    if np.all(hi > lo):
        out[tuple(slice(a - c, b - c) for a, b, c in zip(lo, hi, corner))] = window
    return out, corner


def crop_input(states: np.ndarray) -> np.ndarray:
    """(..., X, Y, Z) int8 states -> (..., 3, X, Y, Z) float32 one-hot (unknown, free, occupied)."""
    states = np.asarray(states)
    return np.stack([states == UNKNOWN, states == FREE, states == OCCUPIED], axis=-4).astype(np.float32)


def decode_crop_input(one_hot: np.ndarray) -> np.ndarray:
    """Inverse of :func:`crop_input`: (..., 3, X, Y, Z) one-hot -> (..., X, Y, Z) int8 states."""
    codes = np.array([UNKNOWN, FREE, OCCUPIED], np.int8)
    return codes[np.argmax(np.asarray(one_hot), axis=-4)]


# --------------------------------------------------------------------------- top-down (MapEx)

def band_layers(origin_z: float, voxel_size: float, layers: int, z: float, band_m: float) -> tuple[int, int]:
    """Voxel layer range [k0, k1) of the band ``z +- band_m`` (world metres): the layers overlapping it,
    at least the one holding its bottom, clipped to the grid; the rule of ``OccupancyMap.slice_2d``."""
    return grid_band_layers(origin_z, voxel_size, layers, float(z) - float(band_m), float(z) + float(band_m))


def topdown_states(states: np.ndarray, k0: int, k1: int) -> np.ndarray:
    """(X, Y) int8 states of the columns of (X, Y, Z) `states` over layers [k0, k1): occupied when one
    of them is occupied, free when all are free, else unknown (``OccupancyMap.slice_2d``'s rule)."""
    band = np.asarray(states)[:, :, k0:k1]
    out = np.full(band.shape[:2], UNKNOWN, np.int8)
    if band.shape[2] == 0:
        return out
    out[np.all(band == FREE, axis=2)] = FREE
    out[np.any(band == OCCUPIED, axis=2)] = OCCUPIED
    return out


def map_topdown_states(occupancy, z: float, band_m: float) -> np.ndarray:
    """(X, Y) int8 top-down states of a map at camera height `z` (``slice_2d(z - band_m, z + band_m)``)."""
    free, occupied = occupancy.slice_2d(float(z) - float(band_m), float(z) + float(band_m))
    out = np.where(free, FREE, UNKNOWN).astype(np.int8)
    out[occupied] = OCCUPIED
    return out


def topdown_probability(states2d: np.ndarray) -> np.ndarray:
    """(X, Y) int8 states -> (X, Y) float32 occupancy probability: 0 free, 0.5 unknown, 1 occupied."""
    states2d = np.asarray(states2d)
    probability = np.full(states2d.shape, 0.5, np.float32)
    probability[states2d == FREE] = 0.0
    probability[states2d == OCCUPIED] = 1.0
    return probability


def probability_states(probability: np.ndarray) -> np.ndarray:
    """Inverse of :func:`topdown_probability` (below 0.25 free, above 0.75 occupied, else unknown)."""
    probability = np.asarray(probability, np.float32)
    out = np.full(probability.shape, UNKNOWN, np.int8)
    out[probability < 0.25] = FREE
    out[probability > 0.75] = OCCUPIED
    return out


def topdown_input(probability: np.ndarray) -> np.ndarray:
    """(..., X, Y) probability -> (..., 2, X, Y) float32: the probability and its unknown mask."""
    probability = np.asarray(probability, np.float32)
    unknown = ((probability > 0.25) & (probability < 0.75)).astype(np.float32)
    return np.stack([probability, unknown], axis=-3)


# --------------------------------------------------------------------------- labels

def truth_labels(occupied: np.ndarray, explorable: np.ndarray) -> np.ndarray:
    """(X, Y, Z) uint8 labels from a VoxelGrid's `occupied` and `explorable`: 1, 0, else IGNORE."""
    labels = np.full(np.shape(occupied), IGNORE, np.uint8)
    labels[np.asarray(explorable, bool)] = LABEL_FREE
    labels[np.asarray(occupied, bool)] = LABEL_OCCUPIED
    return labels


def topdown_labels(labels: np.ndarray, k0: int, k1: int) -> np.ndarray:
    """(X, Y) uint8 labels of the columns over layers [k0, k1) of (X, Y, Z) `labels`: occupied when
    one of them is occupied, else free when one is free (explorable), else IGNORE."""
    band = np.asarray(labels)[:, :, k0:k1]
    out = np.full(band.shape[:2], IGNORE, np.uint8)
    if band.shape[2] == 0:
        return out
    out[np.any(band == LABEL_FREE, axis=2)] = LABEL_FREE
    out[np.any(band == LABEL_OCCUPIED, axis=2)] = LABEL_OCCUPIED
    return out


__all__ = ["IGNORE", "LABEL_FREE", "LABEL_OCCUPIED", "band_layers", "crop_corner", "crop_input", "crop_states",
           "decode_crop_input", "map_states", "map_topdown_states", "probability_states", "states_from_masks",
           "take_crop", "topdown_input", "topdown_labels", "topdown_probability", "topdown_states", "truth_labels"]

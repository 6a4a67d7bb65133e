"""How good a map prediction is: where it is scored, the two simple predictions it must beat, the scores.

**Where** (:func:`near_frontier`): the unknown cells (voxels) within ``radius_m`` (3 m) of a frontier,
whose truth is occupied or free (labels other than :data:`~.encodings.IGNORE`). Frontier cells are the
free cells with an unknown 4-neighbour (2D: the top-down map, as
:func:`~frontiernet.frontiers.map_frontiers.frontier_cells` finds them) or 6-neighbour (3D: a crop);
cells off the grid are not unknown. The distance is Euclidean between cell centres.

**The simple predictions** of the unknown cells (known cells keep their state):

* :func:`predict_free`: unknown = free.
* :func:`predict_wall`, *continue the nearest wall*: an unknown cell is occupied when, walking from it
  along one of the four horizontal axis directions (+x, -x, +y, -y), the first known cell is occupied,
  lies at most ``reach_m`` away, and starts a run of at least ``run_cells`` occupied cells further
  along that direction: the cell lies on the straight continuation of a wall that runs along that
  axis and ends facing it (a wall seen end-on, not the face of a wall across the way, which is
  thinner than the run). Every other unknown cell is free. In 3D the rule applies within each
  horizontal layer (walls are vertical; the floor continues as the floor).

**Scores** (:func:`confusion`, :func:`scores`): over the scored cells, occupied is the positive class:
accuracy, IoU of occupied (TP / (TP + FP + FN)), IoU of free, and their mean (mIoU).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..errors import InputError
from ..frontiers.map_frontiers import frontier_cells
from ..mapping.occupancy import FREE, OCCUPIED, UNKNOWN
from .encodings import IGNORE, LABEL_OCCUPIED

SCORE_NAMES = ("accuracy", "iou_occupied", "iou_free", "miou")


def frontier_mask(states: np.ndarray) -> np.ndarray:
    """Bool mask of the frontier cells of (X, Y) or (X, Y, Z) int8 `states`: free cells with an unknown
    4- (2D) or 6-neighbour (3D); cells off the grid are not unknown."""
    states = np.asarray(states)
    if states.ndim == 2:
        return frontier_cells(states == FREE, states == OCCUPIED)[0]
    if states.ndim != 3:
        raise InputError(f"states must be a 2D or 3D grid, got shape {states.shape}")
    unknown = np.pad(states == UNKNOWN, 1, constant_values=False)
    X, Y, Z = states.shape
    beside = np.zeros(states.shape, bool)
    for axis in range(3):
        for step in (-1, 1):
            index = [slice(1, 1 + n) for n in (X, Y, Z)]
            index[axis] = slice(1 + step, 1 + step + states.shape[axis])
            beside |= unknown[tuple(index)]
    return (states == FREE) & beside


def near_frontier(states: np.ndarray, voxel_size: float, radius_m: float = 3.0,
                  labels: np.ndarray | None = None) -> np.ndarray:
    """Bool mask of the scored cells: unknown, within `radius_m` of a frontier cell (:func:`frontier_mask`)
    and, when `labels` is given, with a label other than IGNORE."""
    states = np.asarray(states)
    frontier = frontier_mask(states)
    if not frontier.any():
        return np.zeros(states.shape, bool)
    distance = ndimage.distance_transform_edt(~frontier, sampling=float(voxel_size))
    mask = (states == UNKNOWN) & (distance <= float(radius_m) + 1e-9)
    if labels is not None:
        mask &= np.asarray(labels) != IGNORE
    return mask


def predict_free(states: np.ndarray) -> np.ndarray:
    """Bool occupancy of "unknown = free": the known occupied cells, nothing else."""
    return np.asarray(states) == OCCUPIED


def _next_index(flags: np.ndarray) -> np.ndarray:
    """For each cell along the last axis, the index of the first cell at or after it where `flags`
    holds (the axis length where none does)."""
    n = flags.shape[-1]
    index = np.where(flags, np.arange(n), n)
    return np.flip(np.minimum.accumulate(np.flip(index, axis=-1), axis=-1), axis=-1)


def _wall_along_last_axis(states: np.ndarray, reach: int, run: int) -> np.ndarray:
    """:func:`predict_wall`'s rule for the walk towards increasing index along the last axis."""
    n = states.shape[-1]
    known = states != UNKNOWN
    first_known = _next_index(known)  # the walk's first known cell
    run_length = _next_index(states != OCCUPIED) - np.arange(n)  # occupied cells from each cell on
    padded = np.concatenate([run_length, np.zeros(states.shape[:-1] + (1,), run_length.dtype)], axis=-1)
    run_there = np.take_along_axis(padded, np.minimum(first_known, n), axis=-1)
    return (~known) & (first_known < n) & (first_known - np.arange(n) <= reach) & (run_there >= run)


def predict_wall(states: np.ndarray, voxel_size: float, reach_m: float = 3.0, run_cells: int = 5) -> np.ndarray:
    """Bool occupancy of "unknown = continue the nearest wall" (module docstring) for (X, Y) or (X, Y, Z)
    int8 `states`: the known occupied cells and the unknown cells on a wall's continuation."""
    states = np.asarray(states)
    if states.ndim not in (2, 3):
        raise InputError(f"states must be a 2D or 3D grid, got shape {states.shape}")
    reach = int(np.floor(float(reach_m) / float(voxel_size) + 1e-9))
    occupied = states == OCCUPIED
    for axis in (0, 1):
        moved = np.moveaxis(states, axis, -1)
        for flip in (False, True):
            walk = np.flip(moved, axis=-1) if flip else moved
            found = _wall_along_last_axis(walk, reach, int(run_cells))
            found = np.flip(found, axis=-1) if flip else found
            occupied |= np.moveaxis(found, -1, axis)
    return occupied


def confusion(predicted_occupied: np.ndarray, labels: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(4,) int64 counts TP, FP, FN, TN of occupied over the cells of `mask` (labels 1 occupied, 0 free)."""
    mask = np.asarray(mask, bool)
    truth = np.asarray(labels)[mask] == LABEL_OCCUPIED
    guess = np.asarray(predicted_occupied, bool)[mask]
    return np.array([np.sum(guess & truth), np.sum(guess & ~truth), np.sum(~guess & truth),
                     np.sum(~guess & ~truth)], np.int64)


def scores(counts) -> dict:
    """Accuracy, IoU of occupied and of free and their mean from (4,) TP, FP, FN, TN counts (NaN where
    a denominator is 0), and the number of cells scored."""
    tp, fp, fn, tn = (int(c) for c in counts)
    total = tp + fp + fn + tn

    def ratio(a: int, b: int) -> float:
        return a / b if b else float("nan")

    occupied, free = ratio(tp, tp + fp + fn), ratio(tn, tn + fn + fp)
    return {"accuracy": ratio(tp + tn, total), "iou_occupied": occupied, "iou_free": free,
            "miou": float(np.nanmean([occupied, free])) if total else float("nan"), "cells": total}


__all__ = ["SCORE_NAMES", "confusion", "frontier_mask", "near_frontier", "predict_free", "predict_wall", "scores"]

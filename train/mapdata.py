"""Training samples of the map predictors, read from a ``frontiernet mapgen`` dataset
(:class:`datagen.mapshards.MapDataset`; docs/mapprediction.md).

* :class:`CropSamples` (``seer``): per snapshot, the crops around its largest frontier pieces
  (``data.crops_per_snapshot``), each centred on the piece (jittered by up to ``data.jitter_m`` in training).
* :class:`TopdownSamples` (``mapex``): per snapshot, a ``data.topdown_size`` square window of the top-down map
  (in training around a random frontier piece, or anywhere with ``data.anywhere_fraction``; in validation
  around the largest piece).

Both decode a snapshot per sample (a packed procedural map is ~60 kB: ~2 ms), rotate and mirror in x-y in
training (walls have no preferred side), and give ``input`` (the encoding), ``label`` (uint8, 255 ignored),
``known``, ``region`` (where validation scores: unknown cells within ``loss.near_frontier_m`` of a frontier)
and ``members`` (which ensemble members learn from this sample's scene: each member of a MapEx-style
ensemble leaves out a different share of the scenes, as MapEx's ``lama_ensemble/train_1..3`` were trained
on different splits).
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict

import numpy as np
import torch
from torch.utils.data import Dataset

from frontiernet.mapping.occupancy import UNKNOWN
from frontiernet.mapprediction.encodings import (IGNORE, band_layers, crop_corner, crop_input, states_from_masks,
                                                 take_crop, topdown_input, topdown_labels, topdown_probability,
                                                 topdown_states, truth_labels)
from frontiernet.mapprediction.quality import near_frontier


def member_mask(scene: str, members: int, holdout: bool) -> np.ndarray:
    """(members,) bool: the members that learn from `scene` (all, or all but the one its stable hash names)."""
    mask = np.ones(members, bool)
    if holdout and members > 1:
        mask[int(hashlib.sha256(scene.encode()).hexdigest()[:8], 16) % members] = False
    return mask


class _Samples(Dataset):
    """What both kinds share: the dataset, the snapshots used, the labels of a few scenes cached."""

    def __init__(self, dataset, snapshots: list[int], spec, data_conf, train: bool, radius_m: float,
                 holdout: bool) -> None:
        self.dataset, self.spec, self.conf, self.train = dataset, spec, data_conf, train
        self.radius_m, self.holdout = float(radius_m), holdout
        self.snapshot_ids = list(snapshots)
        self._labels: OrderedDict = OrderedDict()

    def labels(self, shard: int) -> np.ndarray:
        if shard not in self._labels:
            if len(self._labels) >= 4:
                self._labels.popitem(last=False)
            self._labels[shard] = truth_labels(*self.dataset.truth(shard))
        return self._labels[shard]

    def states(self, snapshot: int) -> np.ndarray:
        return states_from_masks(*self.dataset.masks(snapshot))

    def members(self, snapshot: int) -> torch.Tensor:
        scene = self.dataset.metas[self.dataset.snapshots[snapshot][0]]["scene"]
        return torch.from_numpy(member_mask(scene, self.spec.members, self.holdout))

    def _augment(self, *grids: np.ndarray) -> list[np.ndarray]:
        """The same random quarter turn and mirrors in x-y for every grid (training only)."""
        if not self.train:
            return list(grids)
        turns = int(torch.randint(0, 4, (1,)))
        if grids[0].shape[0] != grids[0].shape[1]:
            turns = 2 * (turns % 2)  # a quarter turn of a crop longer in x than in y would change its shape
        flip_x, flip_y = (bool(v) for v in torch.randint(0, 2, (2,)).tolist())
        out = []
        for grid in grids:
            grid = np.rot90(grid, turns, axes=(0, 1))
            grid = grid[::-1] if flip_x else grid
            grid = grid[:, ::-1] if flip_y else grid
            out.append(np.ascontiguousarray(grid))
        return out

    def _sample(self, states: np.ndarray, labels: np.ndarray, region: np.ndarray, encoded: np.ndarray,
                snapshot: int) -> dict:
        return {"input": torch.from_numpy(encoded), "label": torch.from_numpy(labels),
                "known": torch.from_numpy(states != UNKNOWN), "region": torch.from_numpy(region),
                "members": self.members(snapshot)}


class CropSamples(_Samples):
    """SEER crops around frontier pieces (module docstring)."""

    def __init__(self, dataset, snapshots, spec, data_conf, train, radius_m, holdout) -> None:
        super().__init__(dataset, snapshots, spec, data_conf, train, radius_m, holdout)
        per = int(data_conf.crops_per_snapshot)
        self.items = []
        for snapshot in self.snapshot_ids:
            record = dataset.snapshots[snapshot][1]
            pieces = sorted(record["frontiers"], key=lambda piece: -piece[2])[:per]
            self.items += [(snapshot, piece[0], piece[1], record["floor_z"]) for piece in pieces]

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, index: int) -> dict:
        snapshot, x, y, floor_z = self.items[index]
        shard = self.dataset.snapshots[snapshot][0]
        meta = self.dataset.metas[shard]
        centre = np.array([x, y], np.float64)
        if self.train and float(self.conf.jitter_m) > 0:
            centre += (torch.rand(2).numpy() * 2 - 1) * float(self.conf.jitter_m)
        corner = crop_corner(meta["origin"], meta["voxel_size"], centre, self.spec.crop_shape, floor_z)
        states = take_crop(self.states(snapshot), corner, self.spec.crop_shape, np.int8(UNKNOWN))
        labels = take_crop(self.labels(shard), corner, self.spec.crop_shape, np.uint8(IGNORE))
        if self.train:  # validation scores its region; training does not need it (an EDT per crop)
            region = np.zeros(states.shape, bool)
        else:
            region = near_frontier(states, meta["voxel_size"], self.radius_m, labels)
        states, labels, region = self._augment(states, labels, region)
        return self._sample(states, labels, region, crop_input(states), snapshot)


class TopdownSamples(_Samples):
    """MapEx top-down windows (module docstring)."""

    def __len__(self) -> int:
        return len(self.snapshot_ids)

    def __getitem__(self, index: int) -> dict:
        snapshot = self.snapshot_ids[index]
        shard, record = self.dataset.snapshots[snapshot]
        meta = self.dataset.metas[shard]
        size, voxel = int(self.conf.topdown_size), float(meta["voxel_size"])
        k0, k1 = band_layers(meta["origin"][2], voxel, meta["shape"][2], record["position"][2], self.spec.band_m)
        states = topdown_states(self.states(snapshot), k0, k1)
        labels = topdown_labels(self.labels(shard), k0, k1)
        pieces = sorted(record["frontiers"], key=lambda piece: -piece[2])
        if self.train and (not pieces or float(torch.rand(1)) < float(self.conf.anywhere_fraction)):
            centre_cell = np.array([int(torch.randint(0, n, (1,))) for n in states.shape])
        else:
            piece = pieces[int(torch.randint(0, len(pieces), (1,)))] if self.train else pieces[0]
            centre_cell = np.floor((np.array(piece[:2]) - np.array(meta["origin"][:2])) / voxel).astype(np.int64)
            if self.train:
                centre_cell += (torch.randint(-size // 4, size // 4 + 1, (2,))).numpy()
        corner = centre_cell - size // 2
        region = near_frontier(states, voxel, self.radius_m, labels)
        states, labels, region = (take_crop(grid, corner, (size, size), fill) for grid, fill in
                                  ((states, np.int8(UNKNOWN)), (labels, np.uint8(IGNORE)), (region, False)))
        states, labels, region = self._augment(states, labels, region)
        return self._sample(states, labels, region, topdown_input(topdown_probability(states)), snapshot)


def make_samples(dataset, snapshots: list[int], spec, conf, train: bool) -> _Samples:
    """The samples of `spec.kind` over `snapshots` (indices into ``dataset.snapshots``)."""
    Samples = CropSamples if spec.kind == "seer" else TopdownSamples
    return Samples(dataset, snapshots, spec, conf.data, train, float(conf.loss.near_frontier_m),
                   bool(conf.predictor.member_holdout))


__all__ = ["CropSamples", "TopdownSamples", "make_samples", "member_mask"]

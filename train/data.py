"""Datasets and the Lightning DataModule over ``datagen.open_dataset``.

The validation split is held out *by scene* (paper: Table II is on validation scenes): no
view of a validation scene is ever trained on.
"""

from __future__ import annotations

from pathlib import Path

import lightning as L
import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset

from datagen import DatasetError, FrontierDataset, open_dataset
from frontiernet.errors import InputError
from frontiernet.model import normalise_batch

from .transforms import augment, training_sample


def split_scenes(scenes: list[str], val_scenes, val_fraction: float, seed: int) -> tuple[list[str], list[str]]:
    """(train, val) scene lists, disjoint.

    Args:
        val_scenes: explicit validation scenes (their specs as the dataset records them), or
            None to draw ``ceil(val_fraction * n)`` scenes with `seed` (at least one, and at
            least one scene is left for training).
    """
    scenes = sorted(scenes)
    if val_scenes:
        unknown = sorted(set(val_scenes) - set(scenes))
        if unknown:
            raise InputError(f"data.val_scenes: {unknown[0]!r} is not a scene of the dataset")
        val = sorted(set(val_scenes))
    else:
        if len(scenes) < 2:
            raise InputError(f"the dataset has {len(scenes)} scene(s); a held-out validation split needs two or more")
        count = min(max(1, int(np.ceil(float(val_fraction) * len(scenes)))), len(scenes) - 1)
        rng = np.random.default_rng(seed)
        val = sorted(rng.choice(scenes, size=count, replace=False).tolist())
    train = [scene for scene in scenes if scene not in set(val)]
    if not train:
        raise InputError("data.val_scenes holds every scene of the dataset; nothing is left to train on")
    return train, val


class TrainingSamples(Dataset):
    """Training samples of a :class:`datagen.FrontierDataset`, labels at ``size``, augmented or not.

    ``samples[i]`` is a dict of tensors: ``image`` (C, H, W) float32 normalised network input,
    ``distance`` (H, W) float32 px, ``gain_class`` (H, W) int64, ``frontier`` (H, W) bool,
    ``depth`` (H, W) float32 metres (0 invalid, before jitter) and ``discontinuity`` (H, W) bool.
    A `depth_source` (``frontiernet.depth``) replaces the rendered depth before anything else, so
    the network and the F_d baseline both see that prior (labels stay those of the scene).
    Augmentation draws from torch's generator (seeded per worker and epoch by the DataLoader,
    and by ``seed_everything`` in the main process), so a seeded run is reproducible.
    """

    def __init__(self, dataset: FrontierDataset, model_conf, size: int | None, augment_conf=None, seed: int = 0,
                 depth_source=None):
        self.dataset, self.model_conf, self.size = dataset, model_conf, size
        self.augment_conf, self.seed, self.depth_source = augment_conf, int(seed), depth_source

    def __len__(self) -> int:
        return len(self.dataset)

    def _emulated(self):
        """The emulated monocular depth source of ``configs/depth.yaml`` (made once per process)."""
        if getattr(self, "_emulated_source", None) is None:
            from frontiernet.config import load_config
            from frontiernet.depth import make_depth_source

            self._emulated_source = make_depth_source("emulated", load_config("depth"))
        return self._emulated_source

    def __getitem__(self, index: int) -> dict:
        sample = self.dataset[index]
        rng = None
        if self.augment_conf is not None:
            rng = np.random.default_rng([self.seed, int(index), int(torch.randint(2**31 - 1, ()))])
        source = self.depth_source
        if source is None and rng is not None and rng.random() < float(self.augment_conf["emulated_depth_fraction"]):
            source = self._emulated()
        if source is not None:  # e.g. emulated monocular depth in place of the rendered one
            source.reset(self.seed * 1_000_003 + int(index) if rng is None else int(rng.integers(2**31)))
            sample["depth"] = source.estimate(sample["rgb"], sample["K"], sample["depth"])
        sample = training_sample(sample, self.size, self.model_conf["labels"])
        clean_depth = sample["depth"]
        if rng is not None:
            sample = augment(sample, self.augment_conf, rng)
            clean_depth = sample.pop("clean_depth", sample["depth"])
        inputs = self.model_conf["network"]["inputs"]
        image = normalise_batch(sample["rgb"][None], sample["depth"][None], inputs, self.model_conf["input"])[0]
        return {"image": torch.from_numpy(image), "distance": torch.from_numpy(sample["distance"]),
                "gain_class": torch.from_numpy(sample["gain_class"]),
                "frontier": torch.from_numpy(sample["frontier"]),
                "depth": torch.from_numpy(np.ascontiguousarray(clean_depth)),
                "discontinuity": torch.from_numpy(sample["discontinuity"])}


def open_training_data(path: str | Path) -> FrontierDataset:
    """``open_dataset`` with errors as :class:`InputError` (missing, empty or corrupt folder)."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: dataset folder not found (make one with `frontiernet datagen`)")
    try:
        dataset = open_dataset(path)
    except DatasetError as error:
        raise InputError(str(error)) from None
    if len(dataset) == 0:
        raise InputError(f"{path}: the dataset holds no samples")
    return dataset


def _limit(dataset: FrontierDataset, limit, seed: int) -> FrontierDataset:
    """At most `limit` samples, spread over the dataset (a fixed, seeded choice)."""
    if not limit or len(dataset) <= int(limit):
        return dataset
    rng = np.random.default_rng(seed)
    return dataset.subset(sorted(rng.choice(len(dataset), size=int(limit), replace=False).tolist()))


class FrontierDataModule(L.LightningDataModule):
    """Train/validation loaders over one dataset folder, split by scene (``train.yaml: data``)."""

    def __init__(self, conf):
        super().__init__()
        self.conf = conf
        self.train_set = self.val_set = None
        self.train_scenes = self.val_scenes = []

    def setup(self, stage: str | None = None) -> None:
        if self.train_set is not None:
            return
        data, seed = self.conf["data"], int(self.conf["seed"])
        dataset = open_training_data(data["path"])
        self.train_scenes, self.val_scenes = split_scenes(dataset.scenes, data["val_scenes"],
                                                          float(data["val_fraction"]), seed)
        train = _limit(dataset.subset(dataset.indices_for_scenes(self.train_scenes)), data["max_train_samples"], seed)
        val = _limit(dataset.subset(dataset.indices_for_scenes(self.val_scenes)), data["max_val_samples"], seed)
        size = data["image_size"]
        self.train_set = TrainingSamples(train, self.conf["model"], size, self.conf["augment"], seed)
        self.val_set = TrainingSamples(val, self.conf["model"], size, None, seed)

    def _loader(self, samples: TrainingSamples, shuffle: bool) -> DataLoader:
        workers = int(self.conf["data"]["num_workers"])
        return DataLoader(samples, batch_size=int(self.conf["data"]["batch_size"]), shuffle=shuffle,
                          num_workers=workers, persistent_workers=workers > 0, drop_last=shuffle,
                          pin_memory=torch.cuda.is_available(), worker_init_fn=_one_thread)

    def train_dataloader(self) -> DataLoader:
        return self._loader(self.train_set, shuffle=True)

    def val_dataloader(self) -> DataLoader:
        return self._loader(self.val_set, shuffle=False)


def _one_thread(worker_id: int) -> None:
    torch.set_num_threads(1)  # loader workers decode PNGs; the model's threads do the maths

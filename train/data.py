"""Training items and the Lightning DataModule over a ``frontiernet datagen`` dataset.

Training reads the dataset's training cache (:mod:`train.cache`, built on first use): loader
workers only copy a crop window and draw the view's augmentation factors
(:func:`train.transforms.training_item`); the per-pixel augmentation and the input normalisation
run batched on the training device (:func:`train.transforms.network_batch`, the DataModule's
``on_after_batch_transfer``). ``data.cache: null`` decodes the dataset on every read instead.

The validation split is held out *by scene* (paper: Table II is on validation scenes): no
view of a validation scene is ever trained on.
"""

from __future__ import annotations

import os
from pathlib import Path

import lightning as L
import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset

from datagen import DatasetError, FrontierDataset, open_dataset
from frontiernet.errors import InputError, cpu_count_option

from .cache import TrainingCache, ensure_cache, existing_cache
from .config import plain
from .packed import pack_sample
from .transforms import network_batch, training_item, training_sample


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
        if not 0.0 < float(val_fraction) < 1.0:  # (1.5 used to hold out all but one scene in silence)
            raise InputError(f"data.val_fraction must lie strictly between 0 and 1, got {val_fraction}")
        count = min(max(1, int(np.ceil(float(val_fraction) * len(scenes)))), len(scenes) - 1)
        rng = np.random.default_rng(seed)
        val = sorted(rng.choice(scenes, size=count, replace=False).tolist())
    train = [scene for scene in scenes if scene not in set(val)]
    if not train:
        raise InputError("data.val_scenes holds every scene of the dataset; nothing is left to train on")
    return train, val


class _Items(Dataset):
    """Shared by both sources of training items: per-view random generator and depth prior.

    Augmentation draws from a generator seeded by (seed, index, a draw of torch's generator), and
    torch's generator is seeded per worker and epoch by the DataLoader (and by ``seed_everything``
    in the main process), so a seeded run is reproducible. With ``augment.emulated_depth_fraction``,
    that fraction of views gets the emulated monocular depth of ``configs/depth.yaml`` as its prior.
    """

    def __init__(self, augment_conf=None, seed: int = 0, depth_source=None):
        self.augment_conf, self.seed, self.depth_source = augment_conf, int(seed), depth_source

    def _emulated(self):
        """The emulated monocular depth source of ``configs/depth.yaml`` (made once per process)."""
        if getattr(self, "_emulated_source", None) is None:
            from frontiernet.config import load_config
            from frontiernet.depth import make_depth_source

            self._emulated_source = make_depth_source("emulated", load_config("depth"))
        return self._emulated_source

    def _item(self, view: dict, index: int) -> dict:
        rng = None
        if self.augment_conf is not None:
            rng = np.random.default_rng([self.seed, int(index), int(torch.randint(2**31 - 1, ()))])
        source = self.depth_source
        if source is None and rng is not None and rng.random() < float(self.augment_conf["emulated_depth_fraction"]):
            source = self._emulated()
        if source is not None:
            source.reset(self.seed * 1_000_003 + int(index) if rng is None else int(rng.integers(2**31)))
        return training_item(view, self.augment_conf, rng, source)


class TrainingSamples(_Items):
    """Training items (:func:`train.transforms.training_item`) decoded from a dataset on every read.

    ``samples[i]``: dataset view i with its labels recomputed at ``size`` (``training_sample``);
    collate, then :func:`train.transforms.network_batch` makes the network's batch. What
    ``frontiernet evaluate`` reads, and training with ``data.cache: null``; training otherwise
    reads :class:`CachedSamples` (the same items, decoded once).
    """

    def __init__(self, dataset: FrontierDataset, model_conf, size: int | None, augment_conf=None, seed: int = 0,
                 depth_source=None):
        super().__init__(augment_conf, seed, depth_source)
        self.dataset, self.model_conf, self.size = dataset, model_conf, size

    def __len__(self) -> int:
        return len(self.dataset)

    def __getitem__(self, index: int) -> dict:
        labels = self.model_conf["labels"]
        sample = training_sample(self.dataset[index], self.size, labels)
        return self._item(pack_sample(sample, float(labels["truncation_px"])), index)


class CachedSamples(_Items):
    """Training items read from a :class:`train.cache.TrainingCache` (views `indices` of it)."""

    def __init__(self, cache: TrainingCache, indices, augment_conf=None, seed: int = 0, depth_source=None):
        super().__init__(augment_conf, seed, depth_source)
        self.cache, self.indices = cache, np.asarray(indices, np.int64)

    def __len__(self) -> int:
        return len(self.indices)

    def __getitem__(self, index: int) -> dict:
        return self._item(self.cache.view(int(self.indices[index])), index)


def open_training_data(path: str | Path) -> FrontierDataset:
    """``open_dataset`` with errors as :class:`InputError` (missing, empty or corrupt folder, or a folder
    that lacks a shard its dataset.json plans: :func:`~datagen.generate.missing_shards`; training and
    evaluating on the rest would drop its views without a word)."""
    from datagen.generate import missing_shards

    path = Path(path)
    if not path.exists() and not path.is_symlink():  # (a link to nothing: open_dataset names it so, not "not found")
        raise InputError(f"{path}: dataset folder not found (make one with `frontiernet datagen`)")
    try:
        dataset = open_dataset(path)
    except DatasetError as error:
        raise InputError(str(error)) from None
    missing = missing_shards(path, dataset.info) if path.is_dir() else []
    if missing:
        raise InputError(f"{path}: shard {missing[0].name} of scene {missing[0].spec} is missing from "
                         f"{path / 'shards'} ({len(missing)} of the shards its dataset.json plans: deleted, or a run "
                         f"that did not finish); make them with the dataset's `frontiernet datagen` command and "
                         f"--resume")
    if len(dataset) == 0:
        raise InputError(f"{path}: the dataset holds no samples")
    return dataset


def gain_bins_mismatch(labels, dataset: FrontierDataset) -> str | None:
    """What differs between the gain classes `labels` (a model's ``labels``: ``bin_edges``, ``bin_unit_m3``)
    defines and those the dataset's views are labelled with (dataset.json ``config.ground_truth.gain``), as
    ``bin edges [1, 50] x 0.01 m^3, the dataset's [1, 50, ...] x 0.01 m^3``; None when they agree or the
    dataset does not record its own. Training and evaluating read the dataset's classes as they are: other
    edges failed at the first validation step (a confusion matrix of the wrong size) or scored other classes."""
    gain = ((dataset.info.get("config") or {}).get("ground_truth") or {}).get("gain") or {}
    if "bin_edges" not in gain:
        return None
    theirs = [float(edge) for edge in gain["bin_edges"]], float(gain.get("bin_unit_m3", labels["bin_unit_m3"]))
    ours = [float(edge) for edge in labels["bin_edges"]], float(labels["bin_unit_m3"])
    if ours == theirs:
        return None
    def text(bins):
        return f"[{', '.join(f'{edge:g}' for edge in bins[0])}] x {bins[1]:g} m^3"
    return f"bin edges {text(ours)}, the dataset's {text(theirs)}"


def _limit(indices: list[int], limit, seed: int) -> list[int]:
    """At most `limit` of `indices`, spread over them (a fixed, seeded choice)."""
    if not limit or len(indices) <= int(limit):
        return list(indices)
    rng = np.random.default_rng(seed)
    return [indices[i] for i in sorted(rng.choice(len(indices), size=int(limit), replace=False).tolist())]


def view_size(dataset: FrontierDataset) -> int:
    """The side of a dataset's (square) views, for ``data.image_size: null``."""
    height, width = (int(dataset.info.get("config", {}).get("camera", {}).get(key, 0)) for key in ("height", "width"))
    if not height:
        first = dataset[0]["depth"].shape
        height, width = first
    if height != width:
        raise InputError(f"data.image_size: null keeps the dataset's {width} x {height} views, but training "
                         f"needs square ones; set data.image_size=PX")
    return height


def worker_count(value, name: str = "data.num_workers") -> int:
    """``data.num_workers`` / ``data.cache_workers`` (`name`): a count from 0 (in the training process)
    to :data:`~frontiernet.errors.PER_CORE` per core, or ``auto`` (the machine's cores, at most 16)."""
    if str(value) == "auto":
        return min(os.cpu_count() or 1, 16)
    try:
        return cpu_count_option(value, name, 0)
    except InputError as error:
        raise InputError(f"{error}; or auto") from None


class FrontierDataModule(L.LightningDataModule):
    """Train/validation loaders over one dataset folder, split by scene (``train.yaml: data``)."""

    def __init__(self, conf, progress: bool = True, dataset=None):
        """`dataset`: the ``data.path`` dataset when the caller has opened it already (None: opened
        by :meth:`setup`)."""
        super().__init__()
        self.conf, self.progress, self.dataset = conf, progress, dataset
        # Plain copies for the per-batch transform: a Ctrl-C landing inside omegaconf's Python
        # __getitem__ while torch.tensor reads a ListConfig surfaced as torch's ValueError ("could
        # not determine the shape of object type 'ListConfig'"), not as KeyboardInterrupt, and the
        # run died without its interrupt checkpoint. Plain lists are read in C, with no Python frame.
        self.batch_confs = plain(conf["model"]), plain(conf["augment"])
        self.train_set = self.val_set = None
        self.train_scenes = self.val_scenes = []

    def split(self) -> tuple[list[int], list[int]]:
        """(training, validation) view indices of the dataset (:func:`split_scenes`, then at most
        ``data.max_*_samples``), its scenes set as ``train_scenes`` and ``val_scenes``: what a run's loop
        settings are judged by before the training cache is built."""
        data, seed = self.conf["data"], int(self.conf["seed"])
        if self.dataset is None:
            self.dataset = open_training_data(data["path"])
        self.train_scenes, self.val_scenes = split_scenes(self.dataset.scenes, data["val_scenes"],
                                                          float(data["val_fraction"]), seed)
        return (_limit(self.dataset.indices_for_scenes(self.train_scenes), data["max_train_samples"], seed),
                _limit(self.dataset.indices_for_scenes(self.val_scenes), data["max_val_samples"], seed))

    def setup(self, stage: str | None = None) -> None:
        if self.train_set is not None:
            return
        data, seed = self.conf["data"], int(self.conf["seed"])
        model_conf, augment_conf = self.conf["model"], self.conf["augment"]
        train, val = self.split()
        dataset = self.dataset
        if not data["cache"]:
            size = data["image_size"]
            self.train_set = TrainingSamples(dataset.subset(train), model_conf, size, augment_conf, seed)
            self.val_set = TrainingSamples(dataset.subset(val), model_conf, size, None, seed)
            return
        cache = open_training_cache(data, model_conf, dataset, self.progress)
        self.train_set = CachedSamples(cache, train, augment_conf, seed)
        self.val_set = CachedSamples(cache, val, None, seed)

    def _loader(self, samples: Dataset, shuffle: bool) -> DataLoader:
        workers = worker_count(self.conf["data"]["num_workers"])
        return DataLoader(samples, batch_size=int(self.conf["data"]["batch_size"]), shuffle=shuffle,
                          num_workers=workers, persistent_workers=workers > 0, drop_last=shuffle,
                          pin_memory=torch.cuda.is_available(), worker_init_fn=_one_thread)

    def train_dataloader(self) -> DataLoader:
        return self._loader(self.train_set, shuffle=True)

    def val_dataloader(self) -> DataLoader:
        return self._loader(self.val_set, shuffle=False)

    def on_after_batch_transfer(self, batch: dict, dataloader_idx: int) -> dict:
        """Augment (training batches only) and normalise on the training device."""
        training = self.trainer is not None and self.trainer.training
        model_conf, augment_conf = self.batch_confs
        return network_batch(batch, model_conf, augment_conf if training else None)


def open_training_cache(data_conf, model_conf, dataset: FrontierDataset, progress: bool = True) -> TrainingCache:
    """The training cache of ``data.path`` at ``data.image_size`` (``data.cache``), built when missing."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    size = int(data_conf["image_size"] or view_size(dataset))
    columns = (TextColumn("training cache"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn())
    with Progress(*columns, transient=True, disable=not progress) as bar:
        task = bar.add_task("cache", total=len(dataset))
        return ensure_cache(data_conf["path"], data_conf["cache"], size, model_conf["labels"],
                            worker_count(data_conf["cache_workers"], "data.cache_workers"),
                            lambda done, total: bar.update(task, completed=done, total=total))


def check_training_cache(data_conf, model_conf, dataset: FrontierDataset) -> None:
    """Before the trainer's setup: InputError naming the file when the training cache that ``data.cache`` names
    (:func:`~train.cache.existing_cache`; none yet: it is built later) is not one of this dataset at this size and
    label encoding (it was opened only after Lightning's lines on stderr)."""
    if data_conf["cache"]:
        existing_cache(data_conf["path"], data_conf["cache"], int(data_conf["image_size"] or view_size(dataset)),
                       model_conf["labels"])


def _one_thread(worker_id: int) -> None:
    torch.set_num_threads(1)  # loader workers copy crops (or decode PNGs); the model's threads do the maths

"""The training cache: a dataset's training samples at the training resolution, decoded once.

A ``frontiernet datagen`` dataset stores 480 px views as PNGs and bit-packed masks in zip
shards; turning one into a 320 px training sample (decode, resample F, exact distance
transform, gain band) costs ~28 ms of a core. The cache does that once per view and keeps the
result as fixed-size arrays in ``.npy`` files, memory-mapped by every loader worker: a training
crop is then a few window copies, no decoding, and the OS page cache shares the bytes between
workers. Plain ``.npy`` needs nothing but numpy on a GPU node and is random-access by index;
streaming formats (WebDataset, LitData) pay off for data on object stores or larger than a node's
disk and memory, which a 15k-view cache (~14 GiB at 320 px) is not.

Layout of a cache folder (``S`` = training size, ``N`` = views of the dataset, in its order)::

    cache.json        format, version, size, labels, the dataset's fingerprint, N, scene per view
    rgb.npy           (N, S, S, 3) uint8
    depth_mm.npy      (N, S, S) uint16 millimetres, 0 = invalid
    far_depth_mm.npy  (N, S, S) uint16 millimetres of surfaces hit beyond the sensor's range, 0
                      elsewhere (all 0 for a dataset without far depth); emulated monocular depth
                      reads it (train/transforms.py:training_item)
    distance_sq.npy   (N, S, S) uint8: D^2 in px^2 below the truncation r, 255 where D = r
                      (D is a distance between pixel centres, so D^2 < r^2 is an integer: exact)
    gain_class.npy    (N, S, S) uint8
    masks.npy         (N, S, S) uint8: bit 0 frontier F, bit 1 depth discontinuity F_d

A cache is built in ``<folder>.partial/`` (resumable: views done so far are recorded in
``progress.npy`` every few seconds) and renamed into place when complete, so a finished folder
is always whole; one process builds at a time (``<folder>.lock``: a second one waits and opens the
first's cache). Opening checks it against its dataset (``dataset.json`` and the shards' names,
sizes and view counts) and the training config (size, label encoding): a mismatch, or a
truncated array, is an :class:`InputError` naming the file; nothing is rebuilt over it.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from datagen.shards import CACHE_DIR
from frontiernet.errors import InputError
from frontiernet.io import write_json

from .packed import TRUNCATED, array_specs, pack_sample

log = logging.getLogger(__name__)

CACHE_FORMAT = "frontiernet-training-cache"
CACHE_VERSION = 2  # 2: far_depth_mm
INFO_NAME = "cache.json"
PROGRESS_NAME = "progress.npy"


def label_encoding(labels_conf) -> dict:
    """The parts of ``model.labels`` that a cache's labels depend on (plain values)."""
    return {"truncation_px": float(labels_conf["truncation_px"]), "num_classes": int(labels_conf["num_classes"]),
            "bin_edges": [float(edge) for edge in labels_conf["bin_edges"]],
            "bin_unit_m3": float(labels_conf["bin_unit_m3"])}


def dataset_fingerprint(root: Path) -> str:
    """SHA-256 of a dataset folder's ``dataset.json`` and its shards' names, sizes and view counts.

    A regenerated dataset changes it (new config or seed, other shards); reading it opens no
    shard's contents beyond what ``open_dataset`` reads anyway."""
    from datagen.dataset import open_dataset

    digest = hashlib.sha256()
    info_file = root / "dataset.json"
    digest.update(info_file.read_bytes() if info_file.is_file() else b"")
    dataset = open_dataset(root)
    views = Counter(record["shard"] for record in dataset.records)
    for shard in dataset.shards:
        digest.update(f"{shard.name}:{shard.stat().st_size}:{views[shard.name]};".encode())
    return digest.hexdigest()


def default_cache_dir(dataset_root: Path, size: int, labels_conf) -> Path:
    """``<dataset>/cache/<S>px-<hash of the label encoding and cache version>``: one cache per size,
    encoding and format (a cache of an older format is left alone, and a new one built beside it)."""
    key_data = {**label_encoding(labels_conf), "version": CACHE_VERSION}
    key = hashlib.sha256(json.dumps(key_data, sort_keys=True).encode()).hexdigest()[:8]
    return Path(dataset_root) / CACHE_DIR / f"{int(size)}px-{key}"


@dataclass
class TrainingCache:
    """An open cache: memory-mapped arrays (read-only) and one scene spec per view."""

    path: Path
    size: int
    labels: dict
    scenes: list[str]
    arrays: dict[str, np.ndarray]

    def __len__(self) -> int:
        return len(self.scenes)

    def view(self, index: int) -> dict[str, np.ndarray]:
        """The cache arrays of view `index` (memory-mapped windows: slicing copies only what it reads)."""
        return {name: array[index] for name, array in self.arrays.items()}

    def __getstate__(self) -> dict:  # loader workers reopen the maps instead of pickling their bytes
        return {**self.__dict__, "arrays": None}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self.arrays = _map_arrays(self.path, self.size, len(self.scenes))


def _map_arrays(path: Path, size: int, count: int, mode: str = "r") -> dict[str, np.ndarray]:
    arrays = {}
    for name, (shape, dtype) in array_specs(size).items():
        file = _cache_file(path / f"{name}.npy", path)
        try:
            array = np.load(file, mmap_mode=mode)
        except FileNotFoundError:
            raise InputError(f"{file}: missing from the training cache (delete {path} to rebuild it)") from None
        except (ValueError, OSError, EOFError) as error:
            raise InputError(f"{file}: truncated or corrupt cache array ({error}); delete {path} to rebuild it") from None
        if array.shape != (count, *shape) or array.dtype != dtype:
            raise InputError(f"{file}: holds {array.shape} {array.dtype}, expected {(count, *shape)} {dtype}; "
                             f"delete {path} to rebuild it")
        arrays[name] = array
    return arrays


def _cache_file(file: Path, path: Path) -> Path:
    """`file` of training cache `path`; InputError naming it when something other than a regular file has its
    name (a pipe's read would wait for ever, a folder's fail inside numpy). FileNotFoundError passes: the
    caller says what a missing file means."""
    if os.path.lexists(file) and not file.is_file():
        raise InputError(f"{file}: {'is a folder' if file.is_dir() else 'not a regular file'}, expected a file of the "
                         f"training cache; delete {path} to rebuild it")
    return file


def _read_info(path: Path) -> dict:
    file = _cache_file(path / INFO_NAME, path)
    try:
        info = json.loads(file.read_text())
    except FileNotFoundError:
        raise InputError(f"{file}: not found ({path} is not a training cache)") from None
    except (OSError, ValueError) as error:
        raise InputError(f"{file}: unreadable ({error})") from None
    if not isinstance(info, dict) or info.get("format") != CACHE_FORMAT:
        raise InputError(f"{file}: not a training cache description")
    if info.get("version") != CACHE_VERSION:
        raise InputError(f"{file}: cache version {info.get('version')}, this code reads {CACHE_VERSION}; "
                         f"delete {path} to rebuild it")
    return info


def open_cache(path: str | Path, dataset_root: str | Path, size: int, labels_conf) -> TrainingCache:
    """Open the cache at `path`, checked against its dataset and the training size and labels."""
    path, dataset_root = Path(path), Path(dataset_root)
    info = _read_info(path)
    file = path / INFO_NAME
    wanted = {"size": int(size), "labels": label_encoding(labels_conf)}
    for key, value in wanted.items():
        if info.get(key) != value:
            raise InputError(f"{file}: built for {key} {info.get(key)}, the config asks for {value} "
                             f"(data.cache names another folder, or delete {path} to rebuild it)")
    if info.get("dataset_fingerprint") != dataset_fingerprint(dataset_root):
        raise InputError(f"{file}: built from another version of the dataset {dataset_root} "
                         f"(it was regenerated or changed); delete {path} to rebuild it")
    scenes = list(info["scenes"])
    return TrainingCache(path, int(size), wanted["labels"], scenes, _map_arrays(path, int(size), len(scenes)))


class _PackedViews:
    """Map-style dataset of ``(index, cache arrays)`` for the views to build (loader workers decode)."""

    def __init__(self, dataset, indices: np.ndarray, size: int, labels_conf):
        self.dataset, self.indices, self.size, self.labels_conf = dataset, indices, size, labels_conf

    def __len__(self) -> int:
        return len(self.indices)

    def __getitem__(self, item: int):
        from .transforms import training_sample

        index = int(self.indices[item])
        sample = training_sample(self.dataset[index], self.size, self.labels_conf)
        return index, pack_sample(sample, float(self.labels_conf["truncation_px"]))


def build_cache(dataset_root: str | Path, path: str | Path, size: int, labels_conf, workers: int = 0,
                progress=None, flush_seconds: float = 5.0) -> TrainingCache:
    """Write the cache of every view of the dataset at `dataset_root` to `path`, then open it.

    Decoding runs in `workers` loader processes (0: in this process); the main process writes.
    An interrupted build resumes from ``<path>.partial`` (views recorded as done are not redone).

    Args:
        size: training resolution S (labels recomputed at S x S, ``training_sample``).
        labels_conf: ``model.labels`` of the training config.
        progress: optional callable ``progress(done, total)``.
    """
    import torch
    from torch.utils.data import DataLoader

    from datagen.dataset import open_dataset

    dataset_root, path, size = Path(dataset_root), Path(path), int(size)
    labels = label_encoding(labels_conf)
    if labels["truncation_px"] ** 2 >= TRUNCATED:
        raise InputError(f"model.labels.truncation_px: {labels['truncation_px']} px is too large for the training "
                         f"cache (D^2 is stored in a byte: at most 15.9 px)")
    dataset = open_dataset(dataset_root)
    count = len(dataset)
    info = {"format": CACHE_FORMAT, "version": CACHE_VERSION, "size": size, "labels": labels,
            "dataset": str(dataset_root.resolve()), "dataset_fingerprint": dataset_fingerprint(dataset_root),
            "num_samples": count, "scenes": [record["scene"] for record in dataset.records]}
    partial = path.with_name(path.name + ".partial")
    arrays, done = _open_partial(partial, info, size, count)
    todo = np.flatnonzero(~done)
    if len(todo) < count:
        log.info("resuming the training cache %s: %d of %d views done", path, count - len(todo), count)
    loader = DataLoader(_PackedViews(dataset, todo, size, labels_conf), batch_size=None, shuffle=False,
                        num_workers=int(workers), worker_init_fn=_one_thread if workers else None)
    last_flush = time.monotonic()
    finished = count - len(todo)
    if progress:
        progress(finished, count)
    threads = torch.get_num_threads()
    try:
        if not workers:
            torch.set_num_threads(1)
        for index, packed in loader:
            for name, array in arrays.items():
                array[index] = packed[name].numpy() if hasattr(packed[name], "numpy") else packed[name]
            done[index] = True
            finished += 1
            if progress:
                progress(finished, count)
            if time.monotonic() - last_flush > flush_seconds:
                _flush(partial, arrays, done)
                last_flush = time.monotonic()
    finally:
        torch.set_num_threads(threads)
        _flush(partial, arrays, done)
    del arrays
    write_json(partial / INFO_NAME, info)
    (partial / PROGRESS_NAME).unlink()
    (partial / "partial.json").unlink()
    if _holds_cache(path):  # a finished cache of the same key appeared meanwhile (another process): keep it
        shutil.rmtree(partial)
    else:
        if path.is_dir():  # an empty folder given as data.cache: the cache takes its place
            path.rmdir()
        os.replace(partial, path)
    return open_cache(path, dataset_root, size, labels_conf)


def _open_partial(partial: Path, info: dict, size: int, count: int) -> tuple[dict, np.ndarray]:
    """The arrays and done flags of a partial build: resumed when it was for the same dataset and
    config, else started afresh (a partial folder is this module's scratch, never a result)."""
    description = partial / "partial.json"
    if partial.is_dir():
        try:
            same = json.loads(_cache_file(description, partial).read_text()) == info
            done = np.load(_cache_file(partial / PROGRESS_NAME, partial))
            arrays = _map_arrays(partial, size, count, mode="r+")
            if same and done.shape == (count,) and done.dtype == bool:
                return arrays, done.copy()
        except (OSError, ValueError, InputError):
            pass
        log.info("%s: an unfinished cache of another dataset or config; starting it again", partial)
        shutil.rmtree(partial)
    partial.mkdir(parents=True)
    arrays = {name: np.lib.format.open_memmap(partial / f"{name}.npy", mode="w+", dtype=dtype, shape=(count, *shape))
              for name, (shape, dtype) in array_specs(size).items()}
    done = np.zeros(count, bool)
    write_json(description, info)
    _flush(partial, arrays, done)
    return arrays, done


def _flush(partial: Path, arrays: dict, done: np.ndarray) -> None:
    """Arrays to disk first, then the done flags (atomically): a flag never claims unwritten bytes."""
    for array in arrays.values():
        array.flush()
    temporary = partial / f"{PROGRESS_NAME}.tmp-{os.getpid()}"
    with open(temporary, "wb") as handle:
        np.save(handle, done)
    os.replace(temporary, partial / PROGRESS_NAME)


def _one_thread(worker_id: int) -> None:
    import torch

    torch.set_num_threads(1)  # each worker decodes one view at a time; processes give the parallelism


def _holds_cache(path: Path) -> bool:
    """Whether `path` is there as something other than an empty folder (an empty one is where a cache is built)."""
    return path.exists() and not (path.is_dir() and not any(path.iterdir()))


def check_cache_folder(cache, path: Path | None = None) -> None:
    """Before anything is made: InputError naming ``data.cache`` when its folder (`cache`, or `path` for
    ``auto``; nothing for null or false, no cache) is a file, or is not there and cannot be made: the
    folder it goes in is missing (a cache is made only in a folder that is there, so a typo makes none)
    or cannot be written in (:func:`~frontiernet.io.check_writable_folder`); or when it is a folder that holds
    files but is no training cache (no readable ``cache.json`` of this format: it was refused only after the
    trainer's setup). An empty folder is taken: the cache is built in it. For ``auto``, the dataset's ``cache``
    folder that holds its caches is made with the first: something else there is refused (a file was, only once
    the trainer was set up: "cannot create the training cache folder")."""
    from frontiernet.io import check_writable_folder

    if not cache or (str(cache) == "auto" and path is None):
        return
    path = Path(str(cache)) if path is None else path
    if str(cache) == "auto" and not path.parent.is_dir():  # <dataset>/cache, beside the shards
        where = path.parent
        if os.path.lexists(where):
            kind = "is a file" if where.is_file() else "a symbolic link to nothing" if not where.exists() else \
                "not a regular file nor a folder (a device or a pipe?)"
            raise InputError(f"{where}: {kind}, expected the folder of the dataset's training caches (data.cache="
                             "auto); remove it, or set data.cache=FOLDER to put the cache elsewhere")
        check_writable_folder(where.parent, "data.cache=auto")
        return
    if path.exists() and not path.is_dir():
        raise InputError(f"data.cache={cache}: is a file, expected the training cache's folder")
    if path.is_dir():
        if not _holds_cache(path):
            check_writable_folder(path, "data.cache")
        elif not (path / INFO_NAME).exists():
            raise InputError(f"data.cache={cache}: {path} holds files but no {INFO_NAME}, so it is not a training "
                             "cache; give a new or an empty folder (the cache is built there), or data.cache=auto")
        else:
            _read_info(path)
        return
    if not path.parent.is_dir():
        raise InputError(f"data.cache={cache}: the folder it goes in, {path.parent}, does not exist (a cache "
                         "folder is made only in one that does): make it first, or set data.cache=auto (beside "
                         "the dataset)")
    check_writable_folder(path.parent, "data.cache")


def _cache_path(dataset_root: str | Path, cache, size: int, labels_conf) -> Path:
    """The folder of the cache that ``data.cache`` (`cache`) names: ``auto`` (:func:`default_cache_dir`) or a folder."""
    return default_cache_dir(Path(dataset_root), size, labels_conf) if str(cache) == "auto" else Path(str(cache))


def existing_cache(dataset_root: str | Path, cache, size: int, labels_conf) -> TrainingCache | None:
    """The cache that ``data.cache`` (`cache`) names, opened and checked against the dataset, `size` and
    `labels_conf` (:func:`open_cache`: InputError naming the file otherwise), when one is there; None when it is
    still to be built (no folder, or an empty one), where it can be (:func:`check_cache_folder`)."""
    path = _cache_path(dataset_root, cache, size, labels_conf)
    if _holds_cache(path):
        return open_cache(path, dataset_root, size, labels_conf)
    check_cache_folder(cache, path)  # where it is to be built (auto's too: a file at <dataset>/cache is refused now)
    return None


def ensure_cache(dataset_root: str | Path, cache, size: int, labels_conf, workers: int = 0,
                 progress=None) -> TrainingCache:
    """The cache named by ``data.cache`` (``auto``: :func:`default_cache_dir`; or a folder), built
    from the dataset when it does not exist yet, else opened and checked."""
    dataset_root = Path(dataset_root)
    path = _cache_path(dataset_root, cache, size, labels_conf)
    if _holds_cache(path):
        return open_cache(path, dataset_root, size, labels_conf)
    if str(cache) == "auto":  # <dataset>/cache/, made beside the dataset's shards
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise InputError(f"{path.parent}: cannot create the training cache folder ({error.strerror}); "
                             f"set data.cache=FOLDER to put it elsewhere") from None
    check_cache_folder(cache, path)  # (else the lock below waits forever: /proc, read-only)
    from filelock import FileLock

    # two runs on one dataset (e.g. two trainings started together) would share <path>.partial:
    # the second waits for the first's build and opens its cache
    with FileLock(str(path.with_name(path.name + ".lock"))):
        if _holds_cache(path):
            log.info("the training cache %s was built by another process meanwhile", path)
            return open_cache(path, dataset_root, size, labels_conf)
        log.info("building the training cache %s (%d px)", path, size)
        return build_cache(dataset_root, path, size, labels_conf, workers, progress)

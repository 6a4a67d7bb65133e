"""Random access to an on-disk dataset written by :mod:`datagen.shards`."""

from __future__ import annotations

import copy
import io
import operator
import os
import zipfile
import zlib
from collections import OrderedDict
from pathlib import Path

import numpy as np

from frontiernet.errors import InputError, positive_number
from frontiernet.io import why_missing
from frontiernet.array_files import native_stderr, npy_overclaim

from .labels import distance_field, gain_definition
from .shards import (DEFAULT_TRUNCATION_PX, INFO_NAME, MASK_NAMES, SHARDS_DIR, DatasetError,
                     _corrupt, read_dataset_info, read_shard_meta, regular_file)

_MAX_OPEN_SHARDS = 32


def _decode_sample(read, meta: dict, key: str) -> dict:
    """Arrays of sample `key`; `read(name)` returns a member's bytes. ValueError naming a bad member."""
    import cv2

    shape = (meta["height"], meta["width"])

    def image(name: str, flags: int, dtype, image_shape) -> np.ndarray:
        data = np.frombuffer(read(name), np.uint8)
        try:
            with native_stderr():  # libpng's own line for a damaged PNG: the ValueError below says it
                array = cv2.imdecode(data, flags) if data.size else None
        except cv2.error:
            array = None
        if array is None or array.dtype != dtype or array.shape != image_shape:
            raise ValueError(f"{name} does not decode to a {image_shape} {np.dtype(dtype)} image")
        return array

    def npy(name: str, dtype, array_shape) -> np.ndarray:
        data = read(name)
        overclaim = npy_overclaim(io.BytesIO(data), len(data))
        if overclaim is not None:
            raise ValueError(f"{name}: {overclaim}")
        array = np.lib.format.read_array(io.BytesIO(data), allow_pickle=False)
        if array.dtype != dtype or array.shape != array_shape:
            raise ValueError(f"{name} is {array.shape} {array.dtype}, expected {array_shape} "
                             f"{np.dtype(dtype)}")
        return array

    rgb_name = f"{key}/rgb.{meta['rgb_format']}"
    sample = {"rgb": image(rgb_name, cv2.IMREAD_COLOR, np.uint8, shape + (3,))[..., ::-1].copy()}
    def metres(name: str) -> np.ndarray:  # a uint16 millimetre PNG, 0 = none -> float32 metres, NaN
        millimetres = image(name, cv2.IMREAD_UNCHANGED, np.uint16, shape)
        return np.where(millimetres > 0, millimetres.astype(np.float32) / 1000.0, np.nan).astype(np.float32)

    sample["depth"] = metres(f"{key}/depth.png")
    sample["far_depth"] = metres(f"{key}/far_depth.png") if meta.get("far_depth") else None
    packed_shape = (shape[0], (shape[1] + 7) // 8)
    for name in MASK_NAMES:
        packed = npy(f"{key}/{name}.npy", np.uint8, packed_shape)
        sample[name] = np.unpackbits(packed, axis=1, count=shape[1]).astype(bool)
    sample["gain"] = npy(f"{key}/gain.npy", np.float32, shape)
    sample["gain_class"] = npy(f"{key}/gain_class.npy", np.uint8, shape).astype(np.int64)
    return sample


class FrontierDataset:
    """Random access to the samples of a set of shards; usable as a torch map-style dataset.

    ``ds[i]`` is a dict: rgb (H, W, 3) uint8; depth (H, W) float32 metres, NaN invalid;
    far_depth (H, W) float32 metres of surfaces beyond the sensor's range, NaN elsewhere (None for
    shards written before datagen stored it);
    frontier_mask, frontier_projected, discontinuity (H, W) bool; distance_field (H, W)
    float32 pixels (computed from frontier_mask, truncated at `truncation_px`); gain (H, W)
    float32 m^3; gain_class (H, W) int64; K (3, 3) and T_world_cam (4, 4) float64; scene,
    shard (file name), key str; index int; record dict.

    Zip handles open lazily, at most 32 at a time, and reopen in a forked process (DataLoader
    workers); pickling drops them.
    """

    def __init__(self, shards: list[Path], metas: list[dict], info: dict,
                 truncation_px: float = DEFAULT_TRUNCATION_PX, locations=None):
        self.shards = list(shards)
        self.info = info
        self.truncation_px = float(truncation_px)
        self._metas = metas
        if locations is None:
            locations = [(s, record["key"]) for s, meta in enumerate(metas)
                         for record in sorted(meta["samples"], key=lambda r: r["key"])]
        self._locations = list(locations)
        by_key = [{r["key"]: r for r in meta["samples"]} for meta in metas]
        self.records = [dict(by_key[s][key], shard=self.shards[s].name, key=key)
                        for s, key in self._locations]
        self.scenes = sorted({record["scene"] for record in self.records})
        self._handles: OrderedDict[int, zipfile.ZipFile] = OrderedDict()
        self._pid = os.getpid()

    def __len__(self) -> int:
        return len(self._locations)

    @property
    def gain_definition(self) -> str:
        """The definition its gain labels were made with (``config.ground_truth.gain`` of
        dataset.json; :func:`~frontiernet.frontiers.gain.gain_definition`, the default when absent)."""
        ground_truth = (self.info.get("config") or {}).get("ground_truth") or {}
        return gain_definition(ground_truth.get("gain") or {})

    def __getitem__(self, index: int) -> dict:
        index = operator.index(index)
        if not -len(self) <= index < len(self):
            raise IndexError(f"sample index {index} out of range for {len(self)} samples")
        index %= len(self)
        shard_index, key = self._locations[index]
        shard = self.shards[shard_index]
        archive = self._archive(shard_index)

        def read(name: str) -> bytes:
            try:
                return archive.read(name)
            except KeyError:
                raise _corrupt(shard, f"member {name} is missing") from None
            except (zipfile.BadZipFile, zlib.error, EOFError) as error:
                raise _corrupt(shard, f"member {name} is damaged: {error}") from None

        try:
            sample = _decode_sample(read, self._metas[shard_index], key)
        except ValueError as error:
            if isinstance(error, DatasetError):
                raise
            raise _corrupt(shard, str(error)) from None
        record = copy.deepcopy(self.records[index])
        sample["distance_field"] = distance_field(sample["frontier_mask"], self.truncation_px)
        sample.update(K=np.asarray(record["K"], np.float64).reshape(3, 3),
                      T_world_cam=np.asarray(record["T_world_cam"], np.float64).reshape(4, 4),
                      scene=str(record["scene"]), index=index, shard=shard.name, key=key,
                      record=record)
        return sample

    def _archive(self, shard_index: int) -> zipfile.ZipFile:
        """The open zip of shard `shard_index` (reopened after a fork; least recently used closed)."""
        if os.getpid() != self._pid:
            self.close()  # inherited handles share their file offset with the parent
            self._pid = os.getpid()
        archive = self._handles.get(shard_index)
        if archive is not None:
            self._handles.move_to_end(shard_index)
            return archive
        shard = self.shards[shard_index]
        try:
            archive = zipfile.ZipFile(shard)
        except zipfile.BadZipFile:
            raise _corrupt(shard, "bad zip file") from None
        except OSError as error:
            raise DatasetError(f"{shard}: cannot read shard ({error.strerror})") from None
        self._handles[shard_index] = archive
        while len(self._handles) > _MAX_OPEN_SHARDS:
            self._handles.popitem(last=False)[1].close()
        return archive

    def close(self) -> None:
        """Close the open zip handles (they reopen on the next read)."""
        for archive in self._handles.values():
            archive.close()
        self._handles.clear()

    def __enter__(self) -> FrontierDataset:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_handles"] = OrderedDict()
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._pid = os.getpid()

    def indices_for_scenes(self, scenes, strict: bool = True) -> list[int]:
        """Sample indices (ascending) whose scene spec is in `scenes` (a str or an iterable).

        With `strict`, a scene that has no sample raises InputError (catches typos in a split).
        """
        wanted = {scenes} if isinstance(scenes, str) else set(scenes)
        unknown = sorted(wanted.difference(self.scenes))
        if strict and unknown:
            raise InputError(f"scene(s) not in the dataset: {', '.join(unknown)}")
        return [i for i, record in enumerate(self.records) if record["scene"] in wanted]

    def subset(self, indices) -> FrontierDataset:
        """A dataset of the samples at `indices` (in that order), renumbered from 0."""
        picked = [self._locations[int(i)] for i in indices]
        return FrontierDataset(self.shards, self._metas, self.info, self.truncation_px, picked)


def _truncation_px(info: dict) -> float:
    """config.ground_truth.truncation_px of a dataset.json dict (10 px when absent)."""
    ground_truth = (info.get("config") or {}).get("ground_truth") or {}
    return positive_number(ground_truth.get("truncation_px", DEFAULT_TRUNCATION_PX),
                           "dataset.json config.ground_truth.truncation_px", "pixels")


def open_dataset(path: str | Path, truncation_px: float | None = None) -> FrontierDataset:
    """Open a dataset folder (dataset.json + shards/) or a single shard .zip.

    A single shard inside ``DIR/shards/`` uses ``DIR/dataset.json`` when present. The
    distance field is truncated at `truncation_px`, by default the dataset config's
    ``ground_truth.truncation_px`` (10 px when absent). Corrupt shards (bad zip, bad
    meta.json) raise :class:`DatasetError` here; damaged members raise at ``ds[i]``.
    """
    path = Path(path)
    if path.is_file() and path.suffix.lower() != ".zip":
        raise DatasetError(f"{path}: is a file, expected a dataset folder (made by frontiernet datagen) or one of "
                           "its shards (.zip)")
    if path.is_file():
        shards = [path]
        root = path.parent.parent
        info = read_dataset_info(root) if path.parent.name == SHARDS_DIR and \
            os.path.lexists(root / INFO_NAME) else {}
    elif path.is_dir():
        shard_dir = path / SHARDS_DIR
        if not os.path.lexists(path / INFO_NAME) and not shard_dir.is_dir():
            raise DatasetError(f"{path}: not a FrontierNet dataset (no {INFO_NAME} and no "
                               f"{SHARDS_DIR}/ folder)")
        info = read_dataset_info(path) if os.path.lexists(path / INFO_NAME) else {}  # (a folder there: refused)
        # every *.zip: one that is a pipe, a device or a folder is refused as such (it was left out, then "missing")
        shards = sorted((regular_file(p, "dataset shard") for p in shard_dir.glob("*.zip")), key=lambda p: p.name) \
            if shard_dir.is_dir() else []
    elif path.exists():  # (a pipe, a device: "no such" sent one looking for a missing folder)
        raise DatasetError(f"{path}: not a regular file nor a folder (a device or a pipe?), expected a dataset folder "
                           "or one of its shards (.zip)")
    elif path.is_symlink():  # to nothing, or a loop (was "no such dataset folder", which sent one looking for it)
        raise DatasetError(f"{path}{why_missing(path)}; expected a dataset folder (made by frontiernet datagen) or "
                           "one of its shards (.zip)")
    else:
        raise DatasetError(f"{path}: no such dataset folder or shard")
    metas = [read_shard_meta(shard) for shard in shards]
    if truncation_px is None:
        truncation_px = _truncation_px(info)
    return FrontierDataset(shards, metas, info, truncation_px)

"""The on-disk map-prediction dataset of ``frontiernet mapgen``: partial maps along exploration runs and the
true occupancy, in atomic zip shards (the writer's helpers are :mod:`datagen.shards`').

Layout of a dataset folder (as a FrontierNet dataset's, with another ``format``)::

    DIR/dataset.json        format frontiernet-map-dataset, generator, config and its hash, seed, scenes,
                            runs, voxel_size (the map resolution: training and evaluation check it)
    DIR/shards/<name>.zip   one exploration run of one scene
    DIR/summary.json        runs, snapshots, failures, time

Members of a shard, in this order (every array a flat ``np.packbits`` of an (X, Y, Z) bool grid, C order)::

    truth/occupied.npy       the scene's occupied voxels (VoxelGrid.occupied)
    truth/explorable.npy     its explorable (free interior) voxels
    {key}/observed.npy       snapshot `key` (``f"{j:04d}"``): the robot's map, voxels observed
    {key}/occupied.npy       ... and observed occupied
    meta.json                the run (scene, method, depth, seed, start, grid origin / shape / voxel
                             size, stop reason) and one record per snapshot (step, camera position and
                             yaw, floor height, coverage, the map's frontier pieces [x, y, cells])

Shards are written to ``<name>.zip.tmp-<pid>`` and renamed into place (:func:`datagen.shards.write_zip` and
friends: fixed time stamps, the same inputs give the same bytes); a reader ignores the temporaries.
"""

from __future__ import annotations

import io
import json
import os
import zipfile
import zlib
from collections import OrderedDict
from pathlib import Path

import numpy as np

from frontiernet.errors import InputError, decode_problem
from frontiernet.io import ensure_dir, input_folder, write_json

from .shards import (INFO_NAME, META_NAME, SHARDS_DIR, DatasetError, _dumps, _npy_bytes, read_info_file, regular_file,
                     write_zip)

MAP_DATASET_FORMAT = "frontiernet-map-dataset"
MAP_DATASET_VERSION = 1
MAP_SHARD_VERSION = 1
_RUN_KEYS = ("scene", "method", "depth", "seed", "origin", "shape", "voxel_size", "snapshots")
_SNAPSHOT_KEYS = ("key", "step", "position", "floor_z", "frontiers")


def write_map_dataset_info(root: str | Path, info: dict) -> Path:
    """Write ``root/dataset.json`` atomically: `info` plus ``format`` and ``format_version``."""
    data = {"format": MAP_DATASET_FORMAT, "format_version": MAP_DATASET_VERSION, **info}
    return write_json(ensure_dir(root) / INFO_NAME, json.loads(_dumps(data)))


def read_map_dataset_info(root: str | Path) -> dict:
    """The dict of ``root/dataset.json``; InputError naming `root` when it is a file or missing
    (:func:`~frontiernet.io.input_folder`), or the file when it is missing, unreadable or not a map
    dataset's (a FrontierNet dataset of ``frontiernet datagen`` says so)."""
    input_folder(root, "map dataset")
    path, info = read_info_file(root, "not a map dataset folder; make one with frontiernet mapgen")
    found = info.get("format") if isinstance(info, dict) else type(info).__name__
    if found != MAP_DATASET_FORMAT:
        raise DatasetError(f"{path}: not a map dataset (format {found!r}, expected {MAP_DATASET_FORMAT!r}; "
                           "make one with frontiernet mapgen)")
    if info.get("format_version") != MAP_DATASET_VERSION:
        raise DatasetError(f"{path}: map dataset format version {info.get('format_version')!r} is not supported "
                           f"(this version reads {MAP_DATASET_VERSION})")
    voxel = info.get("voxel_size")
    if isinstance(voxel, bool) or not isinstance(voxel, (int, float)) or not voxel > 0:
        raise DatasetError(f"{path}: key voxel_size (the map resolution) is missing or not a positive number")
    return info


def check_voxel_size(info: dict, root: str | Path, expected: float, what: str) -> None:
    """InputError naming the dataset's ``voxel_size`` key when it differs from `expected` (`what` names
    where that comes from, e.g. ``predictor.voxel_size``)."""
    if not np.isclose(float(info["voxel_size"]), float(expected), rtol=1e-6, atol=0.0):
        raise InputError(f"{Path(root) / INFO_NAME}: voxel_size {info['voxel_size']} m (the map resolution the "
                         f"dataset was made with) differs from {what} {float(expected)} m")


def _packed(mask: np.ndarray) -> bytes:
    return _npy_bytes(np.packbits(np.asarray(mask, bool).reshape(-1)))


def _snapshot_bits(array: np.ndarray, shape: tuple, name: str) -> bytes:
    """npy bytes of a snapshot grid given as an (X, Y, Z) bool grid or already packed (flat uint8 bits)."""
    array = np.asarray(array)
    if array.dtype == np.uint8 and array.ndim == 1:
        if array.size != (int(np.prod(shape)) + 7) // 8:
            raise ValueError(f"snapshot {name}: {array.size} packed bytes do not hold a {shape} grid")
        return _npy_bytes(array)
    if array.shape != shape:
        raise ValueError(f"snapshot {name} is {array.shape}, not {shape}")
    return _packed(array)


def write_map_shard(path: str | Path, truth: dict, snapshots: list[dict], meta: dict) -> Path:
    """Write one run's shard atomically and deterministically.

    Args:
        truth: ``occupied`` and ``explorable``, (X, Y, Z) bool grids of the scene.
        snapshots: dicts with ``observed`` and ``occupied`` (X, Y, Z) bool (or those packed: flat
            ``np.packbits``) and ``record`` (JSON-able:
            step, position, floor_z, frontiers, ...).
        meta: the run's JSON-able record (scene, method, depth, seed, origin, voxel_size, ...).
    """
    path = Path(path)
    shape = tuple(np.shape(truth["occupied"]))
    members = [(f"truth/{name}.npy", _packed(truth[name]), zipfile.ZIP_DEFLATED) for name in ("occupied", "explorable")]
    records = []
    for j, snapshot in enumerate(snapshots):
        key = f"{j:04d}"
        members += [(f"{key}/{name}.npy", _snapshot_bits(snapshot[name], shape, f"{key}/{name}"), zipfile.ZIP_DEFLATED)
                    for name in ("observed", "occupied")]
        records.append(dict(snapshot["record"], key=key))
    return write_zip(path, members, dict(meta, shape=list(shape), snapshots=records,
                                          shard_format_version=MAP_SHARD_VERSION))


def _corrupt(shard: Path, what: str) -> DatasetError:
    return DatasetError(f"{shard}: corrupt map shard ({what}); delete it and rerun frontiernet mapgen with --resume")


def read_map_shard_meta(shard: str | Path) -> dict:
    """The checked meta.json of a map shard; DatasetError naming the shard otherwise (one that is no regular file:
    :func:`~datagen.shards.regular_file`'s words; a pipe was opened and waited on for ever)."""
    shard = regular_file(Path(shard), "map shard")
    try:
        with zipfile.ZipFile(shard) as archive:
            meta = json.loads(archive.read(META_NAME))
            names = set(archive.namelist())
    except KeyError:
        raise _corrupt(shard, "no meta.json") from None
    except (zipfile.BadZipFile, zlib.error, OSError, EOFError, ValueError) as error:
        raise _corrupt(shard, f"unreadable: {decode_problem(error)}") from None
    ok = isinstance(meta, dict) and all(key in meta for key in _RUN_KEYS) and isinstance(meta["snapshots"], list) \
        and len(meta["shape"]) == 3 and all(isinstance(r, dict) and all(k in r for k in _SNAPSHOT_KEYS)
                                            for r in meta["snapshots"])
    if not ok:
        raise _corrupt(shard, "meta.json lacks or mangles scene, method, depth, origin, shape, voxel_size or snapshots")
    wanted = {"truth/occupied.npy", "truth/explorable.npy"} | {f"{r['key']}/{n}.npy" for r in meta["snapshots"]
                                                                for n in ("observed", "occupied")}
    if not wanted <= names:
        raise _corrupt(shard, f"member {sorted(wanted - names)[0]} missing")
    return meta


def map_shard_complete(path: str | Path) -> bool:
    """True when `path` is a readable map shard with every member its meta.json lists."""
    try:
        read_map_shard_meta(path)
    except DatasetError:
        return False
    return True


class MapDataset:
    """The snapshots of a map dataset folder, decoded on demand (a few shards' truths cached).

    Attributes:
        root, info (dataset.json), shards (paths), metas (one per shard), snapshots ((shard index, record)
        pairs, in shard order).
    """

    def __init__(self, root: str | Path, cache_shards: int = 4) -> None:
        self.root = Path(root)
        if not self.root.is_dir():
            raise InputError(f"{self.root}: map dataset folder not found (make one with frontiernet mapgen)")
        self.info = read_map_dataset_info(self.root)
        if os.path.lexists(self.root / SHARDS_DIR):  # (a dangling link or a file there read as "no snapshots yet")
            input_folder(self.root / SHARDS_DIR, "map shards")
        self.shards = sorted((self.root / SHARDS_DIR).glob("*.zip"))
        # every one checked a regular file as its meta is read (a pipe blocked): read_map_shard_meta
        self.metas = [read_map_shard_meta(path) for path in self.shards]
        for path, meta in zip(self.shards, self.metas):
            if not np.isclose(float(meta["voxel_size"]), float(self.info["voxel_size"]), rtol=1e-6, atol=0.0):
                raise InputError(f"{path}: voxel_size {meta['voxel_size']} m differs from its dataset's "
                                 f"{self.info['voxel_size']} m")
        self.snapshots = [(index, record) for index, meta in enumerate(self.metas) for record in meta["snapshots"]]
        self._truths: OrderedDict = OrderedDict()
        self._cache_shards = int(cache_shards)

    @property
    def voxel_size(self) -> float:
        return float(self.info["voxel_size"])

    @property
    def scenes(self) -> list[str]:
        """The scenes with at least one shard, in shard order."""
        return list(dict.fromkeys(meta["scene"] for meta in self.metas))

    def __len__(self) -> int:
        return len(self.snapshots)

    def _read(self, shard: int, name: str) -> np.ndarray:
        meta = self.metas[shard]
        shape = tuple(meta["shape"])
        try:
            with zipfile.ZipFile(self.shards[shard]) as archive:
                packed = np.lib.format.read_array(io.BytesIO(archive.read(name)), allow_pickle=False)
        except (KeyError, zipfile.BadZipFile, zlib.error, OSError, ValueError) as error:
            raise _corrupt(self.shards[shard], f"{name}: {'missing' if isinstance(error, KeyError) else decode_problem(error)}") from None
        count = int(np.prod(shape))
        if packed.dtype != np.uint8 or packed.size != (count + 7) // 8:
            raise _corrupt(self.shards[shard], f"{name} holds {packed.size} bytes, not a {shape} grid")
        return np.unpackbits(packed, count=count).astype(bool).reshape(shape)

    def truth(self, shard: int) -> tuple[np.ndarray, np.ndarray]:
        """(occupied, explorable) (X, Y, Z) bool of shard `shard`'s scene."""
        if shard not in self._truths:
            while len(self._truths) >= max(self._cache_shards, 1):
                self._truths.popitem(last=False)
            self._truths[shard] = (self._read(shard, "truth/occupied.npy"), self._read(shard, "truth/explorable.npy"))
        self._truths.move_to_end(shard)
        return self._truths[shard]

    def masks(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """(observed, occupied) (X, Y, Z) bool of snapshot `index`."""
        shard, record = self.snapshots[index]
        return (self._read(shard, f"{record['key']}/observed.npy"), self._read(shard, f"{record['key']}/occupied.npy"))


def open_map_dataset(path: str | Path) -> MapDataset:
    """A :class:`MapDataset`; InputError naming the folder or file when it is missing, corrupt or empty."""
    dataset = MapDataset(path)
    if not dataset.snapshots:
        raise InputError(f"{path}: the map dataset holds no snapshots yet")
    return dataset


__all__ = ["MAP_DATASET_FORMAT", "MapDataset", "check_voxel_size", "map_shard_complete", "open_map_dataset",
           "read_map_dataset_info", "read_map_shard_meta", "write_map_dataset_info", "write_map_shard"]

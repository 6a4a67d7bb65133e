"""The on-disk dataset: deterministic, atomic zip shards (the reader is :mod:`datagen.dataset`).

Layout of a dataset folder::

    DIR/dataset.json        # generator, config, seed, scenes (write_dataset_info)
    DIR/shards/<name>.zip   # one shard per write_shard call
    DIR/cache/              # derived data of this version of the dataset (train/cache.py's training
                            # caches); a datagen run that writes shards removes it

Members of a shard, in this order, for sample j (``key = f"{j:06d}"``)::

    {key}/rgb.png | rgb.jpg            (H, W, 3) RGB image, stored (already compressed)
    {key}/depth.png                    (H, W) uint16 millimetres, 0 = invalid, stored
    {key}/far_depth.png                (H, W) uint16 millimetres of surfaces hit beyond the sensor's
                                       range, 0 elsewhere (capped at 65.534 m), stored; only in
                                       shards whose meta.json has "far_depth": true
    {key}/frontier_mask.npy            np.packbits(mask, axis=1): (H, ceil(W / 8)) uint8
    {key}/frontier_projected.npy       same
    {key}/discontinuity.npy            same
    {key}/gain.npy                     (H, W) float32 cubic metres
    {key}/gain_class.npy               (H, W) uint8
    meta.json                          the caller's meta + samples, num_samples, height, width

All .npy and meta.json members are deflated. Every member carries the same fixed time
stamp and attributes, so the same inputs give a byte-identical shard. A shard is written
to ``<name>.zip.tmp-<pid>`` and renamed into place: a killed writer never leaves a
half-written ``.zip``, only a temporary that the reader ignores.
"""

from __future__ import annotations

import io
import json
import os
import zipfile
import zlib
from pathlib import Path

import numpy as np

from frontiernet.errors import InputError, decode_problem
from frontiernet.io import ensure_dir, input_file, write_json

DATASET_FORMAT = "frontiernet-dataset"
DATASET_FORMAT_VERSION = 1
SHARD_FORMAT_VERSION = 1
INFO_NAME = "dataset.json"
SHARDS_DIR = "shards"
CACHE_DIR = "cache"
META_NAME = "meta.json"
MASK_NAMES = ("frontier_mask", "frontier_projected", "discontinuity")
DEFAULT_TRUNCATION_PX = 10.0
MAX_DEPTH_M = 65.535  # uint16 millimetres
_ZIP_TIME = (1980, 1, 1, 0, 0, 0)
_PNG_COMPRESSION = 3


class DatasetError(InputError):
    """A dataset folder or shard that cannot be read; the message names the file."""


def _tmp_name(path: Path) -> Path:
    return path.with_name(f"{path.name}.tmp-{os.getpid()}")


def _shape(value) -> tuple:
    """np.shape of `value`, or () for a ragged nest of lists."""
    try:
        return np.shape(value)
    except ValueError:
        return ()


def _dumps(data) -> bytes:
    """Deterministic JSON bytes (sorted keys, fixed separators; numpy values as Python)."""

    def default(value):
        if isinstance(value, np.generic):
            return value.item()
        if isinstance(value, np.ndarray):
            return value.tolist()
        raise TypeError(f"{type(value).__name__} is not JSON serialisable")

    return json.dumps(data, sort_keys=True, separators=(",", ":"), default=default).encode()


# --------------------------------------------------------------------------- dataset.json

def write_dataset_info(root: str | Path, info: dict) -> Path:
    """Write ``root/dataset.json`` atomically: `info` plus ``format`` and ``format_version``."""
    data = {"format": DATASET_FORMAT, "format_version": DATASET_FORMAT_VERSION}
    data.update({k: v for k, v in info.items() if k not in data})
    return write_json(ensure_dir(root) / INFO_NAME, json.loads(_dumps(data)))


def read_info_file(root: str | Path, not_found: str) -> tuple[Path, object]:
    """(path, parsed JSON) of ``root/dataset.json`` (a FrontierNet or a map dataset's); DatasetError
    naming the file when it is missing (`not_found` says what the folder then is not) or is no
    readable JSON. The caller checks its format."""
    path = Path(root) / INFO_NAME
    if not os.path.lexists(path):
        raise DatasetError(f"{path}: not found ({not_found})")
    regular_file(path, "dataset description")  # (a folder there was taken for none: the shards' metas stood in)
    try:
        return path, json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as error:
        # (not valid JSON at line L column C, not UTF-8 text: in words, not the decoder's class name)
        raise DatasetError(f"{path}: not a readable JSON file: {decode_problem(error)}") from None


def regular_file(path: Path, what: str) -> Path:
    """`path` if it is a regular file; DatasetError in :func:`~frontiernet.io.input_file`'s words otherwise (``is a
    folder, expected a file``, ``not a regular file``: a pipe, a device, ``not found: a symbolic link to ...``)."""
    try:
        return input_file(path, what)
    except InputError as error:
        raise DatasetError(str(error)) from None


def read_dataset_info(root: str | Path) -> dict:
    """The dict of ``root/dataset.json``; DatasetError naming the file if it is missing or wrong."""
    path, info = read_info_file(root, "not a FrontierNet dataset folder")
    if not isinstance(info, dict) or info.get("format") != DATASET_FORMAT:
        found = info.get("format") if isinstance(info, dict) else type(info).__name__
        raise DatasetError(f"{path}: not a FrontierNet dataset description "
                           f"(format {found!r}, expected {DATASET_FORMAT!r})")
    if info.get("format_version") != DATASET_FORMAT_VERSION:
        raise DatasetError(f"{path}: dataset format version {info.get('format_version')!r} is not "
                           f"supported (this version reads {DATASET_FORMAT_VERSION})")
    return info


# --------------------------------------------------------------------------- writer

def _writer_settings(writer_conf) -> tuple[str, int]:
    """(rgb extension "png" | "jpg", jpg quality) from a dict / DictConfig / None."""
    conf = writer_conf if writer_conf is not None else {}
    fmt = str(conf.get("rgb_format", "png")).lower()
    fmt = "jpg" if fmt == "jpeg" else fmt
    if fmt not in ("png", "jpg"):
        raise InputError(f"writer.rgb_format must be png or jpg, got {fmt!r}")
    quality = conf.get("jpg_quality", 95)
    if isinstance(quality, bool) or not isinstance(quality, int) or not 1 <= quality <= 100:
        raise InputError(f"writer.jpg_quality must be an integer in [1, 100], got {quality!r}")
    return fmt, quality


def encode_depth_mm(depth: np.ndarray) -> np.ndarray:
    """(H, W) float metres, NaN (or inf) invalid -> (H, W) uint16 millimetres (half up), 0 invalid.

    Raises ValueError for a valid depth < 0 or >= 65.535 m. Depths below 0.5 mm become 0
    (invalid); no sensor reports them.
    """
    depth = np.asarray(depth, np.float64)
    valid = np.isfinite(depth)
    if np.any(depth[valid] < 0) or np.any(depth[valid] >= MAX_DEPTH_M):
        raise ValueError(f"depth must lie in [0, {MAX_DEPTH_M}) m to be stored as uint16 millimetres, "
                         f"got range [{depth[valid].min()}, {depth[valid].max()}]")
    millimetres = np.zeros(depth.shape, np.uint16)
    millimetres[valid] = np.floor(depth[valid] * 1000.0 + 0.5).astype(np.uint16)
    return millimetres


def _encode_image(ext: str, image: np.ndarray, quality: int) -> bytes:
    import cv2

    params = [cv2.IMWRITE_JPEG_QUALITY, quality] if ext == "jpg" else \
        [cv2.IMWRITE_PNG_COMPRESSION, _PNG_COMPRESSION]
    ok, data = cv2.imencode("." + ext, image, params)
    if not ok:
        raise ValueError(f"cannot encode a {image.shape} {image.dtype} image as {ext}")
    return data.tobytes()


def _npy_bytes(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.lib.format.write_array(buffer, np.ascontiguousarray(array), allow_pickle=False)
    return buffer.getvalue()


def _sample_members(key: str, sample: dict, shape: tuple[int, int], ext: str, quality: int):
    """Yield (name, bytes, compress_type) of one sample's members, in shard order."""
    rgb = np.asarray(sample["rgb"])
    if rgb.shape != shape + (3,) or rgb.dtype != np.uint8:
        raise ValueError(f"sample {key}: rgb must be {shape + (3,)} uint8, got {rgb.shape} {rgb.dtype}")
    arrays = {name: np.asarray(sample[name]) for name in ("depth", "gain", "gain_class") + MASK_NAMES}
    for name, array in arrays.items():
        if array.shape != shape:
            raise ValueError(f"sample {key}: {name} must have shape {shape}, got {array.shape}")
    classes = arrays["gain_class"]
    if not np.issubdtype(classes.dtype, np.integer) or classes.min() < 0 or classes.max() > 255:
        raise ValueError(f"sample {key}: gain_class must be integers in [0, 255]")
    yield f"{key}/rgb.{ext}", _encode_image(ext, rgb[..., ::-1], quality), zipfile.ZIP_STORED
    yield f"{key}/depth.png", _encode_image("png", encode_depth_mm(arrays["depth"]), quality), \
        zipfile.ZIP_STORED
    if "far_depth" in sample:
        far = np.asarray(sample["far_depth"], np.float32)
        if far.shape != shape:
            raise ValueError(f"sample {key}: far_depth must have shape {shape}, got {far.shape}")
        far = np.where(np.isfinite(far), np.minimum(far, np.float32(MAX_DEPTH_M - 0.001)), np.nan)
        yield f"{key}/far_depth.png", _encode_image("png", encode_depth_mm(far), quality), zipfile.ZIP_STORED
    for name in MASK_NAMES:
        yield f"{key}/{name}.npy", _npy_bytes(np.packbits(arrays[name].astype(bool), axis=1)), \
            zipfile.ZIP_DEFLATED
    yield f"{key}/gain.npy", _npy_bytes(arrays["gain"].astype(np.float32)), zipfile.ZIP_DEFLATED
    yield f"{key}/gain_class.npy", _npy_bytes(classes.astype(np.uint8)), zipfile.ZIP_DEFLATED


def member_names(key: str, rgb_format: str = "png", far_depth: bool = False) -> list[str]:
    """The member names of sample `key` in a shard, in order (`far_depth`: the shard stores it)."""
    return [f"{key}/rgb.{rgb_format}", f"{key}/depth.png"] + ([f"{key}/far_depth.png"] if far_depth else []) + \
        [f"{key}/{name}.npy" for name in MASK_NAMES + ("gain", "gain_class")]


def _record(key: str, sample: dict) -> dict:
    record = dict(sample["record"])
    missing = [name for name in ("scene", "T_world_cam", "K") if name not in record]
    if missing:
        raise ValueError(f"sample {key}: record lacks {', '.join(missing)}")
    if _shape(record["T_world_cam"]) != (4, 4) or _shape(record["K"]) != (3, 3):
        raise ValueError(f"sample {key}: record T_world_cam must be 4x4 and K 3x3")
    record["key"] = key
    return record


def _add(archive: zipfile.ZipFile, name: str, data: bytes, compress_type: int) -> None:
    info = zipfile.ZipInfo(name, date_time=_ZIP_TIME)
    info.compress_type = compress_type
    info.create_system = 3
    info.external_attr = 0o644 << 16
    archive.writestr(info, data)


def write_shard(path: str | Path, samples: list[dict], meta: dict, writer_conf=None) -> Path:
    """Write `samples` (see the module docstring) to the zip `path`, atomically and deterministically.

    Args:
        samples: dicts with rgb (H, W, 3) uint8, depth (H, W) float metres (NaN invalid),
            optionally far_depth (H, W) float metres (NaN where none; all samples or none),
            frontier_mask / frontier_projected / discontinuity (H, W) bool, gain (H, W) float32
            m^3, gain_class (H, W) int in [0, 255], record (JSON-able dict with at least
            scene, T_world_cam 4x4, K 3x3). All samples share H and W.
        meta: JSON-able shard-level data; the writer adds samples (records with key),
            num_samples, height, width, rgb_format and shard_format_version.
        writer_conf: the ``writer`` config section (rgb_format, jpg_quality) or None.
    Returns:
        `path`.
    """
    path = Path(path)
    ext, quality = _writer_settings(writer_conf)
    if not samples:
        raise ValueError(f"{path}: a shard needs at least one sample")
    shape = tuple(np.shape(samples[0]["depth"]))
    if len(shape) != 2:
        raise ValueError(f"depth must be (H, W), got shape {shape}")
    records = [_record(f"{j:06d}", sample) for j, sample in enumerate(samples)]
    with_far = {"far_depth" in sample for sample in samples}
    if len(with_far) > 1:
        raise ValueError(f"{path}: some samples have far_depth and some not (all or none)")
    full_meta = dict(meta, samples=records, num_samples=len(records), height=shape[0],
                     width=shape[1], rgb_format=ext, shard_format_version=SHARD_FORMAT_VERSION)
    if with_far == {True}:
        full_meta["far_depth"] = True
    members = (member for j, sample in enumerate(samples)
               for member in _sample_members(f"{j:06d}", sample, shape, ext, quality))
    return write_zip(path, members, full_meta)


def write_zip(path: Path, members, meta: dict) -> Path:
    """Write a shard atomically and deterministically: the `members` ((name, bytes, compress type)
    in order), then `meta` as :data:`META_NAME`, into ``<name>.tmp-<pid>``, synced and renamed into
    place (the folder synced too); the temporary file is removed on any error."""
    tmp = _tmp_name(ensure_dir(path.parent) / path.name)
    try:
        with open(tmp, "wb") as handle:
            with zipfile.ZipFile(handle, "w") as archive:
                for name, data, compress_type in members:
                    _add(archive, name, data, compress_type)
                _add(archive, META_NAME, _dumps(meta), zipfile.ZIP_DEFLATED)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    _fsync_dir(path.parent)
    return path


def _fsync_dir(folder: Path) -> None:
    """Make a rename in `folder` durable (best effort: some file systems refuse)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
    except OSError:
        pass


def remove_stale_temporaries(shard_dir: str | Path) -> int:
    """Delete leftover ``*.tmp-*`` files of killed writers in `shard_dir`; return how many.

    Only call it while no writer is running on the folder.
    """
    shard_dir = Path(shard_dir)
    stale = [p for p in shard_dir.glob("*.tmp-*") if p.is_file()] if shard_dir.is_dir() else []
    for path in stale:
        path.unlink(missing_ok=True)
    return len(stale)


def shard_complete(path: str | Path) -> bool:
    """True when `path` is a zip whose meta.json lists num_samples samples, all members present.

    Reads only the central directory and meta.json, so it does not catch corrupt member data.
    """
    try:
        with zipfile.ZipFile(path) as archive:
            meta = _parse_meta(archive, Path(path))
            names = set(archive.namelist())
    except (DatasetError, OSError, zipfile.BadZipFile):
        return False
    return all(name in names for record in meta["samples"]
               for name in member_names(record["key"], meta["rgb_format"], bool(meta.get("far_depth"))))


# --------------------------------------------------------------------------- shard meta
# (used by shard_complete here and by the reader in datagen.dataset)

def _corrupt(shard: Path, what: str) -> DatasetError:
    """The error of a corrupt shard; a dataset's own (in its shards/ folder) is remade by a resumed run."""
    remedy = "; delete it and rerun with --resume" if shard.parent.name == SHARDS_DIR else ""
    return DatasetError(f"{shard}: corrupt shard ({what}){remedy}")


def _parse_meta(archive: zipfile.ZipFile, shard: Path) -> dict:
    """meta.json of an open shard, checked; DatasetError naming `shard` otherwise."""
    try:
        meta = json.loads(archive.read(META_NAME))
    except KeyError:
        raise _corrupt(shard, "no meta.json") from None
    except (zipfile.BadZipFile, zlib.error, OSError, EOFError, ValueError) as error:
        raise _corrupt(shard, f"unreadable meta.json: {decode_problem(error)}") from None
    ok = isinstance(meta, dict) and isinstance(meta.get("samples"), list) \
        and meta.get("num_samples") == len(meta["samples"]) \
        and all(isinstance(meta.get(k), int) and meta[k] > 0 for k in ("height", "width")) \
        and meta.get("rgb_format") in ("png", "jpg") \
        and all(isinstance(r, dict) and isinstance(r.get("key"), str)
                and isinstance(r.get("scene"), str)
                and _shape(r.get("T_world_cam")) == (4, 4) and _shape(r.get("K")) == (3, 3)
                for r in meta["samples"]) \
        and len({r["key"] for r in meta["samples"]}) == len(meta["samples"])
    if not ok:
        raise _corrupt(shard, "meta.json lacks or mangles samples, num_samples, height, width "
                              "or rgb_format")
    return meta


def read_shard_meta(shard: str | Path) -> dict:
    """The checked meta.json of a shard file (per-sample records under ``"samples"``).

    Raises:
        DatasetError: naming the shard, when it is not a readable, well-formed shard.
    """
    shard = Path(shard)
    try:
        with zipfile.ZipFile(shard) as archive:
            return _parse_meta(archive, shard)
    except zipfile.BadZipFile:
        raise _corrupt(shard, "bad zip file") from None
    except OSError as error:
        raise DatasetError(f"{shard}: cannot read shard ({error.strerror})") from None

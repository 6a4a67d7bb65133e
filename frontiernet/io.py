"""Writing outputs atomically, so an interrupted run never leaves a half-written file."""

from __future__ import annotations

import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import numpy as np

from .errors import InputError


def ensure_dir(path: str | Path) -> Path:
    """Create output folder `path` (and parents); fail with a clear message if impossible."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputError(f"{path}: output path exists and is not a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise InputError(f"{path}: cannot create output folder ({error.strerror})") from None
    return path


FORCE = "--force"
"""The option of every command that replaces earlier outputs (export, render, explore, scene topdown)."""


def check_output_file(path: str | Path, force: bool = True) -> Path:
    """Before the work: InputError when output file `path` is a folder, or exists and `force`
    is off (nothing written before is replaced unless asked: :data:`FORCE`)."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path}: is a folder; give the output's file name")
    if path.exists() and not force:
        raise InputError(f"{path}: exists; pass {FORCE} to replace it, or choose another output")
    return path


def check_output_folder(path: str | Path, force: bool = False) -> Path:
    """Before the work: InputError when output folder `path` is a file, or already holds files
    and `force` is off (a command's earlier outputs are not replaced unless asked: :data:`FORCE`)."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputError(f"{path}: output path exists and is not a folder")
    if path.is_dir() and not force and any(path.iterdir()):
        raise InputError(f"{path}: folder already holds files (earlier outputs?); pass {FORCE} to write over "
                         f"them, or choose another --out")
    return path


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary file beside `path` for the ``with`` block to write; renamed into place when the
    block ends, removed when it raises (`path` is then left as it was).

    ``with atomic_path(out / "figure.png") as tmp: figure.savefig(tmp, format="png")``. For a
    writer that needs a file name; :func:`write_bytes` and :func:`write_text` write data.

    Raises:
        InputError: a folder in the way, or a folder that cannot be written (missing, no permission).
    """
    path = Path(path)
    if path.is_dir():  # os.replace would fail after the work, with a traceback
        raise InputError(f"{path}: cannot write, a folder is in the way")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent)
    except OSError as error:  # a missing folder, a file where the folder should be, no permission
        raise InputError(f"{path}: cannot write ({error.strerror})") from None
    os.close(fd)
    try:
        yield Path(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; give the file normal permissions
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def write_bytes(path: str | Path, data: bytes) -> Path:
    """Write `data` to `path` atomically (:func:`atomic_path`); returns `path`."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text(path: str | Path, text: str) -> Path:
    """Write `text` (UTF-8) to `path` atomically (:func:`atomic_path`); returns `path`."""
    return write_bytes(path, text.encode("utf-8"))


def write_json(path: str | Path, data) -> Path:
    return write_text(path, json.dumps(data, indent=2) + "\n")


def write_npy(path: str | Path, array: np.ndarray) -> Path:
    with atomic_path(path) as tmp, open(tmp, "wb") as handle:
        np.save(handle, array)
    return Path(path)


def check_image_name(path: str | Path) -> None:
    """InputError unless `path`'s suffix names an image format OpenCV writes (.png, .jpg, ...)."""
    import cv2

    if not cv2.haveImageWriter(str(path)):
        raise InputError(f"{path}: not an image file name OpenCV can write (use .png or .jpg)")


def write_image(path: str | Path, rgb: np.ndarray) -> Path:
    """Write an (H, W, 3) uint8 RGB image (format from the suffix, e.g. .png)."""
    import cv2

    check_image_name(path)

    ok, data = cv2.imencode(Path(path).suffix, np.ascontiguousarray(rgb[..., ::-1]))
    if not ok:
        raise InputError(f"{path}: cannot encode image")
    return write_bytes(path, data.tobytes())


def colorize_depth(depth: np.ndarray, max_depth: float) -> np.ndarray:
    """(H, W) float metres (NaN invalid) -> (H, W, 3) uint8 turbo colour image, invalid black."""
    import cv2

    valid = np.isfinite(depth)
    scaled = np.zeros(depth.shape, np.uint8)
    scaled[valid] = (np.clip(depth[valid] / max_depth, 0, 1) * 255).astype(np.uint8)
    colored = cv2.applyColorMap(scaled, cv2.COLORMAP_TURBO)[..., ::-1].copy()
    colored[~valid] = 0
    return colored

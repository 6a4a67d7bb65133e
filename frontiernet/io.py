"""Writing outputs atomically, so an interrupted run never leaves a half-written file."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

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


def atomic_write(path: str | Path, write) -> Path:
    """Call ``write(tmp_path)`` on a temporary file beside `path`, then rename it into place."""
    path = Path(path)
    if path.is_dir():  # os.replace would fail after the work, with a traceback
        raise InputError(f"{path}: cannot write, a folder is in the way")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent)
    except OSError as error:  # a missing folder, a file where the folder should be, no permission
        raise InputError(f"{path}: cannot write ({error.strerror})") from None
    os.close(fd)
    try:
        write(Path(tmp))
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; give the file normal permissions
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def write_json(path: str | Path, data) -> Path:
    return atomic_write(path, lambda tmp: tmp.write_text(json.dumps(data, indent=2) + "\n"))


def write_npy(path: str | Path, array: np.ndarray) -> Path:
    def write(tmp: Path) -> None:
        with open(tmp, "wb") as handle:
            np.save(handle, array)

    return atomic_write(path, write)


def check_image_name(path: str | Path) -> None:
    """InputError unless `path`'s suffix names an image format OpenCV writes (.png, .jpg, ...)."""
    import cv2

    if not cv2.haveImageWriter(str(path)):
        raise InputError(f"{path}: not an image file name OpenCV can write (use .png or .jpg)")


def write_image(path: str | Path, rgb: np.ndarray) -> Path:
    """Write an (H, W, 3) uint8 RGB image (format from the suffix, e.g. .png)."""
    import cv2

    check_image_name(path)

    def write(tmp: Path) -> None:
        ok, data = cv2.imencode(Path(path).suffix, np.ascontiguousarray(rgb[..., ::-1]))
        if not ok:
            raise InputError(f"{path}: cannot encode image")
        tmp.write_bytes(data.tobytes())

    return atomic_write(path, write)


def colorize_depth(depth: np.ndarray, max_depth: float) -> np.ndarray:
    """(H, W) float metres (NaN invalid) -> (H, W, 3) uint8 turbo colour image, invalid black."""
    import cv2

    valid = np.isfinite(depth)
    scaled = np.zeros(depth.shape, np.uint8)
    scaled[valid] = (np.clip(depth[valid] / max_depth, 0, 1) * 255).astype(np.uint8)
    colored = cv2.applyColorMap(scaled, cv2.COLORMAP_TURBO)[..., ::-1].copy()
    colored[~valid] = 0
    return colored

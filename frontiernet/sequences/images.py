"""Reading RGB images and depth maps from disk, with the depth encodings of common datasets.

* :func:`read_rgb`: (H, W, 3) uint8 RGB from any image OpenCV reads.
* :func:`read_depth`: (H, W) float32 metres, 0 = invalid, from ``.npy`` or a depth image in one
  of the :data:`DEPTH_ENCODINGS`:

  ``scale`` (default): integer images and arrays divided by ``depth_scale`` units per metre (1000
  for millimetre PNGs as Redwood, ICL-NUIM and ScanNet write them; 5000 for TUM RGB-D), float
  ones (``frontiernet render``'s ``depth.npy``) taken as metres; ``sun``: SUN3D / SUN RGB-D's bit-rotated millimetres
  (``mm = v >> 3 | v << 13``); ``nyu``: NYU Depth V2's raw Kinect values, stored little-endian
  in a PGM whose header says big-endian (``m = 351.3 / (1092.5 - raw)``, Open3D's
  ``CreateFromNYUFormat``).
"""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError
from ..array_files import read_image, read_npy
from ..io import input_file

DEPTH_ENCODINGS = ("scale", "sun", "nyu")
PLAUSIBLE_DEPTH_M = (0.05, 100.0)  # median depths outside this mean a wrong unit (indoor and outdoor sensors)
MAX_DEPTH_M = PLAUSIBLE_DEPTH_M[1]
"""The farthest depth pixel read, metres: no indoor camera sees past 100 m (the bound of the simulated camera's
``camera.max_depth``, configs/ranges/sim.yaml, and of ``tracking.gain_view.max_depth_m``); a pixel beyond is no
reading (a float32 depth of 3e38 m overflowed the median to infinity), refused as an infinite one is."""
_NYU_BASELINE, _NYU_OFFSET = 351.3, 1092.5  # Open3D RGBDImageFactory.cpp (NYU raw Kinect disparity)


def read_rgb(path: str | Path) -> np.ndarray:
    """(H, W, 3) uint8 RGB from an image file; InputError for a missing file or another channel count."""
    image = read_image(path, cv2.IMREAD_UNCHANGED)
    channels = 1 if image.ndim == 2 else image.shape[2]
    if channels == 4:  # RGBA (e.g. habitat renders): drop alpha
        image = image[..., :3]
    elif channels != 3:
        raise InputError(f"{path}: image has {channels} channel(s); an RGB image with 3 channels is needed")
    if image.dtype != np.uint8:
        raise InputError(f"{path}: image is {image.dtype}; an 8-bit RGB image is needed")
    return np.ascontiguousarray(image[..., ::-1])


def _pgm_header(data: bytes, path: Path) -> tuple[int, int, int]:
    """(width, height, offset of the pixels) of a binary PGM (P5): four whitespace-separated
    tokens (comments after '#') and one whitespace byte."""
    tokens, position = [], 0
    while len(tokens) < 4 and position < len(data):
        match = re.compile(rb"\s*(#[^\n]*\n\s*)*(\S+)").match(data, position)
        if match is None:
            break
        tokens.append(match.group(2))
        position = match.end()
    if len(tokens) < 4 or tokens[0] != b"P5":
        raise InputError(f"{path}: not a binary PGM (P5 header expected)")
    try:
        return int(tokens[1]), int(tokens[2]), position + 1
    except ValueError:
        raise InputError(f"{path}: PGM header has a non-numeric size") from None


def _read_nyu(path: Path) -> np.ndarray:
    data = path.read_bytes()
    width, height, offset = _pgm_header(data, path)
    if len(data) - offset < 2 * width * height:
        raise InputError(f"{path}: NYU depth PGM is truncated ({len(data) - offset} bytes of pixels, "
                         f"{2 * width * height} expected)")
    raw = np.frombuffer(data, "<u2", width * height, offset=offset).reshape(height, width).astype(np.float64)
    with np.errstate(divide="ignore"):
        return np.where(raw < _NYU_OFFSET, _NYU_BASELINE / (_NYU_OFFSET - raw), 0.0).astype(np.float32)


def read_depth(path: str | Path, depth_scale: float = 1000.0, encoding: str = "scale", *,
               scale_given: bool = False) -> np.ndarray:
    """(H, W) float32 metres from a depth file; 0 = invalid (see the module doc for `encoding`).

    NaN (the convention of ``frontiernet render``'s ``depth.npy``), 0 and negative values are invalid.
    Integer depth (an image or a ``.npy`` array) is divided by `depth_scale`; float depth is metres. An 8-bit
    image or array is refused: integer depth is 16-bit (a 0-255 picture of depth read as millimetres is no depth map).
    `scale_given`: the user gave `depth_scale` (``--depth-scale``), so float depth, which it does not
    apply to, is refused rather than read with the scale silently ignored.
    """
    if encoding not in DEPTH_ENCODINGS:
        raise InputError(f"depth encoding '{encoding}' is unknown; valid: {', '.join(DEPTH_ENCODINGS)}")
    path = input_file(path, "depth file")
    if encoding == "nyu":
        return _read_nyu(path)
    if path.suffix.lower() == ".npy":
        depth = read_npy(path)
        if depth.dtype in (np.uint8, np.int8):  # as an 8-bit image: 0-255 steps read as millimetres reach 25 cm
            raise InputError(f"{path}: holds 8-bit integer ({depth.dtype}) values; integer depth must be 16-bit or "
                             "wider (units, millimetres unless a depth scale says otherwise) or float (metres), e.g. "
                             "a uint16 array of millimetres")
    else:
        depth = read_image(path, cv2.IMREAD_UNCHANGED | cv2.IMREAD_ANYDEPTH, "depth image")
        if depth.dtype in (np.uint8, np.int8):  # a picture of depth (0-255), not a depth map
            raise InputError(f"{path}: an 8-bit image; depth images must be 16-bit (integer units, millimetres unless "
                             "a depth scale says otherwise) or float (metres), e.g. a uint16 PNG of millimetres")
    if not (np.issubdtype(depth.dtype, np.integer) or np.issubdtype(depth.dtype, np.floating)):
        raise InputError(f"{path}: holds {depth.dtype} values, not depth (integer units or float metres)")
    if depth.ndim != 2:
        raise InputError(f"{path}: depth must be a single-channel (H, W) map, got shape {tuple(depth.shape)}")
    floating = encoding == "scale" and np.issubdtype(depth.dtype, np.floating)  # metres, no scale
    if encoding == "sun":
        if depth.dtype != np.uint16:
            raise InputError(f"{path}: SUN depth must be a 16-bit image, got {depth.dtype}")
        depth = ((depth >> 3) | (depth << 13)).astype(np.float32) / 1000.0
    elif np.issubdtype(depth.dtype, np.integer):  # judged in float64: a scale of 1e-300 (1e300) made float32
        depth = depth.astype(np.float64) / float(depth_scale)  # depths infinite (zero), blamed on the file
        check_depth_unit(depth, path, f"read with depth scale {depth_scale:g} units per metre")
    elif floating and scale_given:
        raise InputError(f"{path}: holds {depth.dtype} depth, read as metres; the depth scale "
                         f"({depth_scale:g}, --depth-scale) applies to integer depth only: leave it out")
    else:  # judged as stored, float32 only once judged: float64 1e300 (1e-300) m became inf (0) first,
        depth = depth.astype(np.float64)  # "infinite pixels" (no valid depth) blamed on the wrong thing
    if np.isinf(depth).any():
        raise InputError(f"{path}: depth has {int(np.isinf(depth).sum())} infinite pixels; mark invalid pixels "
                         "with 0 or NaN")
    depth[~(depth > 0)] = 0.0  # NaN too
    if floating:
        check_depth_unit(depth, path, "float depth is read as metres", "convert it to metres (divide by 1000 for "
                         "millimetres) or save it as integer millimetres (uint16)")
    elif encoding != "scale":  # (integer depth of the scale encoding: judged above)
        check_depth_unit(depth, path, f"read with the {encoding} encoding")
    check_depth_range(depth, path)  # after the unit: depth in another unit is said so, stray far pixels here
    return depth.astype(np.float32)


def check_depth_range(depth: np.ndarray, path) -> None:
    """InputError naming `path`, how many pixels and the farthest, when depth pixels (metres) are infinite or
    beyond :data:`MAX_DEPTH_M` (as an infinite pixel is, not read as invalid: a far pixel is a reading, and a
    wrong one is said so); NaN, 0 and negative pixels are invalid ones (no reading), left to the caller."""
    with np.errstate(invalid="ignore"):
        far = depth > MAX_DEPTH_M  # (NaN: False) +inf too
    if far.any():
        largest = float(depth[far].max())
        shown = f"{largest:.4g}" if f"{largest:.4g}" != f"{MAX_DEPTH_M:g}" else f"{largest:.10g}"  # (not "100" for 100.0015)
        raise InputError(f"{path}: depth has {int(far.sum())} pixel(s) beyond {MAX_DEPTH_M:g} m (the farthest "
                         f"{shown} m), which no indoor camera sees; mark invalid pixels with 0 or NaN")


def check_depth_unit(depth: np.ndarray, path, decoding: str, advice: str | None = None) -> None:
    """InputError when the median valid depth (metres) is outside :data:`PLAUSIBLE_DEPTH_M`: a
    depth map read in the wrong unit (millimetres as metres, metres as millimetres). `decoding` says how
    it was read (``read with depth scale 1000 units per metre``), `advice` what to do (default: check the
    depth scale; float depth, which takes none, says its own)."""
    valid = depth[depth > 0]
    if not len(valid):
        return
    median = float(np.median(valid.astype(np.float64)))  # (float32: two values near 3e38 averaged to inf)
    low, high = PLAUSIBLE_DEPTH_M
    if not low <= median <= high:
        advice = advice or "check the depth scale (1000 for millimetres, 5000 for TUM, 1 for metres)"
        raise InputError(f"{path}: median depth {median:.4g} m is implausible ({decoding}); the depth "
                         f"is in another unit: {advice}")

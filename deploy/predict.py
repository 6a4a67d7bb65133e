"""``predict_files(image, depth, model, out)``: the network on one image from disk, with pictures.

Writes to the output folder: ``overlay.png`` (frontier pixels D < l coloured by gain class over
the image), ``distance.png`` (the distance field), ``input.png`` (the network's input after
resizing) and ``outputs.npz`` (``distance_field`` (H, W) float32 px, ``gain_logits`` (K, H, W)
float16, ``gain_class`` (H, W) uint8, ``frontier_mask`` (H, W) bool, ``depth`` (H, W) float32 m).
"""

from __future__ import annotations

import io
from pathlib import Path

import cv2
import numpy as np

from frontiernet.errors import InputError
from frontiernet.io import atomic_write, ensure_dir, write_image
from frontiernet.model.overlay import distance_picture, frontier_overlay

from .runtime import load_runtime


def read_rgb(path: str | Path) -> np.ndarray:
    """(H, W, 3) uint8 RGB from an image file; InputError for a missing file or another channel count."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: image not found")
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise InputError(f"{path}: not a readable image")
    channels = 1 if image.ndim == 2 else image.shape[2]
    if channels != 3:
        raise InputError(f"{path}: image has {channels} channel(s); an RGB image with 3 channels is needed")
    if image.dtype != np.uint8:
        raise InputError(f"{path}: image is {image.dtype}; an 8-bit RGB image is needed")
    return np.ascontiguousarray(image[..., ::-1])


def read_depth(path: str | Path, depth_scale: float = 1000.0) -> np.ndarray:
    """(H, W) float32 metres from a depth file; 0 = invalid.

    ``.npy``: float metres. Images (PNG, TIFF): integer images are divided by `depth_scale`
    (1000 for millimetre PNGs as TUM/Redwood/our datasets write them; TUM's own is 5000);
    float images are metres. NaN is refused (mark invalid pixels with 0).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: depth file not found")
    if path.suffix.lower() == ".npy":
        try:
            depth = np.load(path, allow_pickle=False)
        except (ValueError, OSError) as error:
            raise InputError(f"{path}: not a readable .npy array ({error})") from None
    else:
        depth = cv2.imread(str(path), cv2.IMREAD_UNCHANGED | cv2.IMREAD_ANYDEPTH)
        if depth is None:
            raise InputError(f"{path}: not a readable depth image")
        if np.issubdtype(depth.dtype, np.integer):
            depth = depth.astype(np.float32) / float(depth_scale)
    if depth.ndim != 2:
        raise InputError(f"{path}: depth must be a single-channel (H, W) map, got shape {tuple(depth.shape)}")
    depth = depth.astype(np.float32)
    if np.isnan(depth).any():
        raise InputError(f"{path}: depth has {int(np.isnan(depth).sum())} NaN pixels; mark invalid pixels with 0")
    return depth


def predict_files(image: str | Path | None, depth: str | Path | None, model: str | Path | None, out: str | Path,
                  size: int | None = None, depth_scale: float = 1000.0, threads: int | None = None) -> dict:
    """Run the model on image/depth files and write the pictures and arrays to `out`.

    Args:
        size: network input size (None: the model's inference size, 320; 0: the image's own size).
    Returns:
        The arrays (see :meth:`frontiernet.model.Runtime.predict_at_size`).
    """
    runtime = load_runtime(model, threads=threads)
    needs_rgb, needs_depth = runtime.inputs in ("rgbd", "rgb"), runtime.inputs in ("rgbd", "depth")
    if needs_rgb and image is None:
        raise InputError(f"this model takes {runtime.inputs} input: give --image")
    if needs_depth and depth is None:
        raise InputError(f"this model takes {runtime.inputs} input: give --depth (a depth map in metres "
                         f"or millimetres; see --depth-scale)")
    rgb = read_rgb(image) if image is not None else None
    depth_m = read_depth(depth, depth_scale) if depth is not None else None
    size = runtime.conf["inference"]["size"] if size is None else size
    result = runtime.predict_at_size(rgb, depth_m, size)  # the model ignores an input it does not take
    out = ensure_dir(out)
    labels = runtime.labels
    shown = result["rgb"]
    write_image(out / "overlay.png", frontier_overlay(shown, result["distance_field"], result["gain_class"],
                                                      float(labels["frontier_threshold_px"]),
                                                      int(labels["num_classes"])))
    write_image(out / "distance.png", distance_picture(result["distance_field"], float(labels["truncation_px"])))
    if shown is not None:
        write_image(out / "input.png", shown)
    arrays = {key: value for key, value in result.items() if key != "rgb" and value is not None}
    arrays["gain_logits"] = arrays["gain_logits"].astype(np.float16)
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    atomic_write(out / "outputs.npz", lambda temporary: temporary.write_bytes(buffer.getvalue()))
    return result

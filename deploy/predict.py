"""``predict_files(image, depth, model, out)``: the network on one image from disk, with pictures.

Writes to the output folder: ``overlay.png`` (frontier pixels D < l coloured by gain class over
the image), ``distance.png`` (the distance field), ``input.png`` (the network's input after
resizing) and ``outputs.npz`` (``distance_field`` (H, W) float32 px, ``gain_logits`` (K, H, W)
float16, ``gain_class`` (H, W) uint8, ``frontier_mask`` (H, W) bool, ``depth`` (H, W) float32 m).
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from frontiernet.errors import InputError
from frontiernet.io import atomic_write, ensure_dir, write_image
from frontiernet.model.overlay import distance_picture, frontier_overlay
from frontiernet.sequences.images import read_depth, read_rgb

from .runtime import load_runtime


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

"""``predict_files(image, depth, model, out)``: the network on one image from disk, with pictures.

Writes to the output folder: ``overlay.png`` (frontier pixels D < l coloured by gain class over
the image), ``distance.png`` (the distance field), ``input.png`` (the network's input after
resizing) and ``outputs.npz`` (``distance_field`` (H, W) float32 px, ``gain_logits`` (K, H, W)
float16, ``gain_class`` (H, W) uint8, ``frontier_mask`` (H, W) bool, ``depth`` (H, W) float32 m).

The depth is a file, or a monocular depth model's estimate from the image (``--depth
depth_anything_v2`` or ``metric3d_v2``, local weights, ``configs/depth.yaml``): a plain photo then
runs through the RGB + depth model as the explorer runs it on monocular depth (the paper's
filled-dot rows of Table I).
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from frontiernet.config import load_config, merge_user
from frontiernet.errors import InputError
from frontiernet.geometry import check_intrinsics_fit, intrinsics_matrix
from frontiernet.io import ensure_dir, write_bytes, write_image, write_json
from frontiernet.model.network import ENCODER_STRIDE
from frontiernet.model.predictor import beyond_range_invalid, fill_invalid_nearest, working_geometry, working_intrinsics
from frontiernet.model.overlay import distance_picture, frontier_overlay
from frontiernet.sequences.images import read_depth, read_rgb
from frontiernet.sequences.single import LEVEL_FRAME, frame_frontiers

from .runtime import load_runtime

MIN_IMAGE_PX = ENCODER_STRIDE
"""The smallest image (pixels, its short side) predict takes, 32: the network's deepest features have a cell per
32 x 32 px (the encoder's stride), so a smaller image holds not one of them at its own size, and resized to the
network's input (320 px) all its detail is invented (a 1 x 1 px image was upscaled 320 times and run)."""
OUTPUT_FILES = ("overlay.png", "distance.png", "input.png", "outputs.npz", "frontiers.json")
"""The files ``frontiernet predict`` writes in its folder (:func:`predict_files`; frontiers.json with intrinsics)."""


def check_image_size(array: np.ndarray, path) -> None:
    """InputError naming file `path` and its size when image or depth map `array` is under :data:`MIN_IMAGE_PX`
    on a side."""
    height, width = array.shape[:2]
    if min(height, width) < MIN_IMAGE_PX:
        raise InputError(f"{path}: an image of {width} x {height} pixels is too small: predict needs at least "
                         f"{MIN_IMAGE_PX} px on each side (the network's coarsest features are {ENCODER_STRIDE} px "
                         "cells; a smaller image resized to its input would be all invented detail)")


def check_intrinsics_at_size(intrinsics: tuple, width: int, height: int, size: int) -> None:
    """InputError quoting `intrinsics` (fx, fy, cx, cy) as typed when their principal point, which fits the
    `width` x `height` image, falls outside the pixel centres of the network's `size` px input (resized and
    centre-cropped, :func:`~frontiernet.model.predictor.resize_and_crop`), where the 3D frontiers are anchored:
    e.g. cx = 0 (pixel 0's centre moves to -0.17 when 480 px become 320), or a point in the cropped-off part."""
    K = working_intrinsics(intrinsics_matrix(*intrinsics), height, width, size)
    new_w, new_h, left, top, crop_w, crop_h = working_geometry(height, width, size)
    if 0.0 <= K[0, 2] <= crop_w - 1 and 0.0 <= K[1, 2] <= crop_h - 1:  # as pinhole_intrinsics judges it there
        return
    x = [(left + 0.5) * width / new_w - 0.5, (left + crop_w - 0.5) * width / new_w - 0.5]
    y = [(top + 0.5) * height / new_h - 0.5, (top + crop_h - 0.5) * height / new_h - 0.5]
    raise InputError(f"--intrinsics: the principal point ({intrinsics[2]:g}, {intrinsics[3]:g}) lies outside the part "
                     f"of the {width} x {height} image the network sees at --size {size} (resized and centre-cropped: "
                     f"x {x[0]:.6g} to {x[1]:.6g}, y {y[0]:.6g} to {y[1]:.6g} in the image's pixels); check the "
                     f"intrinsics, or give --size 0 (the image as it is)")


def load_predict_config(user_file=None, overrides=()):
    """What ``predict`` reads besides its flags: section ``depth`` (``configs/depth.yaml`` less its
    ``source``, which is ``--depth``: the monocular models' weights and settings) and section
    ``anchoring`` (``configs/explore.yaml``'s, for the 3D frontiers of ``--intrinsics``), then a
    user YAML file and ``key=value`` overrides (``depth.depth_anything_v2.path=DIR``).

    Raises:
        InputError: an unreadable file, an unknown key or a value of the wrong kind.
    """
    from omegaconf import OmegaConf

    from frontiernet.depth import source_options

    conf = OmegaConf.create({"depth": source_options(), "anchoring": load_config("explore").anchoring})
    return merge_user(conf, user_file, overrides, layout={"depth": "depth", "anchoring": "explore.anchoring"})


def depth_model_name(depth: str | Path | None) -> str | None:
    """The depth source that `depth` names (``depth_anything_v2``, ``metric3d_v2``, an alias such as
    ``gt``) when no file of that name exists; None for a file (or nothing)."""
    from frontiernet.depth import DEPTH_SOURCES, depth_source_name

    if depth is None or Path(depth).exists():
        return None
    name = depth_source_name(str(depth))
    return name if name in DEPTH_SOURCES else None


def estimate_depth(name: str, rgb: np.ndarray, K_image: np.ndarray | None, depth_conf) -> np.ndarray:
    """(H, W) float32 metres, NaN invalid: monocular depth source `name`'s estimate for `rgb` (H, W, 3)
    uint8, built from `depth_conf` (the command's ``depth`` section). `K_image` (3, 3) are the image's
    intrinsics; without them a source that reads no focal length gets a nominal one (focal length the
    image's longer side, principal point at its centre), one that does is refused.

    Raises:
        InputError: a source that needs ground truth (none here), absent intrinsics for a source
            that reads them, absent or corrupt weights.
    """
    from frontiernet.depth import DEPTH_SOURCES, make_depth_source, monocular_sources

    source_class = DEPTH_SOURCES.get(name)
    if source_class.requires_ground_truth:
        raise InputError(f"--depth {name}: that source reads a sensor's depth (the simulator's), and predict has "
                         f"none; give a depth map file, or a monocular model: {', '.join(monocular_sources())}")
    if K_image is None and source_class.uses_intrinsics:
        raise InputError(f"--depth {name}: the model reads the camera's focal length; give --intrinsics FX,FY,CX,CY")
    if K_image is None:
        h, w = rgb.shape[:2]
        K_image = intrinsics_matrix(float(max(h, w)), float(max(h, w)), (w - 1) / 2, (h - 1) / 2)
    return make_depth_source(name, depth_conf).estimate(rgb, K_image)


def predict_files(image: str | Path | None, depth: str | Path | None, model: str | Path | None, out: str | Path,
                  size: int | None = None, depth_scale: float | None = None, threads: int | None = None,
                  intrinsics: tuple | None = None, depth_encoding: str = "scale", fill_invalid: bool = False,
                  conf=None) -> dict:
    """Run the model on image/depth files and write the pictures and arrays to `out`.

    Args:
        depth: a depth map file, or the name of a monocular depth model that estimates the depth
            from `image` (:func:`depth_model_name`, :func:`estimate_depth`).
        size: network input size (None: the model's inference size, 320; 0: the image's own size).
        depth_scale, depth_encoding: how the depth file is decoded
            (:func:`frontiernet.sequences.read_depth`); a `depth_scale` given (not None: 1000, millimetres)
            refuses float depth, which it does not apply to.
        fill_invalid: fill the depth's holes from the nearest valid pixel (real sensors; see
            :func:`frontiernet.model.predictor.fill_invalid_nearest`). Off for rendered depth, whose 0
            means beyond range.
        intrinsics: (fx, fy, cx, cy) pixels of the image: also anchor the frontier pixels to 3D
            frontiers and write ``frontiers.json`` (:mod:`frontiernet.sequences.single`; needs depth).
        conf: the command's config (:func:`load_predict_config`; None: the shipped one).
    Returns:
        The arrays (see :meth:`frontiernet.model.Runtime.predict_frame`), with ``frontiers``
        when `intrinsics` were given.
    """
    depth_model = depth_model_name(depth)
    rgb = read_rgb(image) if image is not None else None  # the files first: a bad one fails before the model loads
    depth_read = None if depth is None or depth_model is not None else read_depth(
        depth, 1000.0 if depth_scale is None else depth_scale, depth_encoding, scale_given=depth_scale is not None)
    if rgb is not None or depth_read is not None:  # (a depth of another size than the image is said so below)
        check_image_size(*((rgb, image) if rgb is not None else (depth_read, depth)))
    if model is None:  # the shipped model that takes what was given: RGB + depth, or an RGB photo alone
        from frontiernet.model import shipped_model_path

        model = shipped_model_path("rgb" if image is not None and depth is None else "rgbd")
    runtime = load_runtime(model, threads=threads)
    needs_rgb, needs_depth = runtime.inputs in ("rgbd", "rgb"), runtime.inputs in ("rgbd", "depth")
    if needs_rgb and image is None:
        raise InputError(f"this model takes {runtime.inputs} input: give --image")
    if needs_depth and depth is None:
        raise InputError(f"this model takes {runtime.inputs} input: give --depth (a depth map in metres "
                         f"or millimetres, see --depth-scale; or a monocular model: depth_anything_v2, metric3d_v2)")
    if intrinsics is not None and depth is None:
        raise InputError("--intrinsics anchors frontiers in 3D, which needs --depth")
    conf = load_predict_config() if conf is None else conf
    if depth_model is not None and image is None:
        raise InputError(f"--depth {depth_model} estimates the depth from the image: give --image")
    if intrinsics is not None:
        height, width = (rgb if rgb is not None else depth_read).shape[:2]
        check_intrinsics_fit(*intrinsics, width, height)
        working = runtime.conf["inference"]["size"] if size is None else size
        if working:  # before any picture is written
            check_intrinsics_at_size(intrinsics, width, height, int(working))
    K_image = None if intrinsics is None else intrinsics_matrix(*intrinsics)
    depth_m = depth_read if depth_model is None else estimate_depth(depth_model, rgb, K_image, conf.depth)
    if depth_m is not None and not np.any(depth_m > 0):
        raise InputError(f"{depth}: no valid depth (every pixel is 0, negative or NaN)")
    if depth_m is not None:  # as the simulated sensor the network learnt from: nothing beyond its range
        depth_m = fill_invalid_nearest(depth_m) if fill_invalid else depth_m
        depth_m = np.nan_to_num(beyond_range_invalid(depth_m, runtime.conf["input"]["max_depth_m"]), nan=0.0)
    if rgb is not None and depth_m is not None and rgb.shape[:2] != depth_m.shape:
        raise InputError(f"{depth}: depth map is {depth_m.shape[1]} x {depth_m.shape[0]} but the image is "
                         f"{rgb.shape[1]} x {rgb.shape[0]}; they must be the same size")
    result, K = runtime.predict_frame(rgb, depth_m, K_image, size=size)  # an input the model does not take is ignored
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
    write_bytes(out / "outputs.npz", buffer.getvalue())
    if intrinsics is not None:
        depth_in = result["depth"]  # at the working size, 0 invalid
        result["frontiers"] = frame_frontiers(result["distance_field"], result["gain_class"],
                                              np.where(depth_in > 0, depth_in, np.nan).astype(np.float32), K, K_image,
                                              labels, conf.anchoring,
                                              gain_logits=result["gain_logits"])
        write_json(out / "frontiers.json", {"frame": LEVEL_FRAME, "image": str(image), "depth": str(depth),
                                            "intrinsics": list(intrinsics), "frontiers": result["frontiers"]})
    return result

"""Pass 1 of ``frontiernet sequence``: per frame, depth and the network's 2D outputs, cached.

Each frame's results go to ``<cache>/<index:05d>.npz`` (written atomically) holding

* ``rgb`` (h, w, 3) uint8, ``depth`` (h, w) float32 metres (NaN invalid), ``K`` (3, 3): the
  network's input at its working size (resize + centre crop, intrinsics adjusted; depth
  beyond the model's ``input.max_depth_m`` made invalid, as the simulator's sensor range);
* ``distance_field`` (h, w) float16 px and ``gain_class`` (h, w) uint8: its outputs;
* ``full_depth`` (H, W) float16 metres (NaN invalid): the frame's depth at its own size, for
  the map and the point cloud;
* ``key``: what produced it (frame name, camera intrinsics, model, depth source, working size).

A re-run with the same key reads the file instead of running the depth source and network
again, so an interrupted run resumes where it stopped.
"""

from __future__ import annotations

import io
import json
import logging
import zipfile
import zlib
from pathlib import Path

import numpy as np

from ..errors import InputError, decode_problem
from ..io import ensure_dir, write_bytes

log = logging.getLogger(__name__)


def image_depth(rgb: np.ndarray, sensor: np.ndarray | None, K: np.ndarray, depth_source, name: str) -> np.ndarray:
    """(H, W) float32 metres, NaN invalid: the sensor depth `sensor` (`depth_source` None) or a
    depth source's estimate (given the sensor depth as its ground truth when it needs one);
    `name` names the frame in errors."""
    if depth_source is None:
        if sensor is None:
            raise InputError(f"frame {name} has no depth file: choose a depth model with --depth "
                             f"(depth_anything_v2 or metric3d_v2)")
        return sensor
    if depth_source.requires_ground_truth and sensor is None:
        raise InputError(f"depth source '{depth_source.name}' degrades a sensor depth, but frame {name} has none")
    return depth_source.estimate(rgb, K, sensor)


def cache_key(frame, model_name: str, depth_name: str, conf) -> str:
    """What a cache file was made from; another key (e.g. ``--intrinsics`` changed) recomputes it."""
    K = [round(float(value), 6) for value in np.asarray(frame.camera.K).ravel()]
    return json.dumps({"frame": frame.name, "K": K, "model": model_name, "depth": depth_name, "size": conf["size"],
                       "crop": bool(conf["crop"]), "fill": bool(conf["fill_invalid_depth"])}, sort_keys=True)


def load_cached(path: Path, key: str | None = None) -> dict | None:
    """The arrays of a cache file made with `key` (None: any), or None (absent, unreadable or
    another key). A damaged one (cut short by a full disk or a killed copy: not a zip, a bad member, a
    CRC error) is a cache entry to recompute, with a warning line naming it, not an internal error."""
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            if key is not None and str(data["key"]) != key:
                return None
            return {name: data[name] for name in data.files if name != "key"}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error) as error:
        log.warning("%s: a damaged cache entry (%s); computed again", path, decode_problem(error))
        return None


def cached_full_depth(path: Path) -> np.ndarray:
    """(H, W) float32 metres, NaN invalid: only the ``full_depth`` of a cache file (an npz member
    is decompressed on access: a fifth of reading the whole file)."""
    with np.load(path, allow_pickle=False) as data:
        return data["full_depth"].astype(np.float32)


def perceive_image(rgb: np.ndarray, sensor: np.ndarray | None, K: np.ndarray, runtime, depth_source, conf,
                  name: str) -> dict:
    """Depth and network outputs of one image (the arrays of a cache file, see the module doc):
    `rgb` (H, W, 3) uint8, `sensor` (H, W) float32 metres (NaN invalid) or None, `K` its (3, 3)
    intrinsics.

    The image is resized so its short side is ``conf.size`` px (null: the model's) and, with
    ``conf.crop``, centre-cropped to a square as the public demo does (without: the network sees
    the whole frame). With ``conf.fill_invalid_depth`` the network's depth has its holes filled
    from the nearest valid pixel first (the map keeps them as no return)."""
    from ..model.predictor import beyond_range_invalid, fill_invalid_nearest

    depth = image_depth(rgb, sensor, K, depth_source, name)
    network_depth = fill_invalid_nearest(depth) if conf["fill_invalid_depth"] else depth
    network_depth = beyond_range_invalid(network_depth, runtime.conf["input"]["max_depth_m"])
    result, K_network = runtime.predict_frame(rgb, network_depth, K, size=conf["size"] or None,
                                              crop=bool(conf["crop"]))
    return {"rgb": result["rgb"], "depth": result["depth"], "K": K_network,
            "distance_field": result["distance_field"].astype(np.float16),
            "gain_class": result["gain_class"].astype(np.uint8), "full_depth": depth.astype(np.float16)}


def perceive_frame(frame, stream) -> dict:
    """Pass 1 of one sequence frame: :meth:`FrontierStream.perceive <.stream.FrontierStream.perceive>`
    of its undistorted image, sensor depth (or None) and intrinsics."""
    return stream.perceive(frame.rgb(), frame.depth(), frame.camera.K, name=frame.name)


def perceive_frames(sequence, stream, cache_dir: Path, model_name: str, progress: bool = True) -> list[Path]:
    """Run :func:`perceive_frame` with `stream` (a :class:`~.stream.FrontierStream`) on every frame
    not cached yet; returns the cache files in order."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    cache_dir = ensure_dir(cache_dir)
    depth_name = "sensor" if stream.depth_source is None else stream.depth_source.name
    paths = []
    columns = (TextColumn("perceiving"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn())
    with Progress(*columns, transient=True, disable=not progress) as bar:
        task = bar.add_task("frames", total=len(sequence))
        for frame in sequence:
            path = cache_dir / f"{frame.index:05d}.npz"
            key = cache_key(frame, model_name, depth_name, stream.conf.network)
            if load_cached(path, key) is None:
                arrays = perceive_frame(frame, stream)
                buffer = io.BytesIO()
                np.savez_compressed(buffer, key=np.array(key), **arrays)
                write_bytes(path, buffer.getvalue())
            paths.append(path)
            bar.advance(task)
    return paths

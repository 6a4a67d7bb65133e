"""Posing a plain folder of images with structure from motion (pycolmap on the CPU).

* :func:`read_image_folder`: SIFT features (one camera for the whole folder), sequential or
  exhaustive matching, incremental mapping; returns the :class:`~.frames.Sequence` of the
  registered images (up to scale, ``metric=False``) holding the largest ``pycolmap.Reconstruction``.
* :func:`sparse_depths` and :func:`metric_scale`: the factor that makes such poses metric, from
  the sequence's reconstruction (its triangulated points) and metric depth maps of its frames.

The work folder holds COLMAP's ``database.db`` and the chosen model in ``sparse/0``. A run that
finds ``sparse/0`` loads it instead of reconstructing again (delete the folder to start over);
an interrupted run keeps the database, and COLMAP skips the images and pairs it already holds.
Options come from the ``sfm`` section of ``configs/sequence.yaml``.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import threading
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..config import option_section
from ..errors import InputError
from ..workers import keep_sigterm_handler

with keep_sigterm_handler():  # its import installs glog's handler: SIGTERM printed a native stack trace
    import pycolmap
from .colmap import COLMAP_PIXEL_CENTRE, sequence_from_reconstruction
from .frames import Camera, Sequence
from .readers import check_camera_size, common_image_size, list_images, require_folder

SFM_SUFFIXES = (".jpg", ".jpeg", ".png")
MIN_REGISTERED = 2  # a reconstruction needs two posed images
MIN_SCALE_POINTS = 20  # sparse points on valid depth that metric_scale needs
SFM_OPTIONS = ("matching", "exhaustive_max_images", "sequential_overlap", "max_image_size", "max_num_features",
               "sift_threads", "camera_model", "min_model_size", "seed")
"""The keys of the ``sfm`` section of ``configs/sequence.yaml``."""


def sfm_config(conf) -> dict:
    """The ``sfm`` section of ``configs/sequence.yaml`` (as the command resolved it: every key of
    :data:`SFM_OPTIONS`), checked, as a plain dict; InputError for a missing or unknown key or a
    bad value."""
    options = option_section(conf, SFM_OPTIONS, "sfm")
    if options["matching"] not in ("auto", "sequential", "exhaustive"):
        raise InputError(f"sfm.matching must be auto, sequential or exhaustive, got {options['matching']!r}")
    if options["camera_model"] not in pycolmap.CameraModelId.__members__ or options["camera_model"] == "INVALID":
        raise InputError(f"sfm.camera_model must be a COLMAP camera model (SIMPLE_RADIAL, OPENCV, ...), "
                         f"got {options['camera_model']!r}")
    for key in ("exhaustive_max_images", "sequential_overlap", "max_image_size", "max_num_features",
                "sift_threads", "min_model_size", "seed"):
        if not isinstance(options[key], int) or isinstance(options[key], bool) or options[key] < (key != "seed"):
            raise InputError(f"sfm.{key} must be a{' non-negative' if key == 'seed' else ' positive'} integer, "
                             f"got {options[key]!r}")
    return options


def check_image_count(count: int, where, holds: str = "the folder holds") -> None:
    """InputError naming `where` (an image folder, a recording without poses) when its `count` images are
    fewer than a reconstruction poses (:data:`MIN_REGISTERED`): one image never is, and pycolmap's
    "0 of 1 registered" advised taking frames closer together."""
    if count < MIN_REGISTERED:
        raise InputError(f"{where}: a reconstruction needs at least two overlapping images, {holds} {count}")


def folder_images(root: Path) -> tuple[list[str], tuple[int, int]]:
    """Names of the jpg/png images directly in `root`, sorted, and their common (width, height);
    InputError if there are fewer than two (:func:`check_image_count`) or their sizes differ (read
    from the file headers)."""
    paths = [path for path in list_images(root) if path.suffix.lower() in SFM_SUFFIXES]
    if not paths:
        raise InputError(f"{root}: no .jpg/.jpeg/.png images in the folder")
    check_image_count(len(paths), root)
    return [path.name for path in paths], common_image_size(paths)


def _check_camera(camera: Camera, size: tuple[int, int], root: Path) -> None:
    check_camera_size(camera, size, root)
    if camera.remap is not None:
        raise InputError(f"{root}: the given camera has lens distortion; give pinhole intrinsics of the images "
                         "or none (COLMAP then estimates them)")


# ----------------------------------------------------------------------------- running pycolmap

@contextmanager
def _stage(bar, task, text: str):
    """Shows `text` on the progress bar while a stage runs, then advances it."""
    bar.update(task, description=text)
    yield
    bar.advance(task)


def _cancellable(function, *args, **kwargs):
    """``function(*args, cancellation_token=..., **kwargs)`` in a worker thread (pycolmap releases
    the GIL), so that Ctrl-C cancels COLMAP and raises KeyboardInterrupt here."""
    token, result, done = pycolmap.CancellationToken(), {}, threading.Event()

    def work():
        try:
            result["value"] = function(*args, cancellation_token=token, **kwargs)
        except BaseException as error:  # noqa: BLE001 - handed to the caller's thread, re-raised there
            result["error"] = error
        finally:
            done.set()

    threading.Thread(target=work, daemon=True).start()
    try:  # (an Event, not Thread.join: Python 3.11's join interrupted by Ctrl-C marks a running thread ended,
        while not done.wait(0.1):  # and the exit then killed COLMAP's thread mid-call: "terminate called")
            pass
    except KeyboardInterrupt:
        token.cancel()
        done.wait()
        raise
    if "error" in result:
        raise result["error"]
    return result.get("value")


def _reader_options(camera: Camera | None, options: dict) -> pycolmap.ImageReaderOptions:
    """Fixed PINHOLE intrinsics from `camera`, else the config's model for COLMAP to estimate.

    COLMAP puts the top-left pixel's centre at (0.5, 0.5) (OpenCV: (0, 0)): the principal point shifts.
    """
    reader = pycolmap.ImageReaderOptions()
    if camera is None:
        reader.camera_model = str(options["camera_model"])
        return reader
    K = camera.K
    reader.camera_model = "PINHOLE"
    reader.camera_params = ",".join(f"{v:.10g}" for v in (K[0, 0], K[1, 1], K[0, 2] + COLMAP_PIXEL_CENTRE,
                                                                K[1, 2] + COLMAP_PIXEL_CENTRE))
    return reader


def _extract_and_match(database: Path, root: Path, names: list[str], camera: Camera | None, options: dict,
                       bar, task) -> None:
    """SIFT features of `names` (one shared camera) and matched, verified pairs into `database`."""
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.num_threads = int(options["sift_threads"])
    extraction.max_image_size = int(options["max_image_size"])
    extraction.sift.max_num_features = int(options["max_num_features"])
    with _stage(bar, task, f"SIFT features of {len(names)} images"):
        _cancellable(pycolmap.extract_features, database, root, image_names=names,
                     camera_mode=pycolmap.CameraMode.SINGLE, reader_options=_reader_options(camera, options),
                     extraction_options=extraction, device=pycolmap.Device.cpu)
    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = int(options["sift_threads"])
    mode = options["matching"]
    if mode == "auto":
        mode = "exhaustive" if len(names) < int(options["exhaustive_max_images"]) else "sequential"
    with _stage(bar, task, f"{mode} matching"):
        if mode == "exhaustive":
            _cancellable(pycolmap.match_exhaustive, database, matching_options=matching, device=pycolmap.Device.cpu)
        else:
            pairing = pycolmap.SequentialPairingOptions()
            pairing.overlap = int(options["sequential_overlap"])
            pairing.loop_detection = False
            _cancellable(pycolmap.match_sequential, database, matching_options=matching, pairing_options=pairing,
                         device=pycolmap.Device.cpu)


def _map(database: Path, root: Path, work_dir: Path, fixed_intrinsics: bool, options: dict, bar, task
         ) -> pycolmap.Reconstruction | None:
    """Incremental mapping; the model with the most registered images, moved to ``sparse/0``."""
    mapping = pycolmap.IncrementalPipelineOptions()
    mapping.min_model_size, mapping.random_seed = int(options["min_model_size"]), int(options["seed"])
    if fixed_intrinsics:
        mapping.ba_refine_focal_length = mapping.ba_refine_principal_point = mapping.ba_refine_extra_params = False
        mapping.mapper.abs_pose_refine_focal_length = mapping.mapper.abs_pose_refine_extra_params = False
    models_dir = work_dir / "models"
    shutil.rmtree(models_dir, ignore_errors=True)  # partial models of an interrupted run
    models_dir.mkdir(parents=True)
    (work_dir / "sparse").mkdir(exist_ok=True)
    registered = [0]

    def next_image():  # called from COLMAP's thread after each registration
        registered[0] += 1
        bar.update(task, description=f"mapping: {registered[0]} images registered")

    with _stage(bar, task, "mapping"):
        models = _cancellable(pycolmap.incremental_mapping, database, root, models_dir, mapping,
                              next_image_callback=next_image)
    best = max(models.values(), key=lambda model: model.num_reg_images()) if models else None
    if best is not None:
        (models_dir / "best").mkdir()
        best.write(models_dir / "best")
        shutil.rmtree(work_dir / "sparse" / "0", ignore_errors=True)  # an incomplete one
        os.replace(models_dir / "best", work_dir / "sparse" / "0")  # whole, or not at all
    shutil.rmtree(models_dir, ignore_errors=True)
    return best


def _existing_model(work_dir: Path, names: list[str]) -> pycolmap.Reconstruction | None:
    """The model a previous run left in ``work_dir/sparse/0``, or None; InputError if it holds
    images the folder does not."""
    path = work_dir / "sparse" / "0"
    if not any((path / f"images.{ext}").is_file() for ext in ("bin", "txt")):
        return None
    try:
        model = pycolmap.Reconstruction(path)
    except Exception as error:  # noqa: BLE001 - pycolmap raises plain RuntimeError / ValueError here
        raise InputError(f"{path}: the saved COLMAP model is not readable ({type(error).__name__}); "
                         f"delete {work_dir} to reconstruct again") from None
    stale = sorted({image.name for image in model.images.values()} - set(names))
    if stale:
        raise InputError(f"{path}: the saved COLMAP model has images that are not in the folder (first: {stale[0]}); "
                         f"delete {work_dir} to reconstruct again")
    return model


@contextmanager
def _quiet_colmap(quiet: bool):
    """COLMAP's log lines off while `quiet`: the progress line tells the stage, and a failure is our
    one line (:func:`reconstruct`'s InputError), not COLMAP's error line before it."""
    level = pycolmap.logging.minloglevel
    if quiet:
        pycolmap.logging.minloglevel = int(pycolmap.logging.FATAL)
    try:
        yield
    finally:
        pycolmap.logging.minloglevel = level


@contextmanager
def _work_folder(work_dir):
    if work_dir is not None:
        path = Path(work_dir)
        path.mkdir(parents=True, exist_ok=True)
        yield path
        return
    with tempfile.TemporaryDirectory(prefix="frontiernet-colmap-") as path:
        yield Path(path)


def read_image_folder(root, camera: Camera | None = None, work_dir=None, *, conf, progress: bool = True
                      ) -> Sequence:
    """Poses of a folder of images from pycolmap's incremental structure from motion (CPU).

    Args:
        root: folder of .jpg/.jpeg/.png images of one camera at one size, taken in name order.
        camera: pinhole intrinsics (``remap`` None) to fix; None: COLMAP estimates
            ``sfm.camera_model`` (SIMPLE_RADIAL by default), and frames come out undistorted.
        work_dir: folder for ``database.db`` and ``sparse/0``; a model found there is loaded
            instead of reconstructing (`camera` and `conf` then have no effect). None: a
            temporary folder, deleted afterwards.
        conf: the ``sfm`` section of ``configs/sequence.yaml`` (:func:`sfm_config`).
        progress: show a rich progress line (and COLMAP's log off: a failure is one InputError); Ctrl-C cancels.
    Returns:
        One frame per registered image, sorted by name, with ``T_world_cam`` (4, 4) float64 in
        COLMAP's world frame and units (``metric=False``), the registration rate in ``notes``, and
        the largest reconstruction as ``reconstruction`` (its points are in the same world frame,
        see :func:`sparse_depths`).
    Raises:
        InputError: no images, mixed sizes, a camera that does not fit, fewer than 2 images registered.
    """
    from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    root = require_folder(root, "image")
    options = sfm_config(conf)
    names, size = folder_images(root)
    if camera is not None:
        _check_camera(camera, size, root)
    pycolmap.set_random_seed(int(options["seed"]))
    with _work_folder(work_dir) as work, _quiet_colmap(progress), \
            Progress(SpinnerColumn(), TextColumn("colmap: {task.description}"), TimeElapsedColumn(),
                     transient=True, disable=not progress) as bar:
        task = bar.add_task("starting", total=3)
        model = _existing_model(work, names)
        reused = model is not None
        if model is None:
            database = work / "database.db"
            _extract_and_match(database, root, names, camera, options, bar, task)
            model = _map(database, root, work, camera is not None, options, bar, task)
        count = 0 if model is None else model.num_reg_images()
        if count < MIN_REGISTERED:
            raise InputError(f"{root}: pycolmap could not reconstruct the images ({count} of {len(names)} registered); "
                             "it needs overlapping views of textured surfaces: take frames closer together "
                             "(more overlap), avoid blank walls, fast turns and motion blur")
        sequence = sequence_from_reconstruction(model, root, root, format="images")
    sequence.notes.append(f"pycolmap registered {count} of {len(names)} images ({100.0 * count / len(names):.0f}%)")
    if reused:
        sequence.notes.append(f"reused the COLMAP model in {Path(work_dir) / 'sparse' / '0'}")
    return sequence


# ----------------------------------------------------------------------------- metric scale

def sparse_depths(sequence: Sequence) -> dict[int, np.ndarray]:
    """The triangulated points of the sequence's reconstruction each of its frames observes,
    matched by image name.

    Returns:
        frame index -> (N, 3) float64 rows (u, v, z): the point in the frame's undistorted image
        (OpenCV pixels, centres at integers, through the frame's ``K``) and its z-depth in the
        reconstruction's units (its own pose, so a transformed sequence gives the same); points in
        front of the camera only.
    Raises:
        InputError: the sequence has no reconstruction (it did not come from COLMAP or pycolmap).
    """
    reconstruction = sequence.reconstruction
    if reconstruction is None:
        raise InputError(f"{sequence.root}: the sequence has no COLMAP reconstruction whose points give the scale")
    points = {}
    for frame in sequence:
        image = reconstruction.find_image_with_name(frame.name)
        if image is None or not image.has_pose:
            continue
        ids = [p.point3D_id for p in image.points2D if p.has_point3D()]
        world = np.array([reconstruction.points3D[i].xyz for i in ids]).reshape(-1, 3)  # (N, 3)
        cam_from_world = np.asarray(image.cam_from_world().matrix())  # (3, 4) world -> OpenCV camera
        cam = world @ cam_from_world[:, :3].T + cam_from_world[:, 3]
        cam = cam[cam[:, 2] > 1e-9]
        K = frame.camera.K
        points[frame.index] = np.column_stack([cam[:, :2] / cam[:, 2:] @ K[:2, :2].T + K[:2, 2], cam[:, 2]])
    return points


def _log_ratios(frame, points: np.ndarray, depth) -> np.ndarray:
    """(M,) log(metres / model z) of `points` (N, 3) (u, v, z) on valid pixels of `depth` (H, W)."""
    depth = np.asarray(depth, np.float32)
    if depth.shape != (frame.camera.height, frame.camera.width):
        raise InputError(f"depth map of frame {frame.index} ({frame.name}) is {depth.shape[1]} x {depth.shape[0]} "
                         f"px but the frame is {frame.camera.width} x {frame.camera.height}")
    col, row = np.rint(points[:, 0]).astype(int), np.rint(points[:, 1]).astype(int)
    inside = (col >= 0) & (col < depth.shape[1]) & (row >= 0) & (row < depth.shape[0])
    metres, z = depth[row[inside], col[inside]], points[inside, 2]
    valid = np.isfinite(metres) & (metres > 0)
    return np.log(metres[valid] / z[valid])


def metric_scale(sequence: Sequence, depth_maps: dict) -> tuple[float, dict]:
    """The factor from the reconstruction's units to metres.

    For every frame with a depth map, the z-depth of each triangulated point it sees
    (:func:`sparse_depths`) is compared with the depth map at the point's nearest pixel; the scale
    is the median of all ratios (metres / model units). Make the sequence from
    :func:`read_image_folder` metric by multiplying its camera positions by the scale.

    Args:
        sequence: a sequence with its ``reconstruction`` (COLMAP model or image folder).
        depth_maps: frame index -> (H, W) float32 metres, NaN invalid, at the frame's undistorted size.
    Returns:
        (scale, stats): stats ``points`` (ratios used), ``images`` (frames contributing) and
        ``spread`` (median absolute deviation of the log ratios: 0.05 is about 5%).
    Raises:
        InputError: no reconstruction, a depth map of the wrong size, or fewer than 20 points on valid depth.
    """
    sparse = sparse_depths(sequence)
    ratios = [_log_ratios(frame, sparse[frame.index], depth_maps[frame.index])
              for frame in sequence if frame.index in depth_maps and frame.index in sparse]
    images = sum(1 for r in ratios if len(r))
    ratios = np.concatenate(ratios) if ratios else np.zeros(0)
    if len(ratios) < MIN_SCALE_POINTS:
        raise InputError(f"{sequence.root}: only {len(ratios)} reconstructed points fall on valid depth "
                         f"(at least {MIN_SCALE_POINTS} needed to find the metric scale)")
    median = float(np.median(ratios))
    spread = float(np.median(np.abs(ratios - median)))
    return float(np.exp(median)), {"points": len(ratios), "images": images, "spread": spread}

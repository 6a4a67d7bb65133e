"""COLMAP sparse models as posed sequences (issue "Real captured data").

* :func:`read_colmap`: a model folder (binary or text) or a project folder holding ``sparse/0``
  or ``sparse`` and ``images/``, read with pycolmap.
* :func:`sequence_from_reconstruction`: the shared core, for any ``pycolmap.Reconstruction``
  (also the structure-from-motion reader's).
* :func:`colmap_camera`: a COLMAP camera as a pinhole :class:`Camera`, with remap tables for
  models with lens distortion.

Pixel coordinates: COLMAP puts the centre of the top-left pixel at (0.5, 0.5) (its feature
extractor adds 0.5 to pixel indices and its principal points refer to that frame), OpenCV and
this package at (0, 0). So a COLMAP principal point (cx, cy) is (cx - 0.5, cy - 0.5) here, and a
point that pycolmap's ``img_from_cam`` projects to (x, y) lies at pixel (x - 0.5, y - 0.5) of the
raw image. pycolmap itself adds no offset: ``img_from_cam`` returns ``fx * X / Z + cx`` (plus
distortion).

Poses: COLMAP stores ``cam_from_world`` (world to OpenCV camera axes); ``T_world_cam`` is its
inverse. The world frame and scale are COLMAP's (arbitrary), so :attr:`Sequence.metric` is False.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..geometry import intrinsics_matrix, quaternion_rotations, rigid_pose
from ..io import input_file, input_folder, present
from ..workers import keep_sigterm_handler

with keep_sigterm_handler():  # its import installs glog's handler: SIGTERM printed a native stack trace
    import pycolmap
from .frames import Camera, Sequence, SequenceFrame
from .readers import IMAGE_SUFFIXES, image_size

COLMAP_PIXEL_CENTRE = 0.5  # COLMAP's coordinate of the top-left pixel's centre (OpenCV: 0)
PINHOLE_MODELS = ("SIMPLE_PINHOLE", "PINHOLE")
MODEL_FILES = ("cameras.bin", "cameras.txt")
MODEL_PARTS = ("cameras", "images", "points3D", "rigs", "frames")
"""The files of a COLMAP model, each ``.bin`` or ``.txt`` (rigs and frames since COLMAP 3.12)."""
MODEL_SUBFOLDERS = (".", "sparse/0", "sparse")
_REMAP_CHUNK_PIXELS = 1 << 20  # pixels projected per pycolmap call (bounds the memory of big images)


def find_model(path: Path) -> Path | None:
    """The COLMAP model folder at `path`, in ``path/sparse/0`` or in ``path/sparse`` (the first with
    ``cameras.bin`` or ``cameras.txt``, of whatever kind: :func:`check_model_files` names a pipe, a folder or a
    link to nothing there, which was "no COLMAP model"); None if there is none."""
    for subfolder in MODEL_SUBFOLDERS:
        folder = path / subfolder
        if any(present(folder / name) for name in MODEL_FILES):
            return folder
    return None


def check_model_files(model: Path) -> None:
    """InputError naming the first file of COLMAP model folder `model` (:data:`MODEL_PARTS`) that is there but is
    no regular file (:func:`~frontiernet.io.input_file`): pycolmap waited for ever on a pipe."""
    for part in MODEL_PARTS:
        for suffix in (".bin", ".txt"):
            if present(model / f"{part}{suffix}"):
                input_file(model / f"{part}{suffix}", "COLMAP model file")


def _default_image_dir(path: Path, model_dir: Path) -> Path:
    """``images/`` of the project folder `path`, else the model folder's sibling (``sparse/images``
    or, for ``sparse/0``, the project's ``images``); where none is a folder, the first that is something else (a
    file, a pipe, a link to nothing) is named as such (:func:`~frontiernet.io.input_folder`), not "no image folder"."""
    candidates = [path / "images", model_dir.parent / "images", model_dir.parent.parent / "images"]
    for candidate in candidates:
        if candidate.is_dir():
            return candidate
    for candidate in candidates:
        if present(candidate):
            input_folder(candidate, "image")
    raise InputError(f"{path}: no image folder for the COLMAP model (looked for "
                     f"{', '.join(str(c) for c in dict.fromkeys(candidates))}); pass image_dir")


def _undistortion_maps(camera: pycolmap.Camera, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(map_x, map_y), each (height, width) float32: the raw-image pixel (OpenCV convention) that
    each pixel of the pinhole image with intrinsics `K` (3, 3) sees, via pycolmap's projection."""
    width, height = camera.width, camera.height
    maps = np.empty((height, width, 2), np.float32)
    x = (np.arange(width) - K[0, 2]) / K[0, 0]
    rows_per_chunk = max(1, _REMAP_CHUNK_PIXELS // width)
    for top in range(0, height, rows_per_chunk):
        y = (np.arange(top, min(top + rows_per_chunk, height)) - K[1, 2]) / K[1, 1]
        ray_x, ray_y = np.meshgrid(x, y)
        rays = np.stack([ray_x.ravel(), ray_y.ravel(), np.ones(ray_x.size)], axis=1)  # K^-1 [u, v, 1]
        pixels = camera.img_from_cam(rays, check_cheirality=False) - COLMAP_PIXEL_CENTRE
        maps[top:top + len(y)] = pixels.reshape(len(y), width, 2)
    maps = np.nan_to_num(maps, nan=-1.0)  # rays the model cannot project: outside the raw image
    return np.ascontiguousarray(maps[..., 0]), np.ascontiguousarray(maps[..., 1])


def colmap_camera(camera: pycolmap.Camera) -> Camera:
    """A COLMAP camera as a :class:`Camera` of the same size in OpenCV pixel convention.

    PINHOLE / SIMPLE_PINHOLE: its own intrinsics, no remap. Any other (perspective or fisheye)
    model: a pinhole with the camera's mean focal length and principal point, and remap tables
    from the raw image. Spherical models are an InputError.
    """
    model = camera.model.name
    if camera.is_spherical():
        raise InputError(f"COLMAP camera {camera.camera_id}: the spherical model {model} has no pinhole equivalent")
    if model in PINHOLE_MODELS:
        K = np.array(camera.calibration_matrix(), np.float64)
        K[:2, 2] -= COLMAP_PIXEL_CENTRE
        return Camera(camera.width, camera.height, K, model)
    focal = camera.mean_focal_length()
    K = intrinsics_matrix(focal, focal, camera.principal_point_x - COLMAP_PIXEL_CENTRE,
                          camera.principal_point_y - COLMAP_PIXEL_CENTRE)
    return Camera(camera.width, camera.height, K, model, remap=_undistortion_maps(camera, K))


def world_from_cam(image: pycolmap.Image, what: str = "COLMAP image") -> np.ndarray:
    """(4, 4) float64 ``T_world_cam`` of a registered image: the inverse of its ``cam_from_world``.

    InputError naming `what` for a quaternion of zero length (pycolmap's ``matrix()`` makes it the
    identity rotation) or not finite; one of another length is left to :func:`rigid_pose` to refuse."""
    quaternion_rotations(image.cam_from_world().rotation.quat, what)
    cam_from_world = np.asarray(image.cam_from_world().matrix(), np.float64)  # (3, 4) [R | t]
    rotation, translation = cam_from_world[:, :3], cam_from_world[:, 3]
    pose = np.eye(4)
    pose[:3, :3] = rotation.T
    pose[:3, 3] = -rotation.T @ translation
    return pose


def _count_image_files(image_dir: Path) -> int:
    return sum(1 for path in image_dir.rglob("*") if path.suffix.lower() in IMAGE_SUFFIXES and path.is_file())


def _depth_paths(names: list[str], depth_dir: Path) -> list[Path]:
    """The depth file (``.png`` or ``.npy``, same stem and subfolder) of each image name; one of the wrong kind
    (a folder, a pipe, a link to nothing) is named as such where no file of the other suffix is there."""
    paths, missing = [], []
    for name in names:
        candidates = [depth_dir / Path(name).with_suffix(suffix) for suffix in (".png", ".npy")]
        found = next((path for path in candidates if path.is_file()), None)
        if found is None and any(present(path) for path in candidates):
            input_file(next(path for path in candidates if present(path)), "depth file")
        if found is None:
            missing.append(candidates[0])
        paths.append(found)
    if missing:
        raise InputError(f"{missing[0]}: depth file not found (nor .npy; {len(missing)} of {len(names)} "
                         f"images have no depth in {depth_dir})")
    return paths


def _check_image_files(paths: list[Path], image_dir: Path) -> None:
    """InputError naming the first image of `paths` that is of the wrong kind (a folder, a pipe, a link to nothing:
    :func:`~frontiernet.io.input_file`), else the first missing one."""
    for path in paths:
        if present(path) and not path.is_file():
            input_file(path, "image of the COLMAP model")
    missing = [path for path in paths if not path.is_file()]
    if missing:
        raise InputError(f"{missing[0]}: image of the COLMAP model not found ({len(missing)} of {len(paths)} "
                         f"registered images missing in {image_dir})")


def _check_size(path: Path, what: str, camera: Camera, camera_id: int) -> None:
    size = image_size(path)
    if size != (camera.width, camera.height):
        raise InputError(f"{path}: {what} is {size[0]} x {size[1]} px but COLMAP camera {camera_id} "
                         f"is {camera.width} x {camera.height}")


def sequence_from_reconstruction(reconstruction: pycolmap.Reconstruction, image_dir: Path, root: Path,
                                 format: str = "colmap", depth_dir: Path | None = None) -> Sequence:
    """One frame per registered image of `reconstruction` (sorted by name), its file in
    `image_dir`, with ``T_world_cam`` and undistortion per :func:`colmap_camera`.

    `depth_dir`: optional depth files with the images' stems (16-bit millimetre ``.png`` or
    ``.npy`` metres). Not metric (COLMAP's scale is arbitrary). InputError for missing image or
    depth files, for images whose size is not their camera's and for a pose that is no rigid transform.
    """
    image_dir = Path(image_dir)
    images = sorted((image for image in reconstruction.images.values() if image.has_pose), key=lambda im: im.name)
    if not images:
        raise InputError(f"{root}: the COLMAP model has no registered images")
    paths = [image_dir / image.name for image in images]
    _check_image_files(paths, image_dir)
    depth = _depth_paths([image.name for image in images], Path(depth_dir)) if depth_dir else [None] * len(images)
    cameras = {}
    frames = []
    for index, (image, path) in enumerate(zip(images, paths)):
        if image.camera_id not in cameras:
            cameras[image.camera_id] = colmap_camera(reconstruction.cameras[image.camera_id]).checked(
                f"{root}: COLMAP camera {image.camera_id}")
        camera = cameras[image.camera_id]
        for file, what in ((path, "image"), (depth[index], "depth")):
            if file is not None:
                _check_size(file, what, camera, image.camera_id)
        what = f"{root}: the COLMAP model's pose of image {image.name}"
        pose = rigid_pose(world_from_cam(image, what), what)
        frames.append(SequenceFrame(index=index, name=image.name, rgb_path=path, camera=camera, T_world_cam=pose,
                                    depth_path=depth[index], depth_scale=1000.0))
    registered = (f"{len(images)} of {reconstruction.num_images()} images in the model registered; "
                  f"{_count_image_files(image_dir)} image files in {image_dir}")
    notes = [registered, "poses are up to an unknown scale (COLMAP)"]
    return Sequence(frames, format, Path(root), metric=False, notes=notes, reconstruction=reconstruction)


def read_colmap(model_dir: str | Path, image_dir: str | Path | None = None,
                depth_dir: str | Path | None = None) -> Sequence:
    """A COLMAP sparse model (``cameras``, ``images``, ``points3D`` as .bin or .txt) in `model_dir`,
    or a project folder with the model in ``sparse/0`` or ``sparse``.

    `image_dir` defaults to the project's ``images/`` (or the model folder's sibling ``images``);
    `depth_dir` (see :func:`sequence_from_reconstruction`) to a ``depth/`` folder beside it, if any.
    """
    path = input_folder(model_dir, "COLMAP model")
    model = find_model(path)
    if model is None:
        raise InputError(f"{path}: no COLMAP model (looked for {' or '.join(MODEL_FILES)} in "
                         f"{', '.join(MODEL_SUBFOLDERS)})")
    check_model_files(model)
    image_dir = input_folder(image_dir if image_dir is not None else _default_image_dir(path, model), "image")
    if depth_dir is None and present(image_dir.parent / "depth"):  # a file, a pipe or a link to nothing: named
        depth_dir = input_folder(image_dir.parent / "depth", "COLMAP depth")
    try:
        reconstruction = pycolmap.Reconstruction(model)
    except (ValueError, RuntimeError, IndexError, KeyError) as error:  # pycolmap's failed checks (ValueError
        # in 4.2; IndexError for an id no other file holds: an image's camera is its trivial rig, "Rig with ID 9")
        reason = (str(error).strip().strip("'").splitlines() or [type(error).__name__])[-1]
        if isinstance(error, (IndexError, KeyError)):
            reason += "; an id in one file that the others do not hold, e.g. an image's CAMERA_ID not in cameras.txt"
        raise InputError(f"{model}: not a readable COLMAP model ({reason})") from None
    return sequence_from_reconstruction(reconstruction, image_dir, path, depth_dir=depth_dir)

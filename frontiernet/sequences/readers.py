"""Readers of posed RGB-D sequences in the TUM RGB-D and Redwood layouts (issue "Real captured data").

* :func:`read_tum`: ``rgb.txt``, ``depth.txt``, ``groundtruth.txt``; colour frames take the nearest
  depth frame and the ground-truth pose interpolated at their timestamp.
* :func:`read_redwood`: a colour folder, optional ``depth/`` and a ``.log`` trajectory, matched by
  sorted file order (Redwood, Augmented ICL-NUIM, Open3D's reconstruction system).
* File helpers the other readers share: :func:`list_images`, :func:`image_size`,
  :func:`common_image_size`, :func:`check_camera_size`.

Both formats store ``T_world_cam`` (camera-to-world, metres, OpenCV camera axes) in the dataset's
own world frame (often the first camera's, not necessarily Z-up).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from PIL import Image, UnidentifiedImageError
from scipy.spatial.transform import Rotation, Slerp

from ..errors import InputError
from ..geometry import MAX_COORDINATE_M, quaternion_rotations, rigid_pose
from ..array_files import read_npy
from ..io import input_file, input_folder, present
from .frames import Camera, Sequence, SequenceFrame

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm", ".pgm", ".webp")
REDWOOD_COLOUR_FOLDERS = ("color", "image", "rgb")
REDWOOD_INTRINSIC_FILES = ("camera_intrinsic.json", "intrinsic.json")
# TUM's recommended intrinsics for its registered images (ROS default), which are also Open3D's
# PrimeSenseDefault: fx, fy, cx, cy in pixels, of 640 x 480 frames.
DEFAULT_INTRINSICS = (525.0, 525.0, 319.5, 239.5)
DEFAULT_INTRINSICS_SIZE = (640, 480)
TUM_DEPTH_SCALE = 5000.0  # TUM RGB-D depth PNGs: 5000 units per metre
REDWOOD_DEPTH_SCALE = 1000.0  # Redwood depth PNGs: millimetres
TUM_LISTS = {"rgb.txt": "TUM colour image list", "depth.txt": "TUM depth image list"}
"""A TUM sequence's image lists, and what a refusal of one of the wrong kind calls it."""


# ----------------------------------------------------------------------------- shared file helpers

def require_folder(path: str | Path, what: str) -> Path:
    """`path` as a Path if it is a folder; InputError naming it and `what` it should be otherwise
    (:func:`~frontiernet.io.input_folder`)."""
    return input_folder(path, what)


def list_images(folder: Path) -> list[Path]:
    """The image files directly in `folder` (by suffix, hidden files skipped), sorted by name;
    InputError if there are none, or naming an entry named like an image that is no file (a folder
    ``00001.jpg`` where a frame is expected: :func:`~frontiernet.io.input_file`)."""
    images = sorted(path for path in folder.iterdir()
                    if not path.name.startswith(".") and path.suffix.lower() in IMAGE_SUFFIXES)
    for path in images:
        input_file(path, "image")
    if not images:
        raise InputError(f"{folder}: no images in the folder (looked for {', '.join(IMAGE_SUFFIXES)})")
    return images


def image_size(path: Path) -> tuple[int, int]:
    """(width, height) in pixels of an image (from its header, no pixels decoded) or a ``.npy`` depth map."""
    input_file(path)
    if path.suffix.lower() == ".npy":
        shape = read_npy(path, mmap_mode="r").shape
        if len(shape) != 2:
            raise InputError(f"{path}: depth must be a (H, W) array, got shape {tuple(shape)}")
        return int(shape[1]), int(shape[0])
    try:
        with Image.open(path) as image:
            return image.size
    except (UnidentifiedImageError, OSError):
        raise InputError(f"{path}: not a readable image") from None
    except Image.DecompressionBombError as error:  # a header claiming billions of pixels
        raise InputError(f"{path}: not an image this reads ({error})") from None


def common_image_size(paths: list[Path], expected: tuple[int, int] | None = None, what: str = "image") -> tuple[int, int]:
    """The (width, height) all `paths` share (`expected`, or the first one's size); InputError naming
    the first file of another size."""
    size = expected or image_size(paths[0])
    for path in paths:
        other = image_size(path)
        if other != size:
            reference = "the colour images" if expected else paths[0].name
            raise InputError(f"{path}: {what} is {other[0]} x {other[1]} px but {reference} "
                             f"{'are' if expected else 'is'} {size[0]} x {size[1]} (images of mixed sizes)")
    return size


def check_camera_size(camera: Camera, size: tuple[int, int], source: Path) -> Camera:
    """`camera` if it is `size` (width, height) px; InputError naming `source` (the images) otherwise."""
    if (camera.width, camera.height) != tuple(size):
        raise InputError(f"{source}: images are {size[0]} x {size[1]} px but the camera is "
                         f"{camera.width} x {camera.height}")
    return camera


def default_camera(size: tuple[int, int]) -> Camera:
    """The :data:`DEFAULT_INTRINSICS` pinhole camera at `size` (width, height) px."""
    return Camera.pinhole(*DEFAULT_INTRINSICS, *size)


def _number_rows(path: Path, columns: int, what: str = "file") -> list[tuple[int, list[str]]]:
    """(line number, fields) of the non-empty, non-``#`` lines of a text file with at least
    `columns` whitespace-separated fields; InputError naming the file and line otherwise, or the file when it
    is no regular file (`what` it should be: :func:`~frontiernet.io.input_file`). A UTF-8 byte-order
    mark (Windows editors write one) is no part of the first line (it made a comment line a bad number's).
    The other text files of the sequence formats are read so as well."""
    input_file(path, what)
    rows = []
    for number, line in enumerate(path.read_text("utf-8-sig", errors="replace").splitlines(), 1):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            continue
        if len(fields) < columns:
            raise InputError(f"{path}:{number}: expected {columns} fields, got '{line.strip()}'")
        rows.append((number, fields))
    return rows


def _floats(path: Path, number: int, fields: list[str]) -> list[float]:
    """The numbers of line `number` of `path`; InputError naming the line for text, NaN or infinity."""
    try:
        values = [float(field) for field in fields]
    except ValueError:
        values = [np.nan]
    if not np.all(np.isfinite(values)):
        raise InputError(f"{path}:{number}: expected finite numbers, got '{' '.join(fields)}'")
    return values


def check_positions(positions: np.ndarray, places: list[str]) -> None:
    """InputError naming the place (``file:line``) of the first of the (N, 3) camera `positions` (metres) farther than
    :data:`~frontiernet.geometry.MAX_COORDINATE_M` from the origin on an axis (the bound of a typed ``--pose``), as
    the trajectory is read: a pose 1e6 m off made a map of 368 GiB, a MemoryError once every frame was perceived,
    and 1e30 m a voxel count that overflowed (a numpy warning, then "map shape must be 3 positive voxel counts")."""
    far = np.flatnonzero(np.abs(positions).max(axis=1, initial=0.0) > MAX_COORDINATE_M)
    if len(far):
        x, y, z = positions[far[0]]
        raise InputError(f"{places[far[0]]}: position ({x:g}, {y:g}, {z:g}) m lies farther than {MAX_COORDINATE_M:g} m "
                         "from the origin (no captured sequence spans that far; check the units are metres)")


# ----------------------------------------------------------------------------- TUM RGB-D

def _read_tum_list(path: Path, what: str) -> tuple[np.ndarray, list[str]]:
    """(timestamps (N,) float64 seconds, relative paths) of a TUM ``rgb.txt`` / ``depth.txt`` (`what`), sorted by
    time."""
    rows = _number_rows(path, 2, what)
    if not rows:
        raise InputError(f"{path}: no entries (lines 'timestamp path' expected)")
    times = np.array([_floats(path, number, fields[:1])[0] for number, fields in rows])
    order = np.argsort(times, kind="stable")
    return times[order], [rows[i][1][1] for i in order]


def _read_tum_groundtruth(path: Path) -> tuple[np.ndarray, np.ndarray, Rotation]:
    """(timestamps (N,) s, translations (N, 3) m, rotations) of a ``groundtruth.txt``, sorted by
    time with repeated timestamps dropped; poses are camera-to-world. InputError naming the line of a position
    too far off (:func:`check_positions`)."""
    rows = _number_rows(path, 8, "TUM ground truth")
    if not rows:
        raise InputError(f"{path}: no poses (lines 'timestamp tx ty tz qx qy qz qw' expected)")
    values = np.array([_floats(path, number, fields[:8]) for number, fields in rows])
    check_positions(values[:, 1:4], [f"{path}:{number}" for number, _ in rows])
    times, unique = np.unique(values[:, 0], return_index=True)
    values = values[unique]
    return times, values[:, 1:4], quaternion_rotations(values[:, 4:8], str(path))  # scipy's are (x, y, z, w) too


def _nearest(sorted_times: np.ndarray, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(index of the nearest of `sorted_times` (M,), |time difference| s) for each of `times` (N,)."""
    after = np.clip(np.searchsorted(sorted_times, times), 0, len(sorted_times) - 1)
    before = np.clip(after - 1, 0, len(sorted_times) - 1)
    use_before = np.abs(times - sorted_times[before]) < np.abs(sorted_times[after] - times)
    index = np.where(use_before, before, after)
    return index, np.abs(sorted_times[index] - times)


def _interpolated_poses(groundtruth, times: np.ndarray) -> np.ndarray:
    """(N, 4, 4) float64 camera-to-world poses at `times` (N,): translation interpolated linearly and
    rotation by slerp between the ground-truth samples around each time (clamped at the ends)."""
    gt_times, translations, rotations = groundtruth
    if len(gt_times) == 1:  # Slerp needs two key times: hold the only pose
        gt_times, translations = np.r_[gt_times, gt_times + 1.0], np.repeat(translations, 2, axis=0)
        rotations = Rotation.concatenate([rotations, rotations])
    clamped = np.clip(times, gt_times[0], gt_times[-1])
    poses = np.tile(np.eye(4), (len(times), 1, 1))
    poses[:, :3, :3] = Slerp(gt_times, rotations)(clamped).as_matrix()
    poses[:, :3, 3] = np.stack([np.interp(clamped, gt_times, translations[:, axis]) for axis in range(3)], axis=1)
    return poses


def _tum_matches(root: Path, rgb_times: np.ndarray, max_time_difference_s: float, notes: list):
    """(depth path, pose, has depth, has pose) per colour frame at `rgb_times` (N,): the nearest
    depth frame and the interpolated pose, found when within `max_time_difference_s` of the time
    (always, as None, when ``depth.txt`` / ``groundtruth.txt`` is absent: noted in `notes`; one of another kind,
    a folder, a pipe or a dangling link, is named: :func:`present`)."""
    count = len(rgb_times)
    depth, poses = [None] * count, [None] * count
    has_depth, has_pose = np.ones(count, bool), np.ones(count, bool)
    if present(root / "depth.txt"):
        depth_times, depth_files = _read_tum_list(root / "depth.txt", TUM_LISTS["depth.txt"])
        index, difference = _nearest(depth_times, rgb_times)
        depth, has_depth = [root / depth_files[i] for i in index], difference <= max_time_difference_s
    else:
        notes.append("no depth.txt: frames have no depth")
    if present(root / "groundtruth.txt"):
        groundtruth = _read_tum_groundtruth(root / "groundtruth.txt")
        poses = list(_interpolated_poses(groundtruth, rgb_times))
        has_pose = _nearest(groundtruth[0], rgb_times)[1] <= max_time_difference_s
    else:
        notes.append("no groundtruth.txt: frames have no poses")
    return depth, poses, has_depth, has_pose


def read_tum(root: str | Path, camera: Camera | None = None, max_time_difference_s: float = 0.02) -> Sequence:
    """A TUM RGB-D sequence folder (``rgb.txt``, ``depth.txt``, optional ``groundtruth.txt``).

    Each colour frame takes the nearest depth frame and the ground-truth pose interpolated at its
    timestamp (linear in translation, slerp in rotation) when the nearest depth frame and the
    nearest ground-truth sample are within `max_time_difference_s` seconds; other frames are
    skipped (counted in the notes). Depth: 5000 units per metre. `camera` defaults to TUM's
    recommended fx = fy = 525, cx = 319.5, cy = 239.5, which are a 640 x 480 frame's: frames of
    another size without `camera` are refused.
    """
    root = require_folder(root, "TUM sequence")
    rgb_times, rgb_files = _read_tum_list(root / "rgb.txt", TUM_LISTS["rgb.txt"])
    notes = []
    depth, poses, has_depth, has_pose = _tum_matches(root, rgb_times, max_time_difference_s, notes)
    kept = np.flatnonzero(has_depth & has_pose)
    if len(kept) < len(rgb_times):
        notes.append(f"skipped {int((~has_depth).sum())} frame(s) without a depth frame and "
                     f"{int((has_depth & ~has_pose).sum())} without a ground-truth pose within "
                     f"{max_time_difference_s} s ({len(kept)} of {len(rgb_times)} kept)")
    if len(kept) == 0:
        raise InputError(f"{root / 'rgb.txt'}: no colour frame has depth and a pose within {max_time_difference_s} s")
    colour = [root / rgb_files[i] for i in kept]
    size = common_image_size(colour)
    if depth[0] is not None:
        common_image_size([depth[i] for i in kept], size, "depth")
    camera = check_camera_size(camera, size, colour[0]) if camera is not None else \
        default_intrinsics(root, size, "TUM's", notes)
    frames = [SequenceFrame(index=k, name=colour[k].name, rgb_path=colour[k], camera=camera, T_world_cam=poses[i],
                            depth_path=depth[i], depth_scale=TUM_DEPTH_SCALE, timestamp=float(rgb_times[i]))
              for k, i in enumerate(kept)]
    return Sequence(frames, "tum", root, metric=True, notes=notes)


# ----------------------------------------------------------------------------- Redwood

def read_redwood_log(path: Path) -> np.ndarray:
    """(N, 4, 4) float64 matrices of a Redwood ``.log`` trajectory, in frame order: per entry a header line
    ``i i i+1`` then the 4 x 4 camera-to-world matrix row by row (metres). The header's first number is the
    frame's index (Redwood's and Open3D's ``metadata``: 0 is the first image by name), so entries may come in
    any order, each frame's pose is the entry of its index; the indices must be 0 to N - 1, each once. InputError
    naming the line if malformed, a frame index listed twice, one missing (frames after it would take other
    frames' poses), a matrix that is not a rigid transform (:func:`~frontiernet.geometry.rigid_pose`) or one whose
    translation lies too far off (:func:`check_positions`), or naming the file when it is no regular file (a pipe:
    a read waits forever)."""
    input_file(path, "Redwood trajectory")
    text = path.read_text("utf-8-sig", errors="replace")  # (a byte-order mark: _number_rows)
    lines = [(number, line.split()) for number, line in enumerate(text.splitlines(), 1) if line.strip()]
    if len(lines) % 5:
        raise InputError(f"{path}: {len(lines)} non-empty lines; a Redwood .log has 5 per frame "
                         f"(a line 'i i i+1' then 4 matrix rows)")
    rows, frames = [], {}  # frame index -> entry (position in the file)
    for position, (number, fields) in enumerate(lines):
        header = position % 5 == 0
        if len(fields) != (3 if header else 4):
            expected = "a frame header 'i i i+1'" if header else "a matrix row of 4 numbers"
            raise InputError(f"{path}:{number}: expected {expected}, got '{' '.join(fields)}'")
        values = _floats(path, number, fields)
        if not header:
            rows.append(values)
        elif not values[0] >= 0 or values[0] != int(values[0]):
            raise InputError(f"{path}:{number}: a frame header's first number is the frame's index, a whole "
                             f"number >= 0; got '{' '.join(fields)}'")
        elif int(values[0]) in frames:
            raise InputError(f"{path}:{number}: frame {int(values[0])} is listed twice (also at line "
                             f"{lines[5 * frames[int(values[0])]][0]}); each frame has one pose")
        else:
            frames[int(values[0])] = position // 5
    missing = next(index for index in range(len(frames) + 1) if index not in frames)
    if missing < len(frames):
        raise InputError(f"{path}: no pose for frame {missing}, though the log lists frame {max(frames)}: the "
                         "first number of a header line is the frame's index, from 0 (the first image by name)")
    order = [frames[index] for index in range(len(frames))]
    matrices = np.array(rows, np.float64).reshape(-1, 4, 4)
    bad = np.flatnonzero(np.abs(matrices[:, 3] - [0.0, 0.0, 0.0, 1.0]).max(axis=1, initial=0.0) > 1e-6)
    if len(bad):
        raise InputError(f"{path}:{lines[5 * bad[0] + 4][0]}: the matrix's last row must be 0 0 0 1")
    for index, entry in enumerate(order):  # a scaled or sheared matrix: named here, not by the map
        rigid_pose(matrices[entry], f"{path}:{lines[5 * entry + 1][0]}: the pose of frame {index}")
    translations = matrices[:, :3, 3]  # named at the matrix row holding the farthest coordinate
    check_positions(translations, [f"{path}:{lines[5 * entry + 1 + int(np.argmax(np.abs(translation)))][0]}"
                                   for entry, translation in enumerate(translations)])
    return matrices[order]


def _redwood_trajectory(root: Path) -> Path | None:
    """``trajectory.log`` or the only ``*.log`` in `root`; None without one. InputError naming the chosen one
    when it is no regular file (a folder, a pipe, a dangling link: :func:`~frontiernet.io.input_file`)."""
    if present(root / "trajectory.log"):
        return input_file(root / "trajectory.log", "Redwood trajectory")
    logs = sorted(root.glob("*.log"))
    if len(logs) > 1:
        raise InputError(f"{root}: several .log trajectories ({', '.join(p.name for p in logs)}); "
                         f"name the one to use trajectory.log")
    return input_file(logs[0], "Redwood trajectory") if logs else None


def read_open3d_intrinsic(path: Path) -> Camera:
    """The :class:`Camera` of an Open3D PinholeCameraIntrinsic JSON (``width``, ``height``,
    ``intrinsic_matrix``: the 3 x 3 K as 9 numbers, column-major); InputError naming the file for
    intrinsics that do not fit its size (:meth:`Camera.checked`), or when it is no regular file."""
    input_file(path, "Open3D camera intrinsic JSON")
    try:
        data = json.loads(path.read_text("utf-8-sig"))
        K = np.array(data["intrinsic_matrix"], np.float64).reshape(3, 3).T
        width, height = int(data["width"]), int(data["height"])
    except (ValueError, KeyError, TypeError) as error:
        raise InputError(f"{path}: not an Open3D camera intrinsic JSON (width, height and a 9-number "
                         f"intrinsic_matrix expected): {error}") from None
    return Camera(width, height, K).checked(str(path))


def _redwood_camera(root: Path, camera: Camera | None, size: tuple[int, int], notes: list) -> Camera:
    """The given `camera`, else the intrinsic JSON in `root`, else the PrimeSense default; checked
    against the images' `size` (width, height)."""
    json_path = next((root / name for name in REDWOOD_INTRINSIC_FILES if present(root / name)), None)
    if camera is not None:
        if json_path is not None:
            notes.append(f"camera given explicitly; {json_path.name} ignored")
        return check_camera_size(camera, size, root)
    if json_path is not None:
        return check_camera_size(read_open3d_intrinsic(json_path), size, json_path)
    return default_intrinsics(root, size, "Redwood's (PrimeSense)", notes)


def default_intrinsics(root: Path, size: tuple[int, int], whose: str, notes: list) -> Camera:
    """The :data:`DEFAULT_INTRINSICS` camera for the frames of `root` ((width, height) `size`), with a
    note naming them (`whose`: "TUM's", "Redwood's (PrimeSense)"); InputError when the frames are not
    the 640 x 480 those numbers are for (a principal point at 319.5, 239.5 would be off their centre)."""
    if tuple(size) != DEFAULT_INTRINSICS_SIZE:
        raise InputError(f"{root}: {whose} default intrinsics are for {DEFAULT_INTRINSICS_SIZE[0]} x "
                         f"{DEFAULT_INTRINSICS_SIZE[1]} frames, these are {size[0]} x {size[1]}: give --intrinsics "
                         "FX,FY,CX,CY")
    notes.append(f"camera: {whose} default intrinsics fx = fy = 525, cx = 319.5, cy = 239.5")
    return default_camera(size)


def _redwood_poses(root: Path, frame_count: int, notes: list) -> list:
    """One (4, 4) pose per frame from the trajectory (None each without one)."""
    trajectory = _redwood_trajectory(root)
    if trajectory is None:
        notes.append("no .log trajectory: frames have no poses")
        return [None] * frame_count
    poses = read_redwood_log(trajectory)
    if len(poses) < frame_count:
        raise InputError(f"{trajectory}: {len(poses)} poses for {frame_count} frames")
    if len(poses) > frame_count:
        notes.append(f"{trajectory.name} has {len(poses)} poses for {frame_count} frames: the first "
                     f"{frame_count} are used")
    return list(poses[:frame_count])


def read_redwood(root: str | Path, camera: Camera | None = None) -> Sequence:
    """A Redwood-style RGB-D folder: colour images in ``color/``, ``image/`` or ``rgb/``, optional
    16-bit millimetre depth PNGs in ``depth/``, and a ``.log`` trajectory (``trajectory.log`` or
    the only one): the i-th image by name takes the trajectory's entry of frame index i (:func:`read_redwood_log`).

    Intrinsics: `camera` when given, else ``camera_intrinsic.json`` / ``intrinsic.json`` (Open3D
    format), else the PrimeSense default fx = fy = 525, cx = 319.5, cy = 239.5. A folder without a
    ``.log`` trajectory that holds ``rgb.txt`` (a TUM sequence) is refused, naming ``--format tum``.
    """
    root = require_folder(root, "Redwood sequence")
    if present(root / "rgb.txt") and _redwood_trajectory(root) is None:
        raise InputError(f"{root}: not a Redwood folder (no color/ and .log trajectory); it looks like a TUM "
                         "sequence: --format tum")
    colour_folder = next((root / name for name in REDWOOD_COLOUR_FOLDERS if (root / name).is_dir()), None)
    if colour_folder is None:
        raise InputError(f"{root}: no colour folder (looked for {', '.join(REDWOOD_COLOUR_FOLDERS)})")
    colour = list_images(colour_folder)
    size = common_image_size(colour)
    depth = [None] * len(colour)
    if (root / "depth").is_dir():
        depth = list_images(root / "depth")
        if len(depth) != len(colour):
            raise InputError(f"{root / 'depth'}: {len(depth)} depth images for {len(colour)} colour images "
                             f"in {colour_folder}")
        common_image_size(depth, size, "depth")
    notes = []
    camera = _redwood_camera(root, camera, size, notes)
    poses = _redwood_poses(root, len(colour), notes)
    frames = [SequenceFrame(index=i, name=path.name, rgb_path=path, camera=camera, T_world_cam=poses[i],
                            depth_path=depth[i], depth_scale=REDWOOD_DEPTH_SCALE) for i, path in enumerate(colour)]
    return Sequence(frames, "redwood", root, metric=True, notes=notes)

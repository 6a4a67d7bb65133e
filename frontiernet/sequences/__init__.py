"""Real captured data: posed image sequences from disk (issue "Real captured data").

* :mod:`.frames`: the :class:`Sequence` type (frames with images, optional depth, intrinsics,
  ``T_world_cam``) every reader returns.
* :mod:`.images`: image and depth files, with the depth encodings of TUM, NYU, SUN, Redwood.
* :mod:`.readers`: TUM RGB-D (:func:`read_tum`) and Redwood (:func:`read_redwood`) folders.
* :mod:`.colmap`: COLMAP sparse models (:func:`read_colmap`).
* :mod:`.rosbag`: robot recordings, rosbag1, rosbag2 and MCAP (:func:`~.rosbag.read_rosbag`, through
  ``rosbags``); :mod:`.ros_out` writes the run's frontiers back as ROS messages.
* :mod:`.stream`: :class:`~.stream.FrontierStream`, the per-frame pipeline (``frontiernet sequence``
  loops over it; a robot's node calls it per frame).
* :func:`open_sequence`: any of them, the format detected from the folder's contents.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError
from ..io import input_file, input_folder, present
from .colmap import MODEL_PARTS, find_model, read_colmap, sequence_from_reconstruction
from .frames import Camera, Sequence, SequenceFrame
from .images import DEPTH_ENCODINGS, read_depth, read_rgb
from .readers import IMAGE_SUFFIXES, REDWOOD_COLOUR_FOLDERS, TUM_LISTS, read_redwood, read_tum
from .ros_extract import is_recording

FORMATS = ("tum", "redwood", "colmap", "images")
"""The folder formats; a recording (``.bag``, ``.mcap``, ``.db3``, a rosbag2 folder) is format ``rosbag``."""
READERS = (*FORMATS, "rosbag")
FOLDERS = {"tum": "a TUM sequence folder", "redwood": "a Redwood sequence folder", "colmap": "a COLMAP model folder",
           "images": "a folder of images"}
"""What each folder format's reader takes, as a refusal of a file given for it says (:func:`file_given`)."""

__all__ = ["DEPTH_ENCODINGS", "FORMATS", "READERS", "Camera", "Sequence", "SequenceFrame", "detect_format",
           "is_recording", "open_sequence", "read_colmap", "read_depth", "read_redwood", "read_rgb", "read_tum",
           "sequence_from_reconstruction"]


def _only_images(folder: Path) -> bool:
    """Whether `folder` holds images and nothing else (hidden files aside; an entry named like an image
    that is a folder counts, for the reader to name it)."""
    entries = [entry for entry in folder.iterdir() if not entry.name.startswith(".")]
    return bool(entries) and all(entry.suffix.lower() in IMAGE_SUFFIXES for entry in entries)


def file_given(path: Path, format: str = "auto") -> str | None:
    """The refusal of file `path` given to the reader of `format` where that file is known for a part of another
    input (None otherwise): a recording (``.bag``, ``.mcap``, ``.db3``) for a folder format; a file of a rosbag2
    recording (its ``metadata.yaml``), or of a COLMAP model (``cameras.bin``, ...), named with the folder to give
    (was "a file; a sequence is a folder" or "is a file, expected a folder")."""
    expected = f", not {FOLDERS[format]}" if format in FOLDERS else ""
    if format not in ("auto", "rosbag") and is_recording(path):
        return f"{path}: a recording ({path.suffix} file){expected}; read it with --format rosbag (or auto)"
    if present(path.parent / "metadata.yaml"):
        return (f"{path}: a file of the rosbag2 recording {path.parent}{expected}; a rosbag2 recording is the folder "
                f"holding metadata.yaml and its .db3 or .mcap files: give {path.parent}")
    if path.suffix in (".bin", ".txt") and path.stem in MODEL_PARTS:
        folder = f": give {path.parent} (or its project folder)" if find_model(path.parent) == path.parent else ""
        return (f"{path}: a file of a COLMAP model{expected}; a COLMAP model is the folder holding cameras, images "
                f"and points3D (.bin or .txt){folder}")
    return None


def detect_format(path: str | Path) -> str:
    """The format of the sequence at `path` (one of :data:`READERS`); InputError if none fits.

    A ``.bag``, ``.mcap`` or ``.db3`` file or a folder with ``metadata.yaml``: rosbag; ``rgb.txt``:
    tum; a ``*.log`` trajectory and a colour folder: redwood; ``cameras.bin`` or
    ``cameras.txt`` (directly, in ``sparse/0`` or ``sparse``): colmap; only image files: images.
    """
    path = Path(path)
    if is_recording(path):
        return "rosbag"
    if path.is_file():
        raise InputError(file_given(path) or f"{path}: a file; a sequence is a folder, or a recording (.bag, .mcap, "
                         ".db3)")
    input_folder(path, "sequence")  # missing, or a device or a pipe
    if present(path / "rgb.txt"):  # a pipe or a dangling link too: named, not taken for absent
        input_file(path / "rgb.txt", TUM_LISTS["rgb.txt"])
        return "tum"
    if any(path.glob("*.log")) and any((path / name).is_dir() for name in REDWOOD_COLOUR_FOLDERS):
        return "redwood"
    if find_model(path) is not None:
        return "colmap"
    if _only_images(path):
        return "images"
    raise InputError(f"{path}: unknown sequence format; looked for rgb.txt (tum), a *.log trajectory with a "
                     f"{'/, '.join(REDWOOD_COLOUR_FOLDERS)}/ folder (redwood), cameras.bin or cameras.txt in ., "
                     f"sparse/0 or sparse (colmap), a folder of only images (images), metadata.yaml (a rosbag2 "
                     f"recording)")


def open_sequence(path: str | Path, format: str = "auto", camera: Camera | None = None, **options) -> Sequence:
    """The sequence at `path` read by the reader of `format` (``auto``: :func:`detect_format`).

    `camera` overrides the intrinsics (not for colmap, whose model has its own); `options` go to
    the reader (e.g. ``max_time_difference_s`` for tum, ``image_dir`` / ``depth_dir`` for colmap,
    ``conf``, ``topics``, ``work_dir`` for rosbag: :func:`~.rosbag.read_rosbag`).
    """
    if format != "auto" and format not in READERS:
        raise InputError(f"sequence format '{format}' is unknown; valid: auto, {', '.join(READERS)}")
    if format == "auto":
        format = detect_format(path)
    elif Path(path).is_file() and not (format == "rosbag" and is_recording(path)):
        refusal = file_given(Path(path), format)  # a recording, or a file of one or of a COLMAP model
        if refusal:
            raise InputError(refusal)
    if format == "tum":
        return read_tum(path, camera, **options)
    if format == "redwood":
        return read_redwood(path, camera, **options)
    if format == "colmap":
        if camera is not None:
            raise InputError(f"{path}: a COLMAP model has its own cameras; a camera cannot be given for it")
        return read_colmap(path, **options)
    if format == "rosbag":
        from .rosbag import read_rosbag  # imported here: rosbags is only needed for recordings

        return read_rosbag(path, camera, **options)
    # imported here: the image-folder reader (structure from motion) is heavier and optional
    from .sfm import read_image_folder

    return read_image_folder(path, camera, **options)

"""Opening a robot recording and streaming it once (issue 57; :mod:`.rosbag` reads it).

* :func:`open_recording`: a ``rosbags`` AnyReader (rosbag1, rosbag2 folders, plain ``.mcap`` and
  ``.db3`` files); :func:`messages`: its messages in time order, deserialised one at a time.
* :func:`extract`: one pass over the chosen topics: colour and depth images go to files in a
  work folder as they arrive (so a recording larger than memory is fine), the first CameraInfo,
  the tf tree and the pose topics' samples are kept (small).

Bad data (a truncated or corrupt file, a message that is not what its topic's role needs) is an
:class:`~frontiernet.errors.InputError` naming the file or the topic.
"""

from __future__ import annotations

import os
import re
import shutil
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import input_file, present
from .readers import image_size
from .ros_messages import COMPRESSED, colour_image, compressed_suffix, depth_image, frame_id, pose_of, stamp_ns
from .ros_tf import Track, TransformBuffer

RECORDING_SUFFIXES = (".bag", ".mcap", ".db3")


def is_recording(path: str | Path) -> bool:
    """Whether `path` is a recording: a ``.bag``, ``.mcap`` or ``.db3`` file, or a rosbag2 folder
    (``metadata.yaml``). What has the name counts whatever it is (a pipe, a folder, a link to nothing:
    :func:`~frontiernet.io.present`), for :func:`check_recording` to name it: taken for absent, a pipe named ``x.bag`` was
    "expected a folder (sequence)", a ``metadata.yaml`` of the wrong kind "unknown sequence format"."""
    path = Path(path)
    if path.is_dir():
        return present(path / "metadata.yaml")
    return path.suffix.lower() in RECORDING_SUFFIXES and present(path)


def _listed_files(folder: Path) -> list[Path]:
    """The storage files that rosbag2 folder `folder`'s ``metadata.yaml`` lists, where rosbags looks for them (in the
    folder, by name); where the metadata does not parse here, every ``.db3`` and ``.mcap`` the folder holds."""
    import yaml

    try:
        names = yaml.safe_load((folder / "metadata.yaml").read_text())["rosbag2_bagfile_information"][
            "relative_file_paths"]
        return [folder / Path(str(name)).name for name in names] if isinstance(names, list) else _held(folder)
    except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError):  # (rosbags refuses it before it
        # opens a file, or reads it where this parser did not)
        return _held(folder)


def _held(folder: Path) -> list[Path]:
    return sorted(entry for entry in folder.iterdir() if entry.suffix.lower() in (".db3", ".mcap"))


def check_recording(path: Path) -> Path:
    """`path` if the recording there is made of regular files; InputError naming the first that is not, before any is
    opened (:func:`~frontiernet.io.input_file`: a folder, a pipe, which sqlite and the MCAP reader wait on for ever,
    SIGTERM unanswered, or a link to nothing, which is not "missing"): a recording file, or a rosbag2 folder's
    ``metadata.yaml`` and its storage files (:func:`_listed_files`)."""
    if not path.is_dir():
        return input_file(path, "recording")
    input_file(path / "metadata.yaml", "rosbag2 metadata")
    for file in _listed_files(path):
        input_file(file, "rosbag2 storage file")
    return path


RECORDING_MAGIC = {".bag": b"#ROSBAG V2.0", ".mcap": b"\x89MCAP0\r\n", ".db3": b"SQLite format 3\x00"}
"""The first bytes of each kind of recording file, by the suffix it goes by."""


def _reason(error: Exception) -> str:
    """`error`'s first line, less a library's advice to report its bug (rosbags' "please report issue."): the
    file is what is wrong."""
    text = re.sub(r"[;,.]?\s*please report[^.;)]*\.?", "", (str(error).splitlines() or [""])[0], flags=re.I)
    return f"{type(error).__name__}: {text.strip()[:160]}"


def _check_suffix(path: Path) -> None:
    """InputError naming a recording file whose bytes are another kind's than its suffix says (an MCAP named
    .bag was "truncated or corrupt (UnicodeDecodeError ...)")."""
    if not path.is_file() or path.suffix.lower() not in RECORDING_MAGIC:
        return
    with open(path, "rb") as handle:
        head = handle.read(16)
    kind = next((suffix for suffix, magic in RECORDING_MAGIC.items() if head.startswith(magic)), None)
    if kind is not None and kind != path.suffix.lower():
        raise InputError(f"{path}: a {kind} recording named {path.suffix}; rename it {path.with_suffix(kind).name}")


@contextmanager
def open_recording(path: Path):
    """An open ``rosbags`` AnyReader of the recording at `path`; InputError naming the file when
    it is missing, of an unknown kind, no regular file (:func:`check_recording`), truncated or corrupt."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    if not os.path.exists(path):
        input_file(path, "recording")  # "recording not found", or a link to nothing named so
    if not is_recording(path):
        raise InputError(f"{path}: not a recording (a .bag, .mcap or .db3 file, or a rosbag2 folder with "
                         "metadata.yaml)")
    check_recording(path)  # (a pipe for a file: the reader waited for ever)
    _check_suffix(path)
    try:  # rosbag2 files without message definitions are read with ROS 2 Humble's
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except Exception as error:  # rosbags' reader errors, sqlite's, a file it cannot parse at all
        raise InputError(f"{path}: not a readable recording, truncated or corrupt ({_reason(error)})") from None
    try:
        yield reader
    finally:
        reader.close()


def messages(reader, path: Path, connections):
    """(topic, msgtype, log time ns, message) of `connections` in time order, streamed;
    InputError naming the file when the data cannot be read (a truncated or corrupt recording)."""
    iterator = reader.messages(connections=connections)
    while True:
        try:
            connection, log_ns, raw = next(iterator)
            message = reader.deserialize(raw, connection.msgtype)
        except StopIteration:
            return
        except Exception as error:  # damaged data surfaces as many types (rosbags, struct, zstd, lz4, sqlite)
            raise InputError(f"{path}: the recording is truncated or corrupt ({_reason(error)})") from None
        yield connection.topic, connection.msgtype, log_ns, message


@dataclass
class Extracted:
    """What one pass over a recording kept.

    Attributes:
        work: the work folder (``rgb/``, ``depth/``).
        rgb, depth: (stamp ns, file) per image message, sorted by stamp (``header.stamp``, the
            log time where a driver leaves it zero).
        size: (width, height) px of the colour images; camera_frame: their ``header.frame_id``.
        info: the first ``sensor_msgs/CameraInfo`` of the info topic, or None.
        tf: the :class:`~.ros_tf.TransformBuffer`; pose_tracks: topic -> :class:`~.ros_tf.Track`.
    """

    work: Path
    rgb: list = field(default_factory=list)
    depth: list = field(default_factory=list)
    size: tuple | None = None
    depth_size: tuple | None = None
    camera_frame: str = "camera"
    info: object = None
    tf: TransformBuffer = field(default_factory=TransformBuffer)
    pose_tracks: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    seen: set = field(default_factory=set)  # colour stamps


def _stamp_name(stamp: int) -> str:
    return f"{stamp // 1_000_000_000}.{stamp % 1_000_000_000:09d}"


def _colour(data: Extracted, path: Path, topic: str, msgtype: str, stamp: int, message) -> None:
    import cv2

    if stamp in data.seen:
        data.notes.append(f"{topic}: two images stamped {stamp / 1e9:.9f} s; the second is dropped")
        return
    if msgtype == COMPRESSED:
        file = data.work / "rgb" / (_stamp_name(stamp) + compressed_suffix(message, topic))
        file.write_bytes(np.asarray(message.data, np.uint8).tobytes())
        size = image_size(file)
    else:
        rgb = colour_image(message, topic)
        file = data.work / "rgb" / f"{_stamp_name(stamp)}.png"
        cv2.imwrite(str(file), rgb[..., ::-1], [cv2.IMWRITE_PNG_COMPRESSION, 1])
        size = (rgb.shape[1], rgb.shape[0])
    if data.size is None:
        data.size, data.camera_frame = size, frame_id(message.header) or "camera"
    elif size != data.size:
        raise InputError(f"{path}: topic {topic}: the image at {stamp / 1e9:.3f} s is {size[0]} x {size[1]} px but the "
                         f"first is {data.size[0]} x {data.size[1]} (images of mixed sizes)")
    data.rgb.append((stamp, file))
    data.seen.add(stamp)


def _depth(data: Extracted, path: Path, topic: str, msgtype: str, stamp: int, message) -> None:
    import cv2

    depth = depth_image(message, msgtype, topic)
    size = (depth.shape[1], depth.shape[0])
    if data.depth_size is None:
        data.depth_size = size
    elif size != data.depth_size:
        raise InputError(f"{path}: topic {topic}: the depth image at {stamp / 1e9:.3f} s is {size[0]} x {size[1]} px "
                         f"but the first is {data.depth_size[0]} x {data.depth_size[1]}")
    if depth.dtype == np.uint16:  # millimetres, as Redwood's PNGs
        file = data.work / "depth" / f"{_stamp_name(stamp)}.png"
        cv2.imwrite(str(file), depth, [cv2.IMWRITE_PNG_COMPRESSION, 1])
    else:  # float32 metres
        file = data.work / "depth" / f"{_stamp_name(stamp)}.npy"
        np.save(file, depth.astype(np.float32))
    data.depth.append((stamp, file))


def _pose(data: Extracted, topic: str, msgtype: str, stamp: int, message) -> None:
    T, body = pose_of(message, msgtype, topic)
    track = data.pose_tracks.setdefault(topic, Track(frame_id(message.header), body, topic))
    track.add(stamp, T)


def _keep(data: Extracted, path: Path, chosen: dict, topic: str, msgtype: str, log_ns: int, message) -> None:
    """One message of the pass, by its topic's role."""
    stamp = (stamp_ns(message.header) or log_ns) if hasattr(message, "header") else log_ns
    if topic == chosen["rgb"]:
        _colour(data, path, topic, msgtype, stamp, message)
    elif topic == chosen["depth"]:
        _depth(data, path, topic, msgtype, stamp, message)
    elif topic == chosen["info"]:
        data.info = message if data.info is None else data.info
    elif topic in chosen["tf"]:
        data.tf.add(message, topic.rstrip("/").endswith("tf_static"), log_ns, topic)
    else:
        _pose(data, topic, msgtype, stamp, message)


def extract(reader, path: Path, chosen: dict, work: Path, progress: bool = True) -> Extracted:
    """One pass over the topics of `chosen` (:func:`~.rosbag.select_topics`): images written to
    ``work/rgb`` and ``work/depth`` (both emptied first), the rest kept; InputError for a colour
    topic without messages or depth images of another size than the colour images."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    for name in ("rgb", "depth"):
        shutil.rmtree(work / name, ignore_errors=True)
        (work / name).mkdir(parents=True)
    data, topics = Extracted(work), reader.topics
    wanted = [topic for topic in (chosen["rgb"], chosen["depth"], chosen["info"], *chosen["tf"],
                                  *chosen["pose_candidates"]) if topic]
    connections = [connection for topic in dict.fromkeys(wanted) for connection in topics[topic].connections]
    with Progress(TextColumn("reading {task.description}"), BarColumn(), MofNCompleteColumn(), transient=True,
                  disable=not progress) as bar:
        task = bar.add_task(path.name, total=sum(connection.msgcount for connection in connections))
        for topic, msgtype, log_ns, message in messages(reader, path, connections):
            try:
                _keep(data, path, chosen, topic, msgtype, log_ns, message)
            except InputError as error:  # a decoder's "topic ...: ..." gets the file's name
                raise InputError(str(error) if str(error).startswith(str(path)) else f"{path}: {error}") from None
            bar.advance(task)
    if not data.rgb:
        raise InputError(f"{path}: the colour topic {chosen['rgb']} has no messages")
    if data.depth_size is not None and data.depth_size != data.size:
        raise InputError(f"{path}: topic {chosen['depth']}: depth images are {data.depth_size[0]} x "
                         f"{data.depth_size[1]} px but the colour images of {chosen['rgb']} are {data.size[0]} x "
                         f"{data.size[1]}; the depth must be registered to the colour camera (e.g. a RealSense's "
                         "aligned_depth_to_color topic)")
    if data.tf.reparented:
        data.notes.append(f"tf: {data.tf.reparented} transform(s) gave a frame a second parent and were ignored")
    data.rgb.sort(key=lambda item: item[0])
    data.depth.sort(key=lambda item: item[0])
    return data

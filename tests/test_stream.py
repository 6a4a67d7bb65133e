"""FrontierStream, the per-frame API a robot's node wraps (issue 57): frame by frame it gives what
`frontiernet sequence` gives on the same frames (frontiers, per-frame records, ROS messages), and
it runs without knowing the poses to come (its map is a box around the first camera).

Frames are rendered in the two-room scene (tests/conftest.py) with depth in whole millimetres:
`sequence` reads them as a Redwood folder, the stream gets them as a node does (uint16 16UC1
depth, the poses in a Z-up world). No test here pretends to be ROS: the messages are checked with
the `mcap` reader's bytes and `rosbags`' decoder.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from frontiernet.cli.main import main
from frontiernet.errors import InputError
from frontiernet.sequences import open_sequence
from frontiernet.sequences.gravity import gravity_alignment
from frontiernet.sequences.ros_out import OutputFrames, typestore
from frontiernet.sequences.stream import FrontierStream, TrackedFrontier, load_sequence_config, metric_depth
from test_rosbag import write_redwood
from test_rosbag_outputs import rendered_frames

FRAMES = 5


@pytest.fixture(scope="module")
def runtime():
    from frontiernet.model import open_runtime

    return open_runtime(None)


@pytest.fixture(scope="module")
def run(two_room_scene, tmp_path_factory):
    """`frontiernet sequence` on the frames as a folder: (frames, K, the folder, its --out)."""
    tmp = tmp_path_factory.mktemp("stream")
    frames, K = rendered_frames(two_room_scene, FRAMES)
    folder = write_redwood(tmp / "folder", frames, K)
    assert main(["sequence", "--input", str(folder), "--out", str(tmp / "out"), "--no-video"]) == 0
    return frames, K, folder, tmp / "out"


def _mcap_messages(path) -> dict:
    """topic -> [(log time, CDR bytes)] of an MCAP file (the `mcap` reader)."""
    from mcap.reader import make_reader

    topics = {}
    with open(path, "rb") as stream:
        for _, channel, message in make_reader(stream).iter_messages():
            topics.setdefault(channel.topic, []).append((message.log_time, bytes(message.data)))
    return topics


@pytest.mark.slow
def test_the_stream_gives_the_frontiers_and_messages_of_frontiernet_sequence(run, runtime):
    frames, K, folder, out = run
    summary = json.loads((out / "summary.json").read_text())
    record = json.loads((out / "frontiers.json").read_text())
    sequence = open_sequence(folder)
    poses = gravity_alignment(sequence.poses(), "cameras") @ sequence.poses()  # the run's world, as main() has it
    # the run's map box and gain-view height (it knows all poses in advance); the messages' frames and
    # stamps of a folder input: map -> camera with a tf, frame / 5 Hz
    stream = FrontierStream(K, runtime=runtime, bounds=summary["map_bounds_m"], view_z=summary["view_z_m"])
    stream.ros_frames = OutputFrames("map", "camera", np.eye(4), None, True)
    messages = {}
    for index, (frame, T) in enumerate(zip(frames, poses)):
        frontiers = stream(frame["rgb"], T, frame["depth"], name=sequence.frames[index].name)  # uint16 mm depth
        for message in stream.ros_messages(map=True if index == FRAMES - 1 else None):
            messages.setdefault(message.topic, []).append((message.stamp_ns, message.data))
    assert frontiers and all(isinstance(frontier, TrackedFrontier) for frontier in frontiers)
    assert stream.per_frame == record["per_frame"]
    names = [frame.name for frame in sequence]
    assert len(frontiers) == len(record["frontiers"])
    for ours, theirs in zip(frontiers, record["frontiers"]):  # frontiers.json rounds to 4 decimals
        assert ours.id == theirs["id"] and ours.observations == theirs["observations"]
        assert np.allclose(ours.position, theirs["position"], atol=1e-4)
        assert np.allclose(ours.direction, theirs["direction"], atol=1e-4)
        assert abs(ours.gain_m3 - theirs["gain_m3"]) < 1e-4
        assert (names[ours.first_seen], names[ours.last_seen]) == (theirs["first_frame"], theirs["last_frame"])
    assert [entry["id"] for entry in stream.tracker.removed_log] == [entry["id"] for entry in record["removed"]]
    # the same messages, byte for byte, as frontiers.mcap holds
    assert messages == _mcap_messages(out / "frontiers.mcap")


@pytest.mark.slow
def test_a_live_stream_maps_a_box_around_its_first_camera_and_publishes_its_frontiers(run, runtime):
    frames, K, _, _ = run
    stream = FrontierStream(runtime=runtime, fixed_frame="odom", camera_frame="camera_color_optical_frame")
    assert stream.frontiers == []
    with pytest.raises(InputError, match="no intrinsics"):
        stream(frames[0]["rgb"], frames[0]["T"], frames[0]["depth"])
    stamps = [1_700_000_000_000_000_000 + i * 100_000_000 for i in range(3)]
    for frame, stamp in zip(frames[:3], stamps):
        frontiers = stream(frame["rgb"], frame["T"], frame["depth"], K=K, stamp_ns=stamp)  # the scene's own world
    first = frames[0]["T"][:3, 3]
    extent = np.asarray(load_sequence_config().stream.map_extent_m)
    assert np.allclose(stream.bounds, first + extent) and stream.view_z == pytest.approx(first[2])
    assert frontiers and len(stream.per_frame) == 3
    for frontier in frontiers:
        assert stamps[0] <= frontier.first_stamp_ns <= frontier.last_stamp_ns <= stamps[-1]
        assert -0.3 < frontier.position[0] < 6.3 and -0.3 < frontier.position[1] < 4.3  # in the rooms
        assert abs(np.linalg.norm(frontier.direction) - 1.0) < 1e-6
    overlay = stream.overlay()
    assert overlay.dtype == np.uint8 and overlay.shape[2] == 3
    # ROS messages, ready to publish: in the node's frames, stamped with the frame's stamp, no tf of ours
    messages = {message.topic: message for message in stream.ros_messages(map=True)}
    assert sorted(messages) == ["/frontiernet/frontier_poses", "/frontiernet/frontiers", "/frontiernet/map",
                                "/frontiernet/overlay", "/frontiernet/overlay/camera_info"]
    store = typestore()
    for topic, message in messages.items():
        decoded = store.deserialize_cdr(message.data, message.msgtype)
        assert message.stamp_ns == stamps[-1]
        header = decoded.header if hasattr(decoded, "header") else decoded.markers[0].header
        assert header.frame_id == ("camera_color_optical_frame" if "overlay" in topic else "odom")
    markers = store.deserialize_cdr(messages["/frontiernet/frontiers"].data, "visualization_msgs/msg/MarkerArray")
    arrows = {marker.id: marker for marker in markers.markers if marker.ns == "frontiers"}
    assert sorted(arrows) == sorted(frontier.id for frontier in frontiers)
    for frontier in frontiers:
        position = arrows[frontier.id].pose.position
        assert np.allclose([position.x, position.y, position.z], frontier.position)
    cloud = messages["/frontiernet/map"].message
    assert cloud.width > 100 and cloud.header.frame_id == "odom"


def test_depth_images_and_bad_frames(runtime):
    millimetres = np.array([[0, 1500], [65535, 250]], np.uint16)
    assert np.allclose(metric_depth(millimetres), [[np.nan, 1.5], [65.535, 0.25]], equal_nan=True)
    metres = np.array([[-1.0, 2.0], [np.nan, 0.0]])
    assert np.allclose(metric_depth(metres), [[np.nan, 2.0], [np.nan, np.nan]], equal_nan=True)
    assert metric_depth(None) is None
    K = np.array([[50.0, 0, 31.5], [0, 50.0, 23.5], [0, 0, 1]])
    stream = FrontierStream(K, runtime=runtime)
    rgb, depth, T = np.zeros((48, 64, 3), np.uint8), np.full((48, 64), 2.0, np.float32), np.eye(4)
    cases = [
        ((rgb, T, np.ones((10, 10), np.float32)), "depth is 10 x 10 px but the image is 64 x 48"),
        ((rgb, T), "no depth image"),
        ((rgb[..., 0], T, depth), "must be (H, W, 3) uint8 RGB"),
        ((rgb, np.eye(3), depth), "T_world_cam must be a finite (4, 4) array"),
        ((rgb, T, depth[None]), "a depth image must be (H, W)"),
    ]
    for args, message in cases:
        with pytest.raises(InputError, match=message.replace("(", r"\(").replace(")", r"\)")):
            stream(*args)
    with pytest.raises(InputError, match="no frame yet"):
        stream.overlay()

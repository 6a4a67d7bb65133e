"""Frontiers out to the robot's tools (issue 57): what `frontiernet sequence` writes from a recording (frontiers.json,
frontiers.mcap, a rosbag2 folder) matches what it writes from the same frames as a folder, in the recording's own
frames and stamps, and `explore --mcap` writes the same messages from the simulator (the recordings in:
tests/test_rosbag.py, whose writers build them)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from frontiernet.cli.main import main

pytest.importorskip("rosbags")
from test_rosbag import CAMERA, FRONTIER_TOPICS, PERIOD, T0, livingroom_frames, recording, write_redwood  # noqa: E402


def rendered_frames(scene, count: int = 3):
    """(frames, K): `count` 160 x 120 frames turning in the left room of the two-room scene (as
    tests/test_sequence.py renders them), depth in whole millimetres."""
    from frontiernet.geometry import pose_from_heading
    from frontiernet.simulator.camera import PinholeCamera, Renderer

    camera = PinholeCamera(160, 120, 100.0, 100.0, 79.5, 59.5, 3.5)
    renderer = Renderer(scene, camera, (0, 0, 0))
    frames = []
    for i in range(count):
        T = pose_from_heading(1.2 + 0.1 * i, 1.9, 1.2, np.radians(-20 + 10 * i))
        frame = renderer.render(T)
        depth = np.where(np.isfinite(frame.depth), np.round(frame.depth * 1000), 0).astype(np.uint16)
        frames.append({"rgb": frame.rgb, "depth": depth, "T": T, "jpeg": None})
    return frames, camera.K


@pytest.fixture(scope="module")
def runs(tmp_path_factory, two_room_scene):
    """The same 3 frames run through `sequence` as a plain MCAP recording (with --rosbag2) and as a
    Redwood folder: livingroom1's when the shared data is there, else frames rendered in the
    two-room scene."""
    import os

    from conftest import REPO_ROOT

    tmp = tmp_path_factory.mktemp("runs")
    shared = Path(os.environ.get("FRONTIERNET_SHARED_DATA", REPO_ROOT.parent / "shared" / "data"))
    if (shared / "images" / "livingroom1").is_dir():
        (frames, K), colour = livingroom_frames(shared, 3), "compressed"
    else:
        (frames, K), colour = rendered_frames(two_room_scene), "rgb8"
    folder = write_redwood(tmp / "folder", frames, K)
    bag = recording(frames, K, colour=colour).write(tmp / "rec", "plain_mcap")
    assert main(["sequence", "--input", str(bag), "--out", str(tmp / "bag"), "--no-video", "--rosbag2"]) == 0
    assert main(["sequence", "--input", str(folder), "--out", str(tmp / "folder_out"), "--no-video"]) == 0
    return tmp / "bag", tmp / "folder_out", len(frames)


def _frontiers(out: Path) -> dict:
    return json.loads((out / "frontiers.json").read_text())


def _decoded(path: Path) -> dict:
    """topic -> [(log time, schema name, decoded message)] of an MCAP file, read with the mcap
    reader and the ROS 2 decoder (independent of rosbags)."""
    mcap_ros2 = pytest.importorskip("mcap_ros2.decoder")
    from mcap.reader import make_reader

    topics = {}
    with open(path, "rb") as stream:
        for schema, channel, message, decoded in make_reader(
                stream, decoder_factories=[mcap_ros2.DecoderFactory()]).iter_decoded_messages():
            topics.setdefault(channel.topic, []).append((message.log_time, schema.name, decoded))
    return topics


@pytest.mark.slow
def test_a_recording_gives_the_frontiers_of_the_folder(runs):
    """Within 1e-4 m and 1e-4 m^3: the recording's poses differ from the folder's by ~5e-9 (quaternions
    of livingroom1's 8-decimal rotations); images, depth and intrinsics are the same."""
    bag, folder, _ = runs
    ours, theirs = _frontiers(bag), _frontiers(folder)
    assert ours["frontiers"] + ours["removed"]  # a case with frontiers
    assert len(ours["frontiers"]) == len(theirs["frontiers"]) and len(ours["removed"]) == len(theirs["removed"])
    for a, b in zip(ours["frontiers"] + ours["removed"], theirs["frontiers"] + theirs["removed"]):
        assert a["id"] == b["id"]
        assert np.allclose(a["position"], b["position"], atol=1e-4)
        assert np.allclose(a["direction"], b["direction"], atol=1e-4)
        assert abs(a["gain_m3"] - b["gain_m3"]) < 1e-4


@pytest.mark.slow
def test_the_mcap_holds_markers_poses_overlay_and_map_in_the_recordings_frames(runs):
    bag, _, count = runs
    topics = _decoded(bag / "frontiers.mcap")
    assert {topic: messages[0][1] for topic, messages in topics.items()} == FRONTIER_TOPICS
    stamps = [T0 + i * PERIOD for i in range(count)]
    for topic in ("/frontiernet/frontiers", "/frontiernet/frontier_poses", "/frontiernet/overlay"):
        assert [time for time, _, _ in topics[topic]] == stamps
    overlay = topics["/frontiernet/overlay"][-1][2]
    assert overlay.header.frame_id == CAMERA and overlay.encoding == "rgb8"
    assert len(overlay.data) == overlay.height * overlay.step
    cloud = topics["/frontiernet/map"][-1][2]
    assert cloud.header.frame_id == "world" and cloud.width > 100
    assert [field.name for field in cloud.fields] == ["x", "y", "z", "rgb"]
    # the last frame's arrows are the frontiers alive at the end, by id, in the recording's fixed frame
    result = _frontiers(bag)
    T_input_world = np.linalg.inv(np.asarray(result["T_world_input"]))
    markers = topics["/frontiernet/frontiers"][-1][2].markers
    arrows = {m.id: m for m in markers if m.ns == "frontiers" and m.action == 0}
    assert sorted(arrows) == sorted(f["id"] for f in result["frontiers"])
    poses = topics["/frontiernet/frontier_poses"][-1][2]
    assert poses.header.frame_id == "world" and len(poses.poses) == len(result["frontiers"])
    for frontier in result["frontiers"]:
        expected = T_input_world[:3, :3] @ frontier["position"] + T_input_world[:3, 3]
        p = arrows[frontier["id"]].pose.position
        assert np.allclose([p.x, p.y, p.z], expected, atol=1e-4)
    # ids persist: a frontier keeps its tracker id as its marker id until it is dropped, then its markers
    # are deleted (one proposed and dropped within a frame is never shown)
    seen = {m.id for _, _, array in topics["/frontiernet/frontiers"] for m in array.markers if m.action == 0}
    deleted = {m.id for _, _, array in topics["/frontiernet/frontiers"] for m in array.markers if m.action == 2}
    assert deleted == seen & {f["id"] for f in result["removed"]}
    assert seen - deleted == {f["id"] for f in result["frontiers"]}


@pytest.mark.slow
def test_the_rosbag2_folder_holds_the_same_messages(runs):
    from rosbags.highlevel import AnyReader

    bag, _, count = runs
    with AnyReader([bag / "rosbag2"]) as reader:
        counts = {topic: info.msgcount for topic, info in reader.topics.items()}
    assert counts == {topic: len(messages) for topic, messages in _decoded(bag / "frontiers.mcap").items()}
    assert counts["/frontiernet/frontiers"] == count


@pytest.mark.slow
def test_other_inputs_get_map_and_camera_frames_and_a_tf(runs):
    _, folder, count = runs
    topics = _decoded(folder / "frontiers.mcap")
    assert topics["/frontiernet/frontier_poses"][0][2].header.frame_id == "map"
    assert topics["/frontiernet/overlay"][0][2].header.frame_id == "camera"
    transforms = [message.transforms[0] for _, _, message in topics["/tf"]]
    assert [(t.header.frame_id, t.child_frame_id) for t in transforms] == [("map", "camera")] * count
    assert [time for time, _, _ in topics["/tf"]] == [round(i / 5.0 * 1e9) for i in range(count)]  # video_fps 5
    poses = np.asarray(json.loads((folder / "poses.json").read_text())["T_world_cam"])
    last = transforms[-1].transform.translation
    assert np.allclose([last.x, last.y, last.z], poses[-1][:3, 3], atol=1e-5)


@pytest.mark.slow
def test_explore_writes_the_same_messages_from_the_simulator(plan_spec, tmp_path):
    out = tmp_path / "explore"
    assert main(["explore", "--scene", plan_spec, "--max-steps", "20", "--no-video", "--mcap", "--out", str(out)]) == 0
    topics = _decoded(out / "exploration.mcap")
    assert {topic: messages[0][1] for topic, messages in topics.items()} == {
        **FRONTIER_TOPICS, "/tf": "tf2_msgs/msg/TFMessage"}
    trajectory = json.loads((out / "trajectory.json").read_text())
    iterations = [step["iteration"] for step in trajectory["steps"]]
    fps = 10.0  # configs/explore.yaml run.video_fps: one message per iteration on the video's clock
    for topic in ("/frontiernet/frontiers", "/frontiernet/frontier_poses", "/frontiernet/overlay", "/tf"):
        assert [time for time, _, _ in topics[topic]] == [round(i / fps * 1e9) for i in iterations]
    # the robot's pose as map -> camera, the last one where the run ended
    transform = topics["/tf"][-1][2].transforms[0]
    assert (transform.header.frame_id, transform.child_frame_id) == ("map", "camera")
    end = np.asarray(trajectory["T_world_cam"][-1])
    t, q = transform.transform.translation, transform.transform.rotation
    assert np.allclose([t.x, t.y, t.z], end[:3, 3], atol=1e-6)
    assert np.allclose(Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix(), end[:3, :3], atol=1e-6)
    # the last markers are the frontiers alive at the end, with the tracker's ids, and the map its occupied voxels
    alive = {frontier["id"] for frontier in json.loads((out / "frontiers.json").read_text())["frontiers"]}
    markers = topics["/frontiernet/frontiers"][-1][2].markers
    assert {m.id for m in markers if m.ns == "frontiers" and m.action == 0} == alive
    maps = topics["/frontiernet/map"]
    assert maps[-1][0] == topics["/tf"][-1][0] and maps[-1][2].header.frame_id == "map" and maps[-1][2].width > 100

"""`frontiernet sequence` and `frontiernet predict --intrinsics`: 3D frontiers on captured data.

A sequence rendered in the two-room scene and written in Redwood's layout runs on every clone;
the shared livingroom1 sequence and the TUM frame run when ../shared/data is there.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import open3d as o3d
import pytest

from frontiernet.cli.main import main
from frontiernet.geometry import pose_from_heading
from frontiernet.mapping import OCCUPIED, OccupancyMap
from frontiernet.sequences import open_sequence
from frontiernet.sequences import perceive as perceive_module
from frontiernet.sequences.gravity import gravity_alignment
from frontiernet.sequences.main import select_frames
from frontiernet.simulator.camera import PinholeCamera, Renderer


def write_redwood(folder, frames, K, with_depth: bool = True) -> None:
    """Frames (rgb, depth metres, T_world_cam) as a Redwood folder: color/, depth/ (mm), trajectory.log,
    camera_intrinsic.json."""
    (folder / "color").mkdir(parents=True)
    if with_depth:
        (folder / "depth").mkdir()
    lines = []
    for index, (rgb, depth, T) in enumerate(frames):
        cv2.imwrite(str(folder / "color" / f"{index:05d}.png"), rgb[..., ::-1])
        if with_depth:
            millimetres = np.where(np.isfinite(depth), np.round(depth * 1000), 0).astype(np.uint16)
            cv2.imwrite(str(folder / "depth" / f"{index:05d}.png"), millimetres)
        lines.append(f"{index} {index} {index + 1}")
        lines += [" ".join(f"{value:.8f}" for value in row) for row in T]
    (folder / "trajectory.log").write_text("\n".join(lines) + "\n")
    height, width = frames[0][0].shape[:2]
    (folder / "camera_intrinsic.json").write_text(json.dumps(
        {"width": width, "height": height, "intrinsic_matrix": np.asarray(K).T.reshape(-1).tolist()}))


@pytest.fixture(scope="module")
def two_room_sequence(two_room_scene, tmp_path_factory):
    """8 frames turning on the spot in the left room of the two-room scene, towards the door at x = 3."""
    camera = PinholeCamera(160, 120, 100.0, 100.0, 79.5, 59.5, 3.5)
    renderer = Renderer(two_room_scene, camera, (0, 0, 0))
    poses = [pose_from_heading(1.2 + 0.1 * i, 1.9, 1.2, np.radians(-40 + 10 * i)) for i in range(8)]
    frames = []
    for T in poses:
        frame = renderer.render(T)
        frames.append((frame.rgb, frame.depth, T))
    folder = tmp_path_factory.mktemp("seq") / "two_room"
    write_redwood(folder, frames, camera.K)
    return folder, np.stack(poses)


def run_sequence(folder, out, *extra) -> int:
    return main(["sequence", "--input", str(folder), "--out", str(out), *extra])


def test_a_rendered_sequence_becomes_a_z_up_map_with_tracked_frontiers(two_room_sequence, tmp_path, capsys):
    folder, true_poses = two_room_sequence
    out = tmp_path / "out"
    assert run_sequence(folder, out) == 0
    assert "frontiers alive" in capsys.readouterr().out
    for name in ("frontiers.json", "map.ply", "frontiers.ply", "poses.json", "occupancy.npz", "overlay.mp4",
                 "summary.json"):
        assert (out / name).is_file(), name
    # the cameras were level, so gravity alignment only moves the first camera to the origin
    poses = np.asarray(json.loads((out / "poses.json").read_text())["T_world_cam"])
    expected = true_poses.copy()
    expected[:, :3, 3] -= true_poses[0, :3, 3]
    assert np.allclose(poses, expected, atol=1e-4)
    # the fused map has the partition wall (x = 2.9 .. 3.1 in the scene) where the scene has it
    occupancy = OccupancyMap.load(out / "occupancy.npz")
    wall = np.array([[3.0, 1.0, 1.2], [3.0, 3.0, 1.2]]) - true_poses[0, :3, 3]
    door = np.array([[3.0, 1.95, 1.0]]) - true_poses[0, :3, 3]
    assert (occupancy.state_at(wall) == OCCUPIED).all()
    assert occupancy.state_at(door)[0] != OCCUPIED
    points = np.asarray(o3d.io.read_point_cloud(str(out / "map.ply")).points) + true_poses[0, :3, 3]
    assert len(points) > 1000
    assert points[:, 0].max() < 6.3 and points[:, 1].min() > -0.3  # inside the scene's walls
    record = json.loads((out / "frontiers.json").read_text())
    assert len(record["per_frame"]) == 8 and record["scale_to_metres"] == 1.0
    for frontier in record["frontiers"] + record["removed"]:
        assert set(frontier) >= {"id", "position", "direction", "gain_m3", "first_frame", "last_frame"}
        assert abs(np.linalg.norm(frontier["direction"]) - 1.0) < 1e-3


def test_a_rerun_reads_the_cache_and_gives_the_same_frontiers(two_room_sequence, tmp_path, monkeypatch):
    folder, _ = two_room_sequence
    out = tmp_path / "out"
    assert run_sequence(folder, out, "--no-video") == 0
    first = json.loads((out / "frontiers.json").read_text())

    def no_network(*args, **kwargs):
        raise AssertionError("a cached frame was perceived again")

    monkeypatch.setattr(perceive_module, "perceive_frame", no_network)
    assert run_sequence(folder, out, "--no-video") == 0
    assert json.loads((out / "frontiers.json").read_text()) == first


def test_a_depth_model_fills_in_depth_and_scale_free_frames_are_selected(two_room_sequence, tmp_path):
    folder, _ = two_room_sequence
    out = tmp_path / "out"
    # `emulated` degrades the sensor depth like a monocular model: the depth-model path without weights
    assert run_sequence(folder, out, "--depth", "emulated", "--stride", "2", "--no-video") == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["frames"] == 4 and summary["depth"] == "emulated"
    sequence = open_sequence(folder)
    assert [frame.name for frame in select_frames(sequence, 3, 2)] == ["00000.png", "00003.png"]


def test_gravity_alignment_levels_a_tilted_world():
    from scipy.spatial.transform import Rotation

    tilt = np.eye(4)
    tilt[:3, :3] = Rotation.from_euler("xy", [25, -10], degrees=True).as_matrix()
    poses = np.stack([tilt @ pose_from_heading(0.3 * i, 0.0, 1.2, 0.4 * i) for i in range(6)])
    aligned = gravity_alignment(poses) @ poses
    assert np.allclose(aligned[:, :3, 1] @ [0, 0, 1], -1.0, atol=1e-9)  # camera y (down) axes point down ...
    assert np.allclose(aligned[:, 2, 3], 0.0, atol=1e-9)  # ... and the cameras at one height, the first at 0
    assert np.allclose(aligned[0, :3, 3], 0.0)


def test_bad_sequence_input_is_one_line_exit_2(two_room_scene, tmp_path, capsys, one_line_error):
    renderer = Renderer(two_room_scene, PinholeCamera(64, 48, 40.0, 40.0, 31.5, 23.5, 3.5), (0, 0, 0))
    T = pose_from_heading(1.5, 2.0, 1.2, 0.0)
    frame = renderer.render(T)
    write_redwood(tmp_path / "no_depth", [(frame.rgb, frame.depth, T)] * 2, renderer.camera.K, with_depth=False)
    (tmp_path / "empty").mkdir()
    write_redwood(tmp_path / "metres", [(frame.rgb, frame.depth, T)] * 2, renderer.camera.K)
    for png in (tmp_path / "metres" / "depth").iterdir():  # depth stored in whole metres, read as millimetres
        cv2.imwrite(str(png), np.nan_to_num(np.round(frame.depth)).astype(np.uint16))
    write_redwood(tmp_path / "zero_depth", [(frame.rgb, np.zeros_like(frame.depth), T)] * 2, renderer.camera.K)
    cases = [
        ([str(tmp_path / "empty")], "empty"),
        ([str(tmp_path / "zero_depth")], "no depth pixel of any frame is valid"),  # was an internal error
        ([str(tmp_path / "missing")], "missing"),
        ([str(tmp_path / "no_depth")], "no_depth: frame 00000.png has no depth image; give the sequence a depth/ "
                                       "folder of 16-bit millimetre PNGs, one per colour image, or estimate depth "
                                       "with --depth depth_anything_v2 or --depth metric3d_v2"),
        ([str(tmp_path / "no_depth"), "--depth", "depth_anything_v2"], "depth_anything_v2"),
        ([str(tmp_path / "no_depth"), "--intrinsics", "1,2,3"], "--intrinsics must be fx,fy,cx,cy"),
        ([str(tmp_path / "no_depth"), "frames.stride=0"], "frames.stride must be an integer >= 1, got 0"),
        # issue 55's fourth probe: a ZeroDivisionError (the ROS output's clock), exit 1
        ([str(tmp_path / "metres"), "outputs.video_fps=0"], "outputs.video_fps must be a number in [0.01, 1000], got 0"),
        ([str(tmp_path / "metres"), "outputs.point_voxel_m=0"], "outputs.point_voxel_m must be a number >= 0.001, got 0"),
        # eighth probe (E1): Open3D's "voxel_size is too small" after every frame, an internal error, cache/ left
        ([str(tmp_path / "metres"), "outputs.point_voxel_m=1e-9"],
         "outputs.point_voxel_m must be a number >= 0.001, got 1e-09"),
        ([str(tmp_path / "metres"), "outputs.point_stride_px=0"], "outputs.point_stride_px must be an integer in [1, 4096], got 0"),
        ([str(tmp_path / "metres"), "outputs.ros.map_every_frames=0"], "outputs.ros.map_every_frames must be an"),
        ([str(tmp_path / "metres"), "seed=-1"], "seed must be an integer in [0, 4294967295], got -1"),
        ([str(tmp_path / "metres")], "is implausible (read with depth scale 1000"),
    ]
    for (folder, *extra), expected in cases:
        assert run_sequence(folder, tmp_path / "out", "--no-video", *extra) == 2, (folder, extra)
        assert expected in one_line_error()
        assert not (tmp_path / "out").exists()  # nor its cache of the frames perceived


def test_livingroom1_frontiers_persist_across_frames(shared_data, tmp_path):
    out = tmp_path / "livingroom"
    assert run_sequence(shared_data / "images/livingroom1", out, "--max-frames", "20", "--no-video") == 0
    record = json.loads((out / "frontiers.json").read_text())
    frontiers = record["frontiers"] + record["removed"]
    assert frontiers, "no frontier was proposed on livingroom1"
    points = np.asarray(o3d.io.read_point_cloud(str(out / "map.ply")).points)
    low, high = points.min(0) - 0.3, points.max(0) + 0.3
    for frontier in frontiers:  # between the cameras and the surfaces they saw
        assert np.all(np.asarray(frontier["position"]) >= low) and np.all(np.asarray(frontier["position"]) <= high)
    # tracked ids stay stable: some frontier is re-observed in consecutive frames under the same id
    ids = [set(frame["frontier_ids"]) for frame in record["per_frame"]]
    assert any(ids[i] & ids[i + 1] for i in range(len(ids) - 1))
    assert max(frontier["observations"] for frontier in frontiers) >= 5


def test_predict_with_intrinsics_writes_3d_frontiers_of_a_real_frame(shared_data, tmp_path, capsys):
    frames = shared_data / "images/rgbd_frames"
    out = tmp_path / "tum"
    assert main(["predict", "--image", str(frames / "TUM_color.png"), "--depth", str(frames / "TUM_depth.png"),
                 "--depth-scale", "5000", "--intrinsics", "525,525,319.5,239.5", "--fill-invalid-depth",
                 "--out", str(out)]) == 0
    assert "3D frontiers" in capsys.readouterr().out
    record = json.loads((out / "frontiers.json").read_text())
    assert record["frontiers"], "no 3D frontier on the TUM frame"
    for frontier in record["frontiers"]:
        u, v = frontier["pixel"]
        assert 0 <= u < 640 and 0 <= v < 480  # in the original image
        x, y, z = frontier["position_camera"]
        assert 0.3 <= z <= 3.6  # in front of the camera, within the depth the network saw
        assert abs(525 * x / z + 319.5 - u) < 1.0 and abs(525 * y / z + 239.5 - v) < 1.0  # on its pixel's ray
        assert np.allclose(frontier["position"], [z, -x, -y], atol=1e-3)  # the level camera frame


def test_holes_in_real_depth_are_filled_from_the_nearest_valid_pixel():
    from frontiernet.model.predictor import fill_invalid_nearest

    depth = np.full((6, 8), 2.0, np.float32)
    depth[:, 4:] = 3.0
    holes = depth.copy()
    holes[0, :] = 0.0  # a blind band at the top (a registered Kinect frame)
    holes[3, 6] = np.nan  # a dropout on a surface
    filled = fill_invalid_nearest(holes)
    assert np.array_equal(filled, depth)  # each hole takes the depth of the surface next to it
    nothing = np.full((3, 3), np.nan, np.float32)
    assert np.isnan(fill_invalid_nearest(nothing)).all()

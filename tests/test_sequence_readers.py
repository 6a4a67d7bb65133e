"""Sequence readers: Redwood (real livingroom1 data and written folders), TUM RGB-D, COLMAP, format detection."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import cv2
import numpy as np
import pycolmap
import pytest
from scipy.spatial.transform import Rotation

from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.sequences import FORMATS, Camera, detect_format, open_sequence, read_colmap, read_redwood, read_tum


def write_image(path: Path, width: int, height: int, value: int = 128) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), np.full((height, width, 3), value, np.uint8))


def write_depth(path: Path, width: int, height: int, units: int) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), np.full((height, width), units, np.uint16))


def pose(rotvec, translation) -> np.ndarray:
    matrix = np.eye(4)
    matrix[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    matrix[:3, 3] = translation
    return matrix


# ----------------------------------------------------------------------------- Redwood

@pytest.fixture(scope="module")
def livingroom(shared_data) -> Path:
    path = shared_data / "images" / "livingroom1"
    if not path.is_dir():
        pytest.skip(f"livingroom1 not found at {path}")
    return path


@pytest.mark.parametrize("reader", [read_redwood, open_sequence])
def test_livingroom1(livingroom, reader):
    sequence = reader(livingroom)
    assert sequence.format == "redwood" and sequence.metric and len(sequence) == 60
    assert sequence.has_poses and sequence.has_depth
    frame = sequence.frames[0]
    np.testing.assert_array_equal(frame.camera.K, [[525, 0, 319.5], [0, 525, 239.5], [0, 0, 1]])
    assert (frame.camera.width, frame.camera.height) == (640, 480) and frame.camera.remap is None
    np.testing.assert_allclose(frame.T_world_cam, np.eye(4), atol=1e-7)
    lines = (livingroom / "trajectory.log").read_text().splitlines()
    second = np.array([[float(x) for x in line.split()] for line in lines[6:10]])
    np.testing.assert_array_equal(sequence.frames[1].T_world_cam, second)
    depth = frame.depth()
    assert depth.shape == (480, 640) and depth.dtype == np.float32
    assert 0.3 < np.nanmin(depth) and np.nanmax(depth) < 3.5 and np.isfinite(depth).mean() > 0.9
    assert frame.rgb().shape == (480, 640, 3)


def write_redwood(root: Path, count: int = 3, poses: int | None = None, size=(32, 24), intrinsics: bool = True) -> Path:
    """A Redwood folder of `count` frames (colour, depth at 1.5 m) and a trajectory of `poses` entries,
    with an Open3D ``camera_intrinsic.json`` for its frame `size` unless `intrinsics` is False."""
    if intrinsics:
        root.mkdir(parents=True, exist_ok=True)
        (root / "camera_intrinsic.json").write_text(json.dumps(
            {"width": size[0], "height": size[1], "intrinsic_matrix": [size[0], 0, 0, 0, size[0], 0,
                                                                       (size[0] - 1) / 2, (size[1] - 1) / 2, 1]}))
    for i in range(count):
        write_image(root / "color" / f"{i:05d}.jpg", *size)
        write_depth(root / "depth" / f"{i:05d}.png", *size, 1500)
    entries = [f"{i} {i} {i + 1}\n" + "\n".join(" ".join(f"{v:.8f}" for v in row)
                                                  for row in pose([0, 0.1 * i, 0], [i, 0, 0]))
               for i in range(count if poses is None else poses)]
    (root / "trajectory.log").write_text("\n".join(entries) + "\n")
    return root


def test_redwood_written(tmp_path):
    root = write_redwood(tmp_path / "seq", count=3, poses=5)
    (root / "camera_intrinsic.json").write_text(json.dumps(
        {"width": 32, "height": 24, "intrinsic_matrix": [30, 0, 0, 0, 31, 0, 15.5, 11.5, 1]}))
    sequence = read_redwood(root)
    np.testing.assert_array_equal(sequence.frames[0].camera.K, [[30, 0, 15.5], [0, 31, 11.5], [0, 0, 1]])
    np.testing.assert_allclose(sequence.frames[2].T_world_cam, pose([0, 0.2, 0], [2, 0, 0]), atol=1e-7)
    np.testing.assert_allclose(sequence.frames[1].depth(), 1.5)
    assert any("5 poses for 3 frames" in note for note in sequence.notes)
    given = read_redwood(root, Camera.pinhole(20, 20, 16, 12, 32, 24))
    assert given.frames[0].camera.K[0, 0] == 20 and any("ignored" in note for note in given.notes)


def test_redwood_without_intrinsics_takes_primesenses_for_640_x_480_frames_only(tmp_path):
    full = read_redwood(write_redwood(tmp_path / "full", count=1, size=(640, 480), intrinsics=False))
    np.testing.assert_array_equal(full.frames[0].camera.K, [[525, 0, 319.5], [0, 525, 239.5], [0, 0, 1]])
    assert any("PrimeSense" in note for note in full.notes)
    small = write_redwood(tmp_path / "small", count=1, intrinsics=False)  # issue 55: used at any size
    with pytest.raises(InputError, match=r"small: Redwood's \(PrimeSense\) default intrinsics are for 640 x 480 "
                                         r"frames, these are 32 x 24: give --intrinsics FX,FY,CX,CY"):
        read_redwood(small)


def test_redwood_errors(tmp_path):
    (tmp_path / "empty" / "color").mkdir(parents=True)
    with pytest.raises(InputError, match="color: no images"):
        read_redwood(tmp_path / "empty")
    with pytest.raises(InputError, match="missing: Redwood sequence folder not found"):
        read_redwood(tmp_path / "missing")

    short = write_redwood(tmp_path / "short", count=3, poses=2)
    with pytest.raises(InputError, match=r"trajectory.log: 2 poses for 3 frames"):
        read_redwood(short)

    mixed = write_redwood(tmp_path / "mixed")
    write_image(mixed / "color" / "00001.jpg", 40, 24)
    with pytest.raises(InputError, match=r"00001.jpg: image is 40 x 24 px .* mixed sizes"):
        read_redwood(mixed)

    depth = write_redwood(tmp_path / "depth")
    write_depth(depth / "depth" / "00002.png", 16, 12, 1000)
    with pytest.raises(InputError, match=r"depth/00002.png: depth is 16 x 12 px"):
        read_redwood(depth)

    malformed = write_redwood(tmp_path / "malformed")
    lines = (malformed / "trajectory.log").read_text().splitlines()
    lines[2] = "0 1 x 0"
    (malformed / "trajectory.log").write_text("\n".join(lines))
    with pytest.raises(InputError, match=r"trajectory.log:3: expected finite numbers"):
        read_redwood(malformed)
    lines[2] = "0 1 nan 0"  # issue 55's third probe: a NaN pose reached the map ("map bounds must be finite")
    (malformed / "trajectory.log").write_text("\n".join(lines))
    with pytest.raises(InputError, match=r"trajectory.log:3: expected finite numbers, got '0 1 nan 0'"):
        read_redwood(malformed)


def test_redwood_poses_are_taken_by_their_frame_index(tmp_path):
    # eighth probe (E6): the headers' frame indices were ignored, poses assigned by position: entries listed
    # 2, 0, 1 gave frame 0 frame 2's pose; a frame listed twice (and another not at all) was used as listed
    root = write_redwood(tmp_path / "order")
    entries = (root / "trajectory.log").read_text().splitlines()
    (root / "trajectory.log").write_text("\n".join(entries[10:15] + entries[:10]) + "\n")
    sequence = read_redwood(root)
    for index in range(3):
        np.testing.assert_allclose(sequence.frames[index].T_world_cam, pose([0, 0.1 * index, 0], [index, 0, 0]),
                                   atol=1e-7)
    (root / "trajectory.log").write_text("\n".join(entries[:5] + entries[:5] + entries[10:15]) + "\n")
    with pytest.raises(InputError, match=r"order/trajectory.log:6: frame 0 is listed twice \(also at line 1\); "
                                         r"each frame has one pose$"):
        read_redwood(root)
    (root / "trajectory.log").write_text("\n".join(entries[:5] + entries[10:15]) + "\n")  # frames 0 and 2
    with pytest.raises(InputError, match=r"order/trajectory.log: no pose for frame 1, though the log lists frame 2: "
                                         r"the first number of a header line is the frame's index, from 0"):
        read_redwood(root)
    (root / "trajectory.log").write_text("\n".join(["-1 -1 0", *entries[1:5]]) + "\n")
    with pytest.raises(InputError, match=r"trajectory.log:1: a frame header's first number is the frame's index, "
                                         r"a whole number >= 0; got '-1 -1 0'"):
        read_redwood(root)


@pytest.mark.parametrize("layout", ["redwood", "images"])
def test_a_folder_named_like_a_frame_is_named(layout, tmp_path):
    # seventh probe (D18): a folder color/00001.jpg was skipped, and the message counted the images instead
    # ("depth: 3 depth images for 2 colour images"); in a plain image folder it was "unknown sequence format"
    root = write_redwood(tmp_path / "rw") if layout == "redwood" else tmp_path / "rw"
    folder = root / "color" / "00001.jpg" if layout == "redwood" else root / "b.jpg"
    write_image(root / "a.jpg", 32, 24)
    if folder.exists():
        folder.unlink()
    folder.mkdir(parents=True)
    options = {} if layout == "redwood" else {"conf": dict(load_config("sequence").sfm)}
    with pytest.raises(InputError, match=rf"^{re.escape(str(folder))}: is a folder, expected a file \(image\)$"):
        open_sequence(root, **options)


@pytest.mark.parametrize("matrix, message", [
    # seventh probe: a file's intrinsics got none of the bounds typed --intrinsics get
    ([1e6, 0, 0, 0, 1e6, 0, 15.5, 11.5, 1], "a focal length of 1e+06 px is over 100 x the 32 x 24 image's side"),
    ([0.5, 0, 0, 0, 0.5, 0, 15.5, 11.5, 1], "a focal length of 0.5 px is under 0.04 x the 32 x 24 image's side"),
    ([30, 0, 0, 0, 30, 0, 320, 240, 1], "the principal point (320, 240) lies outside the 32 x 24 image"),
])
def test_redwood_intrinsics_out_of_bounds_name_the_file(matrix, message, tmp_path):
    root = write_redwood(tmp_path / "rw")
    (root / "camera_intrinsic.json").write_text(json.dumps({"width": 32, "height": 24, "intrinsic_matrix": matrix}))
    with pytest.raises(InputError, match=rf"^{re.escape(str(root / 'camera_intrinsic.json'))}: {re.escape(message)}"):
        read_redwood(root)


def test_a_redwood_matrix_that_is_no_rigid_transform_names_its_line_and_frame(tmp_path):
    # seventh probe (D17): a scaled first matrix ran ~13 s, then "T_world_cam must be a rigid transform"
    # named neither the file nor the frame
    scaled = write_redwood(tmp_path / "scaled")
    lines = (scaled / "trajectory.log").read_text().splitlines()
    lines[6] = "2.0 0 0 1"  # frame 1's first row (line 7): its rotation part scales x by 2
    (scaled / "trajectory.log").write_text("\n".join(lines))
    with pytest.raises(InputError, match=r"scaled/trajectory.log:7: the pose of frame 1 must be a rigid transform "
                                         r"\(rotation \+ translation\), got \[\[2.0, 0.0, 0.0, 1.0\], "):
        read_redwood(scaled)


# ----------------------------------------------------------------------------- TUM

def tum_pose(time: float) -> np.ndarray:
    """The test trajectory: translation linear in time, yaw 0.3 rad/s about z."""
    return pose([0, 0, 0.3 * time], [time, 2 * time, 0.5])


def write_tum(root: Path) -> None:
    rgb_times = [1.000, 1.033, 1.066, 1.100, 2.000]  # the last has no ground truth within 0.02 s
    depth_times = [1.005, 1.030, 1.070, 1.098, 2.001]
    for time in rgb_times:
        write_image(root / "rgb" / f"{time:.6f}.png", 64, 48)
    for time in depth_times:
        write_depth(root / "depth" / f"{time:.6f}.png", 64, 48, 5000)
    (root / "rgb.txt").write_text("# color images\n# timestamp filename\n" +
                                  "".join(f"{t:.6f} rgb/{t:.6f}.png\n" for t in rgb_times))
    (root / "depth.txt").write_text("# depth maps\n" + "".join(f"{t:.6f} depth/{t:.6f}.png\n" for t in depth_times))
    lines = ["# timestamp tx ty tz qx qy qz qw"]
    for time in np.arange(0.99, 1.13, 0.02):
        matrix = tum_pose(time)
        quaternion = Rotation.from_matrix(matrix[:3, :3]).as_quat()  # x y z w, TUM's order
        lines.append(" ".join(f"{v:.9f}" for v in [time, *matrix[:3, 3], *quaternion]))
    (root / "groundtruth.txt").write_text("\n".join(lines) + "\n")


def test_tum(tmp_path):
    write_tum(tmp_path)
    assert detect_format(tmp_path) == "tum"
    with pytest.raises(InputError, match="TUM's default intrinsics are for 640 x 480 frames, these are 64 x 48"):
        open_sequence(tmp_path)  # (issue 55's third probe: the 640 x 480 K was used for any frame size)
    sequence = open_sequence(tmp_path, camera=Camera.pinhole(52.5, 52.5, 31.95, 23.95, 64, 48))
    assert sequence.format == "tum" and len(sequence) == 4
    assert [frame.timestamp for frame in sequence] == [1.000, 1.033, 1.066, 1.100]
    assert any("0 frame(s) without a depth" in note and "1 without a ground-truth pose" in note
               for note in sequence.notes)
    for frame in sequence:
        np.testing.assert_allclose(frame.T_world_cam, tum_pose(frame.timestamp), atol=1e-6)
    assert sequence.frames[2].depth_path.name == "1.070000.png"
    np.testing.assert_allclose(sequence.frames[0].depth(), 1.0)
    camera = sequence.frames[0].camera
    assert (camera.width, camera.height) == (64, 48)
    np.testing.assert_array_equal(camera.K, [[52.5, 0, 31.95], [0, 52.5, 23.95], [0, 0, 1]])
    strict = read_tum(tmp_path, camera, max_time_difference_s=0.0045)  # 1.000 has no depth, 1.100 and 2.000 no pose
    assert [frame.timestamp for frame in strict] == [1.033, 1.066]
    assert "skipped 1 frame(s) without a depth frame and 2 without a ground-truth pose" in strict.notes[0]


def test_text_files_saved_with_a_byte_order_mark_read_as_without(tmp_path):
    # eighth probe (E22): "rgb.txt:1: expected finite numbers, got '\ufeff#'" (a Windows editor's UTF-8 mark)
    write_tum(tmp_path / "tum")
    for name in ("rgb.txt", "depth.txt", "groundtruth.txt"):
        path = tmp_path / "tum" / name
        path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    camera = Camera.pinhole(52.5, 52.5, 31.95, 23.95, 64, 48)
    assert [frame.timestamp for frame in read_tum(tmp_path / "tum", camera)] == [1.000, 1.033, 1.066, 1.100]
    root = write_redwood(tmp_path / "rw")  # and a Redwood trajectory and its Open3D intrinsics
    for name in ("trajectory.log", "camera_intrinsic.json"):
        (root / name).write_bytes(b"\xef\xbb\xbf" + (root / name).read_bytes())
    assert len(read_redwood(root)) == 3


# ----------------------------------------------------------------------------- COLMAP

SIZE = (160, 120)
OPENCV_PARAMS = [110.0, 114.0, 79.0, 61.5, -0.15, 0.03, 0.001, -0.002]  # fx fy cx cy k1 k2 p1 p2
CAM_FROM_WORLD = {"a.png": (1, [0.1, -0.2, 0.05], [0.3, -0.1, 2.0]),
                  "b.png": (2, [0.0, 0.3, 0.1], [-0.5, 0.2, 1.5]),
                  "c.png": (1, [-0.2, 0.1, 0.0], [0.1, 0.4, 1.0])}


def write_colmap_project(root: Path) -> pycolmap.Reconstruction:
    """A COLMAP project: images/ with a.png, b.png, c.png and a binary model in sparse/0."""
    reconstruction = pycolmap.Reconstruction()
    reconstruction.add_camera_with_trivial_rig(
        pycolmap.Camera(camera_id=1, model="PINHOLE", width=SIZE[0], height=SIZE[1], params=[100, 102, 80, 60]))
    reconstruction.add_camera_with_trivial_rig(
        pycolmap.Camera(camera_id=2, model="OPENCV", width=SIZE[0], height=SIZE[1], params=OPENCV_PARAMS))
    keypoints = np.array([[10.0, 20.0], [50.0, 60.0]])
    for image_id, (name, (camera_id, rotvec, translation)) in enumerate(sorted(CAM_FROM_WORLD.items()), 1):
        rigid = pycolmap.Rigid3d(pycolmap.Rotation3d(Rotation.from_rotvec(rotvec).as_matrix()), np.array(translation))
        image = pycolmap.Image(name=name, keypoints=keypoints, camera_id=camera_id, image_id=image_id)
        reconstruction.add_image_with_trivial_frame(image, rigid)
        write_image(root / "images" / name, *SIZE)
    for point in range(2):
        track = pycolmap.Track()
        for image_id in (1, 2, 3):
            track.add_element(image_id, point)
        reconstruction.add_point3D(np.array([0.1 * point, 0.0, 3.0]), track)
    (root / "sparse" / "0").mkdir(parents=True)
    reconstruction.write(root / "sparse" / "0")
    return reconstruction


@pytest.fixture
def colmap_project(tmp_path) -> Path:
    write_colmap_project(tmp_path / "project")
    return tmp_path / "project"


def test_colmap_poses_and_cameras(colmap_project, tmp_path):
    assert detect_format(colmap_project) == "colmap"
    sequence = open_sequence(colmap_project)
    assert sequence.format == "colmap" and not sequence.metric
    assert [frame.name for frame in sequence] == ["a.png", "b.png", "c.png"]
    assert "3 of 3 images in the model registered" in sequence.notes[0]
    for frame in sequence:
        _, rotvec, translation = CAM_FROM_WORLD[frame.name]
        np.testing.assert_allclose(frame.T_world_cam, np.linalg.inv(pose(rotvec, translation)), atol=1e-9)
    pinhole, distorted = sequence.frames[0].camera, sequence.frames[1].camera
    assert pinhole is sequence.frames[2].camera  # one Camera (and one set of tables) per COLMAP camera
    np.testing.assert_allclose(pinhole.K, [[100, 0, 79.5], [0, 102, 59.5], [0, 0, 1]])  # COLMAP centre 0.5 -> 0
    assert pinhole.remap is None and distorted.model == "OPENCV"
    np.testing.assert_allclose(distorted.K, [[112, 0, 78.5], [0, 112, 61], [0, 0, 1]])
    assert distorted.remap[0].shape == (SIZE[1], SIZE[0]) and distorted.remap[0].dtype == np.float32

    text_model = tmp_path / "text"
    text_model.mkdir()
    pycolmap.Reconstruction(colmap_project / "sparse" / "0").write_text(text_model)
    from_text = read_colmap(text_model, image_dir=colmap_project / "images")
    np.testing.assert_allclose(from_text.poses(), sequence.poses(), atol=1e-9)


def blob_image(centre, size, sigma: float = 1.2) -> np.ndarray:
    """(H, W, 3) uint8 Gaussian blob at pixel `centre` (x, y), OpenCV convention."""
    u, v = np.meshgrid(np.arange(size[0]), np.arange(size[1]))
    blob = 250 * np.exp(-((u - centre[0]) ** 2 + (v - centre[1]) ** 2) / (2 * sigma ** 2))
    return np.repeat(blob[..., None], 3, axis=2).round().astype(np.uint8)


def centroid(image: np.ndarray) -> np.ndarray:
    weight = image[..., 0].astype(np.float64)
    weight[weight < 20] = 0
    v, u = np.indices(weight.shape)
    return np.array([(u * weight).sum(), (v * weight).sum()]) / weight.sum()


@pytest.mark.parametrize("point", [[0.0, 0.0, 2.0], [0.5, 0.4, 1.5], [-0.6, -0.4, 1.4], [0.55, -0.45, 1.2]])
def test_colmap_undistortion(colmap_project, point):
    """A point drawn where OpenCV's distortion model puts it in the raw image comes out of the remap
    at its pinhole projection with the camera's K."""
    frame = open_sequence(colmap_project).frames[1]
    fx, fy, cx, cy, *distortion = OPENCV_PARAMS
    raw_K = np.array([[fx, 0, cx - 0.5], [0, fy, cy - 0.5], [0, 0, 1]])  # COLMAP pixel centre 0.5 -> OpenCV 0
    raw, _ = cv2.projectPoints(np.array([point]), np.zeros(3), np.zeros(3), raw_K, np.array(distortion))
    cv2.imwrite(str(frame.rgb_path), blob_image(raw.ravel(), SIZE))
    pinhole = frame.camera.K @ np.array(point)
    # within 0.05 px here; without the 0.5 px pixel-centre shift it is off by ~0.7 px
    assert np.linalg.norm(centroid(frame.rgb()) - pinhole[:2] / pinhole[2]) < 0.25


def test_colmap_errors(colmap_project):
    write_image(colmap_project / "images" / "c.png", 80, 60)
    with pytest.raises(InputError, match=r"c.png: image is 80 x 60 px but COLMAP camera 1 is 160 x 120"):
        read_colmap(colmap_project)
    (colmap_project / "images" / "b.png").unlink()
    with pytest.raises(InputError, match=r"b.png: image of the COLMAP model not found \(1 of 3"):
        read_colmap(colmap_project)
    with pytest.raises(InputError, match="no COLMAP model"):
        read_colmap(colmap_project / "images")
    (colmap_project / "sparse" / "0" / "cameras.bin").unlink()
    (colmap_project / "sparse" / "0" / "cameras.txt").write_text("1 PINHOLE x\n")
    with pytest.raises(InputError, match=r"sparse/0: not a readable COLMAP model"):
        read_colmap(colmap_project)
    with pytest.raises(InputError, match="own cameras"):
        open_sequence(colmap_project, camera=Camera.pinhole(1, 1, 1, 1, 2, 2))


def test_colmap_intrinsics_out_of_bounds_name_the_camera(colmap_project):
    # seventh probe: cameras.txt's intrinsics got none of the bounds typed --intrinsics get
    model = pycolmap.Reconstruction(colmap_project / "sparse" / "0")
    model.cameras[1].params = [1e6, 1e6, 80, 60]
    model.write(colmap_project / "sparse" / "0")
    with pytest.raises(InputError, match=r"project: COLMAP camera 1: a focal length of 1e\+06 px is over 100 x the "
                                         r"160 x 120 image's side"):
        read_colmap(colmap_project)


def test_a_camera_of_no_width_is_named_so(colmap_project, tmp_path):
    # eighth probe (E29): "COLMAP camera 1: the principal point (319.5, 239.5) lies outside the 0 x 480 image"
    text = legacy_text_model(colmap_project)
    lines = (text / "cameras.txt").read_text().splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("1 "))
    lines[at] = "1 PINHOLE 0 120 100 102 80 60"
    (text / "cameras.txt").write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"project: COLMAP camera 1: an image of 0 x 120 px; width and height must be "
                                         r"at least 1 px$"):
        read_colmap(colmap_project)
    root = write_redwood(tmp_path / "rw")  # an Open3D intrinsic file alike
    (root / "camera_intrinsic.json").write_text(json.dumps({"width": 0, "height": 24,
                                                            "intrinsic_matrix": [30, 0, 0, 0, 30, 0, 15.5, 11.5, 1]}))
    with pytest.raises(InputError, match=r"camera_intrinsic.json: an image of 0 x 24 px"):
        read_redwood(root)


def test_a_colmap_pose_that_is_no_rigid_transform_names_the_image(colmap_project):
    # seventh probe (D17's class): a quaternion not of unit length in frames.txt / images.txt made a scaled
    # rotation, refused only by the map ("T_world_cam must be a rigid transform", no file, no frame)
    model = pycolmap.Reconstruction(colmap_project / "sparse" / "0")
    text = colmap_project / "sparse" / "0"
    for name in ("cameras", "images", "points3D", "frames", "rigs"):
        (text / f"{name}.bin").unlink(missing_ok=True)
    model.write_text(text)
    frames = text / "frames.txt" if (text / "frames.txt").is_file() else text / "images.txt"
    lines = frames.read_text().splitlines()
    first = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    fields = lines[first].split()
    quaternion_at = 2 if frames.name == "frames.txt" else 1  # FRAME_ID RIG_ID QW ... / IMAGE_ID QW ...
    fields[quaternion_at] = "2"
    lines[first] = " ".join(fields)
    frames.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"project: the COLMAP model's pose of image a.png must be a rigid "
                                         r"transform \(rotation \+ translation\), got \[\["):
        read_colmap(colmap_project)


def legacy_text_model(project: Path) -> Path:
    """`project`'s model rewritten as the text files of COLMAP before 3.12 (cameras, images, points3D:
    no rigs.txt or frames.txt, so images.txt holds the poses and camera ids); returns the model folder."""
    model, text = pycolmap.Reconstruction(project / "sparse" / "0"), project / "sparse" / "0"
    for name in ("cameras", "images", "points3D", "frames", "rigs"):
        (text / f"{name}.bin").unlink(missing_ok=True)
    model.write_text(text)
    for name in ("frames.txt", "rigs.txt"):
        (text / name).unlink(missing_ok=True)
    return text


def edit_image_line(text: Path, image_id: int, edit) -> None:
    """Rewrites the first line of image `image_id` in ``text/images.txt`` with ``edit(fields)``."""
    lines = (text / "images.txt").read_text().splitlines()
    at = next(i for i, line in enumerate(lines) if line.split()[:1] == [str(image_id)] and not line.startswith("#"))
    fields = lines[at].split()
    edit(fields)
    lines[at] = " ".join(fields)
    (text / "images.txt").write_text("\n".join(lines) + "\n")


def test_a_colmap_image_of_a_camera_the_model_lacks_is_refused(colmap_project):
    # eighth probe (E2): images.txt naming camera 9, which cameras.txt lacks: internal error (IndexError: Rig
    # with ID 9 does not exist), exit 1
    text = legacy_text_model(colmap_project)
    edit_image_line(text, 3, lambda fields: fields.__setitem__(8, "9"))
    with pytest.raises(InputError, match=r"sparse/0: not a readable COLMAP model \(Rig with ID 9 does not exist; "
                                         r"an id in one file that the others do not hold, e\.g\. an image's "
                                         r"CAMERA_ID not in cameras\.txt\)"):
        read_colmap(colmap_project)


def test_a_colmap_pose_with_a_zero_quaternion_is_refused(colmap_project):
    # eighth probe (E7): QW QX QY QZ = 0 0 0 0 in images.txt became the identity rotation (pycolmap's matrix())
    # and was used; TUM's reader refuses the same quaternion
    text = legacy_text_model(colmap_project)
    edit_image_line(text, 1, lambda fields: fields.__setitem__(slice(1, 5), ["0"] * 4))
    with pytest.raises(InputError, match=r"project: the COLMAP model's pose of image a.png: a quaternion has zero "
                                         r"length"):
        read_colmap(colmap_project)


def test_a_colmap_project_without_depth_says_where_depth_goes(colmap_project, tmp_path, capsys):
    # seventh probe (D25): "col_ok: frame 0.jpg has no depth file: or choose a depth model with --depth ..."
    from frontiernet.cli.main import main

    assert main(["sequence", "--input", str(colmap_project), "--out", str(tmp_path / "out"), "--no-video"]) == 2
    assert capsys.readouterr().err.strip() == (
        f"frontiernet sequence: error: {colmap_project}: frame a.png has no depth image; give the sequence a depth/ "
        "folder beside images/ (the images' names, 16-bit millimetre .png or .npy metres), or estimate depth with "
        "--depth depth_anything_v2 or --depth metric3d_v2")


def test_colmap_depth(colmap_project, tmp_path):
    for name in CAM_FROM_WORLD:
        write_depth(tmp_path / "depth" / name, *SIZE, 2000)
    np.save(tmp_path / "depth" / "c.npy", np.full(SIZE[::-1], 3.0, np.float32))
    (tmp_path / "depth" / "c.png").unlink()
    sequence = read_colmap(colmap_project, depth_dir=tmp_path / "depth")
    assert sequence.frames[2].depth_path.suffix == ".npy"
    assert np.nanmedian(sequence.frames[0].depth()) == pytest.approx(2.0)
    assert np.nanmedian(sequence.frames[2].depth()) == pytest.approx(3.0)
    (tmp_path / "depth" / "a.png").unlink()
    with pytest.raises(InputError, match=r"a.png: depth file not found"):
        read_colmap(colmap_project, depth_dir=tmp_path / "depth")


# ----------------------------------------------------------------------------- detection

def test_detection(tmp_path):
    assert FORMATS == ("tum", "redwood", "colmap", "images")
    write_redwood(tmp_path / "redwood")
    assert detect_format(tmp_path / "redwood") == "redwood"
    write_image(tmp_path / "folder" / "x.png", 8, 8)
    assert detect_format(tmp_path / "folder") == "images"
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match=r"empty: unknown sequence format; looked for rgb.txt"):
        open_sequence(tmp_path / "empty")
    with pytest.raises(InputError, match="format 'kitti' is unknown"):
        open_sequence(tmp_path / "redwood", format="kitti")
    shutil.rmtree(tmp_path / "redwood" / "color")
    with pytest.raises(InputError, match="no colour folder"):
        open_sequence(tmp_path / "redwood", format="redwood")

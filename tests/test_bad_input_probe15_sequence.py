"""Bad input of the fifteenth probe of issue 55 for ``frontiernet sequence``: a trajectory with a camera far off
(Q10). A TUM ground-truth line at 1e6 m made the map over the frames 368 GiB, a MemoryError (exit 1) once every
frame was perceived, with ``<out>/cache`` left; 1e30 m (or 1e20 m in z) overflowed the voxel count: a numpy warning,
then "map shape must be 3 positive voxel counts", naming no file; a Redwood translation of 5e5 m the same
MemoryError. Now a position farther than 1e5 m (the bound of a typed ``--pose``) is refused as the trajectory is
read, naming its file and line, and frames spanning more than a sequence's map may hold (at ``map.voxel_size``)
before the first frame is perceived, for every reader (an up-to-scale model's once pass 1 gave its scale); one line,
exit code 2, no output folder or cache left."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from frontiernet.cli.main import main
from frontiernet.errors import InputError
from frontiernet.sequences import Camera, read_redwood, read_tum
from frontiernet.sequences import main as sequence_main
from test_sequence_readers import SIZE, write_colmap_project, write_depth, write_image, write_redwood

ERROR = "frontiernet sequence: error: "
FAR = "m lies farther than 100000 m from the origin (no captured sequence spans that far; check the units are metres)"
TOO_LARGE = ("more than the 400,000,000 of max_map_voxels; check the poses (metres), or set a larger "
             "map.voxel_size")
TUM_TIMES = (1.0, 1.1, 1.2)


def write_tum_frames(root: Path, colour: Path | None = None, depth: Path | None = None) -> Path:
    """A TUM folder of three frames at :data:`TUM_TIMES` (the shared TUM frame's images, else 64 x 48 ones at 1 m)
    with an identity ground-truth pose at each; :func:`ground_truth` sets the positions."""
    for index, time in enumerate(TUM_TIMES, 1):
        if colour is None:
            write_image(root / "rgb" / f"{index}.png", 64, 48)
            write_depth(root / "depth" / f"{index}.png", 64, 48, 5000)
        else:
            (root / "rgb").mkdir(parents=True, exist_ok=True)
            (root / "depth").mkdir(exist_ok=True)
            shutil.copy(colour, root / "rgb" / f"{index}.png")
            shutil.copy(depth, root / "depth" / f"{index}.png")
    for name in ("rgb", "depth"):
        (root / f"{name}.txt").write_text(f"# {name}\n" + "".join(f"{time} {name}/{index}.png\n"
                                                                  for index, time in enumerate(TUM_TIMES, 1)))
    return ground_truth(root, [(0, 0, 0), (0.05, 0, 0), (0.1, 0, 0)])


def ground_truth(root: Path, positions) -> Path:
    """`root`'s ``groundtruth.txt``: a comment line, then one identity-rotation pose per time of :data:`TUM_TIMES` at
    `positions` (as written: strings stay as typed); returns `root`."""
    (root / "groundtruth.txt").write_text("# gt\n" + "".join(f"{time} {' '.join(map(str, position))} 0 0 0 1\n"
                                                             for time, position in zip(TUM_TIMES, positions)))
    return root


def set_translation(log: Path, line: int, value: str) -> None:
    """Set the last number (the translation) of `log`'s matrix row at 0-based `line` to `value` as typed."""
    lines = log.read_text().splitlines()
    lines[line] = " ".join([*lines[line].split()[:3], value])
    log.write_text("\n".join(lines) + "\n")


def refused(source: Path, out: Path, line: str, one_line_error, *extra) -> None:
    """``sequence --input source``: exit 2, `line` alone on stderr, `out` not made."""
    assert main(["sequence", "--input", str(source), "--no-video", "--no-mcap", "--out", str(out),
                 *map(str, extra)]) == 2
    assert one_line_error() == ERROR + line
    assert not out.exists()


@pytest.fixture
def no_perception(monkeypatch):
    """Pass 1 fails the test: a refusal must come before any frame is perceived."""
    def perceive(*args, **kwargs):
        raise AssertionError("a frame was perceived")
    monkeypatch.setattr(sequence_main, "perceive_frames", perceive)


# ----------------------------------------------------------------------------- a position too far off

def test_the_probes_tum_sequence_with_a_pose_1e6_m_off_is_refused_naming_the_line(shared_data, tmp_path,
                                                                                 one_line_error, no_perception):
    # Q10: exit 1 "internal error (MemoryError: Unable to allocate 368. GiB ...)" after 13 s, o_sq11/cache left
    frames = shared_data / "images" / "rgbd_frames"
    if not (frames / "TUM_color.png").is_file():
        pytest.skip(f"the TUM frame not found in {frames}")
    root = write_tum_frames(tmp_path / "tum10", frames / "TUM_color.png", frames / "TUM_depth.png")
    ground_truth(root, [(0, 0, 0), ("1e6", 0, 0), (0.1, 0, 0)])
    refused(root, tmp_path / "o_sq11", f"{root / 'groundtruth.txt'}:3: position (1e+06, 0, 0) {FAR}", one_line_error)


@pytest.mark.parametrize("position, shown", [(("1e30", 0, 0), "1e+30, 0, 0"), ((0, 0, "1e20"), "0, 0, 1e+20"),
                                             ((0, "-100000.5", 0), "0, -100000, 0")])
def test_a_tum_pose_far_off_is_refused_naming_its_line(position, shown, tmp_path, one_line_error, no_perception):
    # 1e30 (1e20 in z): a numpy RuntimeWarning from occupancy.py, then "map shape must be 3 positive voxel counts
    # (X, Y, Z), got (-9223372036854775808, 105, 94)", naming no file
    root = ground_truth(write_tum_frames(tmp_path / "tum"), [(0, 0, 0), (0.1, 0, 0), position])
    refused(root, tmp_path / "out", f"{root / 'groundtruth.txt'}:4: position ({shown}) {FAR}", one_line_error,
            "--intrinsics", "52.5,52.5,31.95,23.95")


def test_a_tum_pose_within_1e5_m_reads_and_one_past_it_is_refused_by_the_reader(tmp_path):
    camera = Camera.pinhole(52.5, 52.5, 31.95, 23.95, 64, 48)
    root = ground_truth(write_tum_frames(tmp_path / "tum"), [(0, 0, 0), (0, 0, 0), (-1e5, 0, 1e5)])
    np.testing.assert_allclose(read_tum(root, camera).frames[2].T_world_cam[:3, 3], [-1e5, 0, 1e5])
    ground_truth(root, [(0, 0, 0), (0, "100000.01", 0), (0, 0, 0)])
    with pytest.raises(InputError, match=r"groundtruth\.txt:3: position \(0, 100000, 0\) m lies farther than 100000 m"):
        read_tum(root, camera)


def test_a_redwood_translation_of_5e5_m_is_refused_naming_its_row(tmp_path, one_line_error, no_perception):
    # Q10: exit 1, MemoryError
    root = write_redwood(tmp_path / "rw")
    log = root / "trajectory.log"
    set_translation(log, 12, "5e5")  # frame 2's second row: y = 5e5 m
    refused(root, tmp_path / "out", f"{log}:13: position (2, 500000, 0) {FAR}", one_line_error)
    set_translation(log, 12, "0")
    set_translation(log, 13, "-3e5")  # z, named at the third row
    with pytest.raises(InputError, match=re.escape(f"trajectory.log:14: position (2, 0, -300000) {FAR}")):
        read_redwood(root)


# ----------------------------------------------------------------------------- frames spanning more than a map holds

def test_tum_frames_spanning_more_than_a_map_holds_are_refused_before_any_frame(tmp_path, one_line_error,
                                                                                no_perception):
    # each position within 1e5 m, but the map over them 9e4 x 9e4 m: 5.67e13 voxels of 0.1 m
    root = ground_truth(write_tum_frames(tmp_path / "tum"), [(0, 0, 0), (0.1, 0, 0), (9e4, 9e4, 0)])
    refused(root, tmp_path / "out", f"{root}: the frames' camera positions span 9e+04 x 0 x 9e+04 m (gravity-aligned; "
            "frame 1.png to frame 3.png on x): a map over them, widened by bounds_margin_m 3.5 m a side, holds "
            f"5.67e+13 voxels of map.voxel_size 0.1 m (2.64e+05 GiB), {TOO_LARGE}", one_line_error,
            "--intrinsics", "52.5,52.5,31.95,23.95")
    assert main(["sequence", "--input", str(root), "--no-video", "--no-mcap", "--out", str(tmp_path / "out"),
                 "--intrinsics", "52.5,52.5,31.95,23.95", "map.voxel_size=1"]) == 2  # 5.67e10 at 1 m: still too many
    assert "holds 5.67e+10 voxels of map.voxel_size 1 m" in one_line_error()


def test_a_kept_earlier_run_stays_when_a_rerun_is_refused_for_its_span(tmp_path, one_line_error, no_perception):
    root = ground_truth(write_tum_frames(tmp_path / "tum"), [(0, 0, 0), (0.1, 0, 0), (9e4, 9e4, 0)])
    out = tmp_path / "out"
    (out / "cache").mkdir(parents=True)
    (out / "cache" / "00000.npz").write_bytes(b"an earlier run's")
    assert main(["sequence", "--input", str(root), "--no-video", "--no-mcap", "--out", str(out),
                 "--intrinsics", "52.5,52.5,31.95,23.95"]) == 2
    assert "the frames' camera positions span" in one_line_error()
    assert sorted(path.name for path in out.rglob("*")) == ["00000.npz", "cache"]


def test_redwood_frames_spanning_more_than_a_map_holds_are_refused_before_any_frame(tmp_path, one_line_error,
                                                                                    no_perception):
    root = write_redwood(tmp_path / "rw")
    set_translation(root / "trajectory.log", 7, "6e4")  # frame 1 at (1, 6e4, 7e4) m
    set_translation(root / "trajectory.log", 8, "7e4")
    assert main(["sequence", "--input", str(root), "--no-video", "--no-mcap", "--out", str(tmp_path / "out")]) == 2
    line = one_line_error()
    assert line.startswith(f"{ERROR}{root}: the frames' camera positions span ") and line.endswith(TOO_LARGE)
    assert "frame 00000.jpg to frame 00001.jpg" in line or "frame 00001.jpg to frame 00000.jpg" in line
    assert not (tmp_path / "out").exists()


def test_recording_frames_spanning_more_than_a_map_holds_are_refused_before_any_frame(tmp_path, one_line_error,
                                                                                      no_perception):
    pytest.importorskip("rosbags")
    from test_rosbag import recording, synthetic_frames

    frames, K = synthetic_frames(3)
    for frame in frames:  # every camera 4e6 m from the recording's origin (a UTM northing), a metre apart: the
        frame["T"][:3, 3] += [3e5, 4e6, 0]  # aligned world starts at the first camera, the map is small
    compact = recording(frames, K).write(tmp_path / "compact", "mcap")
    with pytest.raises(AssertionError, match="a frame was perceived"):  # on to pass 1
        sequence_main.main(None, compact, tmp_path / "compact_out", video=False, mcap=False, progress=False)
    frames[2]["T"][:3, 3] += [9e4, 0, 9e4]
    bag = recording(frames, K).write(tmp_path / "rec", "mcap")
    assert main(["sequence", "--input", str(bag), "--no-video", "--no-mcap", "--out", str(tmp_path / "out")]) == 2
    line = one_line_error()
    assert line.startswith(f"{ERROR}{bag}: the frames' camera positions span ") and line.endswith(TOO_LARGE)
    assert not (tmp_path / "out").exists()


def test_an_up_to_scale_model_spanning_more_than_a_map_holds_is_refused_before_pass_2(tmp_path, one_line_error,
                                                                                     monkeypatch):
    # a COLMAP model's poses are metric only once pass 1's depth gave the scale: refused then, before the map,
    # and the cache of pass 1 removed with the output folder this run made
    project = tmp_path / "project"
    write_colmap_project(project)
    for name in ("a.png", "b.png", "c.png"):
        write_depth(project / "depth" / name, *SIZE, 2000)
    from frontiernet.sequences import sfm

    monkeypatch.setattr(sfm, "metric_scale", lambda sequence, depths: (1e5, {"points": 20, "images": 3,
                                                                            "spread": 0.0}))
    monkeypatch.setattr(sequence_main, "track_frontiers", lambda *args, **kwargs: pytest.fail("a map was made"))
    out = tmp_path / "out"
    assert main(["sequence", "--input", str(project), "--no-video", "--no-mcap", "--out", str(out)]) == 2
    line = one_line_error()
    assert line.startswith(f"{ERROR}{project} (poses x 1e+05 to metres): the frames' camera positions span ")
    assert line.endswith(TOO_LARGE)
    assert not out.exists()

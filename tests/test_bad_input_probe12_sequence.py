"""Bad input of the twelfth probe of issue 55 (runs/probe12_report.md) for ``sequence`` and ``predict``: a Redwood
trajectory or a TUM list that is a pipe or a link to /dev/zero (S3 blocked, S14 took it for absent), an output of the
wrong kind found only after the whole run (S7) and a float depth of 3e38 m (S9, a numpy warning, then "inf"). Each
refusal one line naming the path or value, exit code 2, nothing written before lost. What blocked on a pipe runs in a
subprocess with a timeout, so that a regression fails instead of hanging."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from conftest import folder_files, python_in_subprocess

from frontiernet.cli.main import main
from frontiernet.errors import InputError
from frontiernet.sequences import Camera, detect_format, open_sequence
from frontiernet.sequences.images import read_depth
from frontiernet.sequences.outputs import check_run_outputs
from test_sequence_readers import write_image, write_redwood, write_tum

CAMERA = Camera.pinhole(52.5, 52.5, 31.95, 23.95, 64, 48)
"""The intrinsics of :func:`write_tum`'s 64 x 48 frames."""


def sequence_cli(*args: str) -> subprocess.CompletedProcess:
    """``frontiernet sequence ARGS`` in a subprocess (a read of a pipe would wait forever)."""
    return python_in_subprocess("import sys; from frontiernet.cli.main import main; "
                         f"sys.argv = ['frontiernet', 'sequence', *{list(args)!r}]; sys.exit(main())")


def open_in_subprocess(folder: Path, camera: bool = True) -> subprocess.CompletedProcess:
    """:func:`open_sequence` of `folder` (format detected; with `camera` :data:`CAMERA`) in a subprocess; its
    InputError as the last line."""
    given = "Camera.pinhole(52.5, 52.5, 31.95, 23.95, 64, 48)" if camera else "None"
    return python_in_subprocess("import sys; from frontiernet.errors import InputError; "
                         "from frontiernet.sequences import Camera, open_sequence\n"
                         f"try: open_sequence({str(folder)!r}, camera={given})\n"
                         "except InputError as error: sys.exit(str(error))")


# ----------------------------------------------------------------------------- S3: the Redwood trajectory

@pytest.mark.parametrize("name", ["trajectory.log", "other.log"])
def test_a_redwood_trajectory_that_is_a_pipe_is_named_not_waited_on(name, tmp_path):
    # S3: sequence --input rw_logfifo blocked until killed (the trajectory read from the pipe)
    root = write_redwood(tmp_path / "rw")
    (root / "trajectory.log").unlink()
    os.mkfifo(root / name)
    out = tmp_path / "out"
    result = sequence_cli("--input", str(root), "--no-video", "--out", str(out))
    assert result.returncode == 2, result.stderr
    assert result.stderr.strip().splitlines() == [
        f"frontiernet sequence: error: {root / name}: not a regular file, expected a file (Redwood trajectory)"]
    assert not out.exists()


def test_a_redwood_trajectory_that_is_a_dangling_link_or_a_folder_is_named(tmp_path):
    root = write_redwood(tmp_path / "rw")
    (root / "trajectory.log").unlink()
    (root / "trajectory.log").symlink_to(tmp_path / "nowhere.log")
    with pytest.raises(InputError, match=r"trajectory\.log: Redwood trajectory not found: a symbolic link to "
                                         r".*nowhere\.log, which does not exist"):
        open_sequence(root)  # (was: "no .log trajectory: frames have no poses", then "the frames have no poses")
    (root / "trajectory.log").unlink()
    (root / "trajectory.log").mkdir()
    with pytest.raises(InputError, match=r"trajectory\.log: is a folder, expected a file \(Redwood trajectory\)"):
        open_sequence(root)


def test_a_redwood_intrinsic_json_that_is_a_pipe_is_named(tmp_path):
    # taken for absent before: the default intrinsics, refused as for 640 x 480 frames only
    root = write_redwood(tmp_path / "rw")
    (root / "camera_intrinsic.json").unlink()
    os.mkfifo(root / "camera_intrinsic.json")
    result = open_in_subprocess(root, camera=False)
    assert result.stderr.strip().splitlines()[-1] == (f"{root / 'camera_intrinsic.json'}: not a regular file, "
                                                      "expected a file (Open3D camera intrinsic JSON)")


# ----------------------------------------------------------------------------- S14: the TUM lists

TUM_WHAT = {"rgb.txt": "TUM colour image list", "depth.txt": "TUM depth image list",
            "groundtruth.txt": "TUM ground truth"}


@pytest.mark.parametrize("name", list(TUM_WHAT))
def test_a_tum_list_that_is_a_pipe_is_named_not_taken_for_absent(name, tmp_path):
    # S14: rgb.txt a pipe: "unknown sequence format"; depth.txt: "frame ... has no depth image"; groundtruth.txt:
    # "the frames have no poses"
    root = tmp_path / "tum"
    write_tum(root)
    (root / name).unlink()
    os.mkfifo(root / name)
    result = open_in_subprocess(root)
    assert result.stderr.strip().splitlines()[-1] == f"{root / name}: not a regular file, expected a file " \
                                                     f"({TUM_WHAT[name]})"


def test_a_tum_list_that_is_a_link_to_dev_zero_is_named_not_read(tmp_path):
    # S14 k5: groundtruth.txt -> /dev/zero: "the frames have no poses" (read, it would fill the memory)
    root = tmp_path / "tum"
    write_tum(root)
    (root / "groundtruth.txt").unlink()
    (root / "groundtruth.txt").symlink_to("/dev/zero")
    out = tmp_path / "out"
    result = sequence_cli("--input", str(root), "--intrinsics", "52.5,52.5,31.95,23.95", "--no-video",
                          "--out", str(out))
    assert result.returncode == 2, result.stderr
    assert result.stderr.strip().splitlines() == [f"frontiernet sequence: error: {root / 'groundtruth.txt'}: not a "
                                                  "regular file, expected a file (TUM ground truth)"]
    assert not out.exists()


@pytest.mark.parametrize("name", list(TUM_WHAT))
def test_a_tum_list_that_is_a_dangling_link_is_named(name, tmp_path):
    root = tmp_path / "tum"
    write_tum(root)
    (root / name).unlink()
    (root / name).symlink_to(tmp_path / "gone.txt")
    with pytest.raises(InputError, match=rf"{name}: {TUM_WHAT[name]} not found: a symbolic link to .*gone\.txt, "
                                         "which does not exist"):
        open_sequence(root, camera=CAMERA)


def test_a_tum_sequence_without_its_optional_lists_still_reads(tmp_path):
    # absent (no name at all) stays absent: noted, not refused
    root = tmp_path / "tum"
    write_tum(root)
    (root / "groundtruth.txt").unlink()
    (root / "depth.txt").unlink()
    assert detect_format(root) == "tum"
    sequence = open_sequence(root, camera=CAMERA)
    assert len(sequence) == 5 and not sequence.has_poses and not sequence.has_depth
    assert "no depth.txt: frames have no depth" in sequence.notes


# ----------------------------------------------------------------------------- S7: the outputs, before the frames

def test_a_folder_where_the_video_goes_is_refused_before_the_work(tmp_path, one_line_error):
    # S7: internal error (IsADirectoryError) when the video was put in place, after the run; its scratch left
    root = write_redwood(tmp_path / "rw")
    out = tmp_path / "out"
    (out / "overlay.mp4").mkdir(parents=True)
    (out / "notes.txt").write_text("mine")
    before = folder_files(out)
    assert main(["sequence", "--input", str(root), "--out", str(out)]) == 2
    assert one_line_error().endswith(f"{out / 'overlay.mp4'}: a folder is where the run writes its overlay.mp4; "
                                     "remove it, or choose another --out")
    assert folder_files(out) == before and sorted(path.name for path in out.iterdir()) == ["notes.txt", "overlay.mp4"]


@pytest.mark.parametrize("kind", ["file", "pipe", "link"])
def test_a_file_where_the_rosbag2_folder_goes_is_refused_before_the_work(kind, tmp_path, one_line_error):
    # S7: internal error (NotADirectoryError) when the folder was renamed into place, its .rosbag2.partial left
    root = write_redwood(tmp_path / "rw")
    out = tmp_path / "out"
    out.mkdir()
    if kind == "file":
        (out / "rosbag2").write_text("mine")
    elif kind == "pipe":
        os.mkfifo(out / "rosbag2")
    else:
        (tmp_path / "elsewhere").mkdir()
        (out / "rosbag2").symlink_to(tmp_path / "elsewhere")
    before = folder_files(out)
    assert main(["sequence", "--input", str(root), "--no-video", "--rosbag2", "--out", str(out)]) == 2
    words = {"file": "a file", "pipe": "not a regular file nor a folder (a device or a pipe?)",
             "link": "a symbolic link"}[kind]
    assert one_line_error().endswith(f"{out / 'rosbag2'}: is {words}, expected the rosbag2 folder the run writes "
                                     "(--rosbag2); remove it, or choose another --out")
    assert folder_files(out) == before and sorted(path.name for path in out.iterdir()) == ["rosbag2"]


def test_every_output_of_a_run_is_checked_and_only_those_it_writes(tmp_path):
    for name in ("frontiers.json", "poses.json", "map.ply", "frontiers.ply", "occupancy.npz", "summary.json",
                 "overlay.mp4", ".overlay.mp4.partial.mp4", "frontiers.mcap", ".frontiers.mcap.partial"):
        out = tmp_path / name.strip(".")
        (out / name).mkdir(parents=True)
        with pytest.raises(InputError, match=f"{name}: a folder is where the run writes its {name}"):
            check_run_outputs(out, rosbag2=True)
    check_run_outputs(tmp_path / "overlay.mp4", video=False)  # --no-video: no video written, none checked
    check_run_outputs(tmp_path / "frontiers.mcap", mcap=False)
    (tmp_path / "folder").mkdir()
    (tmp_path / "folder" / ".rosbag2.partial").write_text("")
    check_run_outputs(tmp_path / "folder")  # no --rosbag2
    with pytest.raises(InputError, match=r"\.rosbag2\.partial: is a file, expected the rosbag2 folder"):
        check_run_outputs(tmp_path / "folder", rosbag2=True)
    (tmp_path / "fine" / "rosbag2").mkdir(parents=True)  # an earlier run's folder: replaced, as before
    (tmp_path / "fine" / ".rosbag2.partial").mkdir()  # an interrupted run's scratch: removed, as before
    check_run_outputs(tmp_path / "fine", rosbag2=True)
    check_run_outputs(tmp_path / "not yet made", rosbag2=True)


# ----------------------------------------------------------------------------- S9: depth of 3e38 m

def a_depth(tmp_path: Path, values: dict, name: str = "depth.npy") -> Path:
    depth = np.full((16, 16), 2.0, np.float32)
    for (row, column), value in values.items():
        depth[row, column] = value
    np.save(tmp_path / name, depth)
    return tmp_path / name


def test_a_float_depth_of_3e38_m_is_refused_in_one_line_naming_the_value(tmp_path, recwarn):
    # S9: numpy's overflow warning (the float32 median of two 3e38 values), then "median depth inf m"
    path = tmp_path / "huge.npy"
    np.save(path, np.full((16, 16), 3e38, np.float32))
    with pytest.raises(InputError, match=r"huge\.npy: median depth 3e\+38 m is implausible"):
        read_depth(path)
    with pytest.raises(InputError, match=r"far\.npy: depth has 2 pixel\(s\) beyond 100 m \(the farthest 3e\+38 m\), "
                                         "which no indoor camera sees; mark invalid pixels with 0 or NaN"):
        read_depth(a_depth(tmp_path, {(0, 0): 3e38, (1, 1): 150.0}, "far.npy"))
    assert not [warning for warning in recwarn if issubclass(warning.category, RuntimeWarning)]


def test_invalid_depth_pixels_stay_invalid_and_100_m_is_read(tmp_path):
    # NaN, 0 and negative pixels are no reading (0), as before; a pixel at the bound is one
    depth = read_depth(a_depth(tmp_path, {(0, 0): np.nan, (0, 1): 0.0, (0, 2): -1.0, (0, 3): 100.0}))
    assert depth[0, :4].tolist() == [0.0, 0.0, 0.0, 100.0] and depth[1:].min() == 2.0


def test_predict_with_a_depth_of_3e38_m_is_one_line_exit_2(tmp_path):
    # S9 through the command (l6): 3 lines before, a warning and "inf"
    write_image(tmp_path / "rgb.png", 64, 48)
    np.save(tmp_path / "huge.npy", np.full((48, 64), 3e38, np.float32))
    out = tmp_path / "out"
    result = python_in_subprocess("import sys; from frontiernet.cli.main import main; "
                           f"sys.argv = ['frontiernet', 'predict', '--image', {str(tmp_path / 'rgb.png')!r}, "
                           f"'--depth', {str(tmp_path / 'huge.npy')!r}, '--out', {str(out)!r}]; sys.exit(main())")
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "huge.npy: median depth 3e+38 m is implausible" in lines[0], lines
    assert not out.exists()


def test_a_depth_just_past_the_bound_is_shown_past_it(tmp_path):
    # probe 13 T11: "beyond 100 m (the farthest 100 m)" for a pixel at 100.0015 m
    depth = np.full((4, 4), 2.0, np.float32)
    depth[0, 0] = 100.0015
    np.save(tmp_path / "d.npy", depth)
    with pytest.raises(InputError, match=r"beyond 100 m \(the farthest 100\.001\d* m\)"):
        read_depth(tmp_path / "d.npy")


def test_a_principal_point_is_judged_alike_before_and_after_the_work():
    # probe 13 T4: --intrinsics with cx on the image's edge (-0.5) passed check_intrinsics_fit, then
    # pinhole_intrinsics (pixel centres 0 .. W - 1) refused it after predict had written its outputs
    from frontiernet.geometry import check_intrinsics_fit, pinhole_intrinsics

    for cx, cy in ((-0.5, 23.5), (63.5, 20.0), (10.0, 47.2)):
        with pytest.raises(InputError, match="--intrinsics: the principal point"):
            check_intrinsics_fit(50.0, 50.0, cx, cy, 64, 48)
        with pytest.raises(InputError, match="principal point"):
            pinhole_intrinsics([[50.0, 0, cx], [0, 50.0, cy], [0, 0, 1]], (48, 64))
    for cx, cy in ((0.0, 47.0), (63.0, 0.0)):
        check_intrinsics_fit(50.0, 50.0, cx, cy, 64, 48)
        assert pinhole_intrinsics([[50.0, 0, cx], [0, 50.0, cy], [0, 0, 1]], (48, 64))[0, 2] == cx

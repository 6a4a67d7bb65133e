"""Bad input of the thirteenth probe of issue 55 (docs/bad_input.md, "Probe 13") for ``frontiernet sequence``'s
recordings and COLMAP models: a rosbag2 folder whose ``.db3`` or ``.mcap`` is a pipe blocked for ever (T2); a pipe,
a folder or a link to nothing where a recording's or a COLMAP model's file or folder goes was taken for absent
(T7-T10: "unknown sequence format", "no COLMAP model", "not found", "no image folder", "has no depth image"); a file
of a recording or of a COLMAP model given as --input was "a file; a sequence is a folder" or "expected a folder"
(T12). Each refusal one line naming the path and what it is, exit code 2, no output folder made, nothing written
before lost. What blocked (or would block, were the check gone) on a pipe runs in a subprocess with a timeout, so
that a regression fails instead of hanging."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from conftest import folder_files, python_in_subprocess

from frontiernet.cli.main import main
from test_rosbag import recording, synthetic_frames
from test_sequence_readers import SIZE, write_colmap_project

ERROR = "frontiernet sequence: error: "


def sequence_cli(*args) -> tuple[int, list[str]]:
    """(exit code, stderr lines) of ``frontiernet sequence ARGS`` in a subprocess (a read of a pipe would wait for
    ever; :func:`~conftest.python_in_subprocess` fails the test past its timeout)."""
    words = [str(arg) for arg in args]
    result = python_in_subprocess("import sys; from frontiernet.cli.main import main; "
                                  f"sys.argv = ['frontiernet', 'sequence', *{words!r}]; sys.exit(main())", timeout=120)
    return result.returncode, result.stderr.strip().splitlines()


def refused_in_subprocess(source: Path, out: Path, line: str, *extra) -> None:
    """``sequence --input source`` in a subprocess: exit 2, `line` alone on stderr, `out` not made."""
    code, lines = sequence_cli("--input", source, "--no-video", "--out", out, *extra)
    assert (code, lines) == (2, [ERROR + line])
    assert not out.exists()


def refused(source: Path, out: Path, line: str, one_line_error, *extra) -> None:
    """``sequence --input source`` in this process (what never reads a pipe): exit 2, `line`, `out` not made."""
    assert main(["sequence", "--input", str(source), "--no-video", "--out", str(out), *map(str, extra)]) == 2
    assert one_line_error() == ERROR + line
    assert not out.exists()


def refused_as(kind: str, source: Path, out: Path, line: str, one_line_error, *extra) -> None:
    """:func:`refused_in_subprocess` for a `kind` ``pipe``, else :func:`refused` (quicker)."""
    if kind == "pipe":
        refused_in_subprocess(source, out, line, *extra)
    else:
        refused(source, out, line, one_line_error, *extra)


def make(path: Path, kind: str, target: Path | None = None) -> Path:
    """Put a `kind` where `path` was (removed first): ``pipe``, ``folder`` or ``dangling`` (a link to nothing)."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif os.path.lexists(path):
        path.unlink()
    if kind == "pipe":
        os.mkfifo(path)
    elif kind == "folder":
        path.mkdir()
    else:
        path.symlink_to(target or path.parent / "nowhere")
    return path


@pytest.fixture(scope="module")
def bags(tmp_path_factory) -> dict[str, Path]:
    """Pristine recordings, copied per test: a rosbag2 folder of each storage and a plain .mcap file."""
    frames, K = synthetic_frames(count=2)
    bag, folder = recording(frames, K), tmp_path_factory.mktemp("bags")
    return {kind: bag.write(folder / kind, kind) for kind in ("sqlite3", "mcap", "plain_mcap")}


def copy_bag(bags: dict, kind: str, tmp_path: Path) -> Path:
    source = bags[kind]
    target = tmp_path / source.name
    (shutil.copytree if source.is_dir() else shutil.copy)(source, target)
    return target


def storage_file(folder: Path) -> Path:
    return next(path for path in folder.iterdir() if path.suffix in (".db3", ".mcap"))


# ----------------------------------------------------------------------------- T2: a storage file that is a pipe

@pytest.mark.parametrize("kind", ["sqlite3", "mcap"])
def test_a_rosbag2_storage_file_that_is_a_pipe_is_named_not_waited_on(kind, bags, tmp_path):
    # T2: sequence --input <rosbag2 folder> blocked for ever (sqlite's open of the .db3: SIGTERM unanswered too)
    folder = copy_bag(bags, kind, tmp_path)
    file = make(storage_file(folder), "pipe")
    refused_in_subprocess(folder, tmp_path / "out", f"{file}: not a regular file, expected a file (rosbag2 storage "
                                                    "file)")


def test_a_pipe_in_a_recording_leaves_an_earlier_runs_files_as_they_were(bags, tmp_path):
    folder = copy_bag(bags, "sqlite3", tmp_path)
    file = make(storage_file(folder), "pipe")
    out = tmp_path / "out"
    (out / "cache").mkdir(parents=True)
    (out / "notes.txt").write_text("mine")
    (out / "cache" / "frame.npz").write_bytes(b"earlier")
    before = folder_files(out)
    code, lines = sequence_cli("--input", folder, "--no-video", "--format", "rosbag", "--out", out)
    assert (code, lines) == (2, [f"{ERROR}{file}: not a regular file, expected a file (rosbag2 storage file)"])
    assert folder_files(out) == before


@pytest.mark.parametrize("suffix", [".mcap", ".bag"])
def test_a_recording_file_that_is_a_pipe_is_named_as_a_recording(suffix, tmp_path):
    # T12: "x.bag: is not a regular file nor a folder (a device or a pipe?), expected a folder (sequence)"
    pipe = make(tmp_path / f"x{suffix}", "pipe")
    refused_in_subprocess(pipe, tmp_path / "out", f"{pipe}: not a regular file, expected a file (recording)")


# ----------------------------------------------------------------------------- T7-T10: a recording's files

@pytest.mark.parametrize("kind", ["folder", "dangling"])
@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_a_rosbag2_storage_file_of_the_wrong_kind_is_named_not_missing(storage, kind, bags, tmp_path,
                                                                       one_line_error):
    # was "not a readable recording, truncated or corrupt (AnyReaderError: Some database files are missing: ...)"
    # for a link to nothing, "... Cannot open database ...: disk I/O error" or "... Is a directory." for a folder
    folder = copy_bag(bags, storage, tmp_path)
    file = make(storage_file(folder), kind, tmp_path / "gone.db3")
    line = (f"{file}: is a folder, expected a file (rosbag2 storage file)" if kind == "folder" else
            f"{file}: rosbag2 storage file not found: a symbolic link to {tmp_path / 'gone.db3'}, which does not exist")
    refused(folder, tmp_path / "out", line, one_line_error)


@pytest.mark.parametrize("kind", ["pipe", "folder", "dangling"])
def test_a_rosbag2_metadata_of_the_wrong_kind_is_named_not_taken_for_absent(kind, bags, tmp_path, one_line_error):
    # was "<folder>: unknown sequence format; looked for rgb.txt (tum), ... metadata.yaml (a rosbag2 recording)"
    folder = copy_bag(bags, "mcap", tmp_path)
    metadata = make(folder / "metadata.yaml", kind, tmp_path / "gone.yaml")
    line = {"pipe": f"{metadata}: not a regular file, expected a file (rosbag2 metadata)",
            "folder": f"{metadata}: is a folder, expected a file (rosbag2 metadata)",
            "dangling": f"{metadata}: rosbag2 metadata not found: a symbolic link to {tmp_path / 'gone.yaml'}, "
                        "which does not exist"}[kind]
    refused_as(kind, folder, tmp_path / "out", line, one_line_error)


def test_a_recording_file_that_is_a_link_to_nothing_is_named_so(tmp_path, one_line_error):
    # was "d.bag: sequence folder not found: a symbolic link to ..."
    link = make(tmp_path / "d.bag", "dangling", tmp_path / "gone.bag")
    refused(link, tmp_path / "out", f"{link}: recording not found: a symbolic link to {tmp_path / 'gone.bag'}, which "
                                    "does not exist", one_line_error)


# ----------------------------------------------------------------------------- T12: a file of a recording or model

def test_the_metadata_of_a_rosbag2_recording_as_input_names_its_folder(bags, tmp_path, one_line_error):
    # T12: "metadata.yaml: a file; a sequence is a folder, or a recording (.bag, .mcap, .db3)"
    folder = copy_bag(bags, "sqlite3", tmp_path)
    expected = (f"{folder / 'metadata.yaml'}: a file of the rosbag2 recording {folder}; a rosbag2 recording is the "
                f"folder holding metadata.yaml and its .db3 or .mcap files: give {folder}")
    refused(folder / "metadata.yaml", tmp_path / "out", expected, one_line_error)
    refused(folder / "metadata.yaml", tmp_path / "out", expected, one_line_error, "--format", "rosbag")


def test_a_recording_file_given_a_folder_format_says_to_read_it_as_a_recording(bags, tmp_path, one_line_error):
    # T12: "x.mcap: is a file, expected a folder (TUM sequence)"
    plain = copy_bag(bags, "plain_mcap", tmp_path)
    refused(plain, tmp_path / "out", f"{plain}: a recording (.mcap file), not a TUM sequence folder; read it with "
                                     "--format rosbag (or auto)", one_line_error, "--format", "tum")


@pytest.fixture
def project(tmp_path) -> Path:
    write_colmap_project(tmp_path / "project")
    return tmp_path / "project"


@pytest.mark.parametrize("format", ["auto", "colmap"])
def test_a_colmap_model_file_as_input_names_the_model_folder(format, project, tmp_path, one_line_error):
    # T12: auto "cameras.bin: a file; a sequence is a folder, ..."; colmap "is a file, expected a folder (COLMAP model)"
    model = project / "sparse" / "0"
    given = "" if format == "auto" else ", not a COLMAP model folder"
    refused(model / "cameras.bin", tmp_path / "out", f"{model / 'cameras.bin'}: a file of a COLMAP model{given}; a "
            f"COLMAP model is the folder holding cameras, images and points3D (.bin or .txt): give {model} (or its "
            "project folder)", one_line_error, "--format", format)


# ----------------------------------------------------------------------------- T7-T10: a COLMAP model's files

@pytest.mark.parametrize("name", ["cameras.bin", "images.bin", "points3D.bin"])
def test_a_colmap_model_file_that_is_a_pipe_is_named(name, project, tmp_path):
    # cameras.bin: "unknown sequence format" (no model found); images.bin, points3D.bin: pycolmap waited on the pipe
    file = make(project / "sparse" / "0" / name, "pipe")
    refused_in_subprocess(project, tmp_path / "out", f"{file}: not a regular file, expected a file (COLMAP model "
                                                     "file)")


@pytest.mark.parametrize("kind", ["folder", "dangling"])
def test_a_colmap_cameras_file_of_the_wrong_kind_is_named_not_missing(kind, project, tmp_path, one_line_error):
    # was "project: no COLMAP model (looked for cameras.bin or cameras.txt in ., sparse/0, sparse)"
    file = make(project / "sparse" / "0" / "cameras.bin", kind, tmp_path / "gone.bin")
    line = (f"{file}: is a folder, expected a file (COLMAP model file)" if kind == "folder" else
            f"{file}: COLMAP model file not found: a symbolic link to {tmp_path / 'gone.bin'}, which does not exist")
    refused(project, tmp_path / "out", line, one_line_error, "--format", "colmap")


@pytest.mark.parametrize("kind", ["file", "pipe", "dangling"])
def test_a_colmap_image_folder_of_the_wrong_kind_is_named(kind, project, tmp_path, one_line_error):
    # was "project: no image folder for the COLMAP model (looked for ...); pass image_dir"
    images = project / "images"
    if kind == "file":
        shutil.rmtree(images)
        images.write_text("not a folder")
    else:
        make(images, kind, tmp_path / "gone")
    line = {"file": f"{images}: is a file, expected a folder (image)",
            "pipe": f"{images}: is not a regular file nor a folder (a device or a pipe?), expected a folder (image)",
            "dangling": f"{images}: image folder not found: a symbolic link to {tmp_path / 'gone'}, which does not "
                        "exist"}[kind]
    refused_as(kind, project, tmp_path / "out", line, one_line_error)


@pytest.mark.parametrize("kind", ["pipe", "folder", "dangling"])
def test_a_colmap_image_of_the_wrong_kind_is_named_not_missing(kind, project, tmp_path, one_line_error):
    # was "b.png: image of the COLMAP model not found (1 of 3 registered images missing in ...)"
    image = make(project / "images" / "b.png", kind, tmp_path / "gone.png")
    line = {"pipe": f"{image}: not a regular file, expected a file (image of the COLMAP model)",
            "folder": f"{image}: is a folder, expected a file (image of the COLMAP model)",
            "dangling": f"{image}: image of the COLMAP model not found: a symbolic link to {tmp_path / 'gone.png'}, "
                        "which does not exist"}[kind]
    refused_as(kind, project, tmp_path / "out", line, one_line_error)


@pytest.mark.parametrize("kind", ["file", "pipe", "dangling"])
def test_a_colmap_depth_folder_of_the_wrong_kind_is_named_not_taken_for_none(kind, project, tmp_path, one_line_error):
    # was "project: frame a.png has no depth image; give the sequence a depth/ folder beside images/ ..."
    depth = project / "depth"
    if kind == "file":
        depth.write_text("not a folder")
    else:
        make(depth, kind, tmp_path / "gone")
    line = {"file": f"{depth}: is a file, expected a folder (COLMAP depth)",
            "pipe": f"{depth}: is not a regular file nor a folder (a device or a pipe?), expected a folder (COLMAP "
                    "depth)",
            "dangling": f"{depth}: COLMAP depth folder not found: a symbolic link to {tmp_path / 'gone'}, which does "
                        "not exist"}[kind]
    refused_as(kind, project, tmp_path / "out", line, one_line_error)


@pytest.mark.parametrize("kind", ["pipe", "dangling"])
def test_a_colmap_depth_file_of_the_wrong_kind_is_named_not_missing(kind, project, tmp_path, one_line_error):
    # was "a.png: depth file not found (nor .npy; 1 of 3 images have no depth in ...)"
    (project / "depth").mkdir()
    for name in ("a", "b", "c"):
        cv2.imwrite(str(project / "depth" / f"{name}.png"), np.full(SIZE[::-1], 2000, np.uint16))
    file = make(project / "depth" / "a.png", kind, tmp_path / "gone.png")
    line = (f"{file}: not a regular file, expected a file (depth file)" if kind == "pipe" else
            f"{file}: depth file not found: a symbolic link to {tmp_path / 'gone.png'}, which does not exist")
    refused_as(kind, project, tmp_path / "out", line, one_line_error)

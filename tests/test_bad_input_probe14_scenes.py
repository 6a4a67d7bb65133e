"""Bad input of the fourteenth probe of issue 55 (docs/bad_input.md, "Probe 14") for scenes, their files and the
images read through OpenCV: a subnormal ``scene topdown --pixel-size`` overflowed to an internal error (P1); a cut-off
PNG printed libpng's own "libpng error: Read Error" line beside ours (P3); a corrupt mesh file's refusal quoted
Python exception names (P13); a pipe, a folder or a link loop where an HM3D scene's .glb, a KTH plan's occ_map.npy or
its start_poses.json goes was taken for absent (P15); an output link of a loop was "a link to X, which does not
exist" (P16); shipped starts outside every room of their KTH plan were "shut in by doors too narrow" and silently
replaced by sampled ones (P18). Each refusal one line on stderr naming the file or value, exit code 2, no output
left. What would wait on a pipe, were the check gone, runs in a subprocess with a timeout."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from conftest import python_in_subprocess

from frontiernet.cli.main import main
from frontiernet.errors import InputError
from test_benchmark import kth_folder

EXCEPTION_NAME = re.compile(r"\b[A-Z]\w*(Error|Exception)\b")


def stderr_line(capfd) -> str:
    """What a command wrote to file descriptor 2 (libpng writes there, past Python's sys.stderr): one line, no
    traceback, no Python exception name."""
    err = capfd.readouterr().err.strip()
    assert err and "\n" not in err and "Traceback" not in err, err
    assert not EXCEPTION_NAME.search(err.split("error: ", 1)[-1]), err
    return err


def cli_in_subprocess(*args) -> tuple[int, list[str]]:
    """(exit code, stderr lines) of ``frontiernet ARGS`` in its own process (a read of a pipe would wait for ever)."""
    words = [str(arg) for arg in args]
    result = python_in_subprocess("import sys; from frontiernet.cli.main import main; "
                                  f"sys.argv = ['frontiernet', *{words!r}]; sys.exit(main())", timeout=180)
    return result.returncode, result.stderr.strip().splitlines()


@pytest.fixture(scope="module")
def box_glb(tmp_path_factory) -> Path:
    """A 6 x 4 x 3 m box as a .glb."""
    import trimesh

    path = tmp_path_factory.mktemp("box") / "box.glb"
    trimesh.creation.box(extents=(6.0, 4.0, 3.0)).export(path)
    return path


@pytest.fixture(scope="module")
def png(tmp_path_factory) -> bytes:
    """The bytes of a 160 x 120 colour PNG of noise: several IDAT chunks (OpenCV's own chunk reader refuses a cut in
    the first one without a word; libpng, reading the later ones, prints its own line)."""
    image = np.random.default_rng(0).integers(0, 255, (120, 160, 3), np.uint8)
    return cv2.imencode(".png", image)[1].tobytes()


# P1 ------------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("pixel_size, across", [("1e-320", "e+320"), ("1e-300", "e+300")])
def test_a_subnormal_or_tiny_pixel_size_is_one_line_naming_it_and_the_image_size(box_glb, tmp_path, capfd,
                                                                               pixel_size, across):
    # P1: 1e-320 gave two RuntimeWarning lines and an internal error (OverflowError); 1e-300 a 600-digit count
    out = tmp_path / "sub" / "t.png"
    assert main(["scene", "topdown", str(box_glb), "--out", str(out), "--pixel-size", pixel_size,
                 "--no-explorable"]) == 2
    line = stderr_line(capfd)
    assert re.search(rf"at {pixel_size} m per pixel \(--pixel-size\) would be [\d.]+{re.escape(across)} x "
                     rf"[\d.]+{re.escape(across)} px, more than the 25,000,000 drawn at most \(5,000 x 5,000\); "
                     r"give a larger pixel size, at least 0\.\d+ m$", line), line
    assert len(line) < 400
    assert not (tmp_path / "sub").exists()


def test_the_smallest_pixel_size_a_refusal_names_is_taken(box_glb):
    from frontiernet.scenes import load_scene
    from frontiernet.simulator.preview import check_view_size
    from conftest import scenes_config

    scene = load_scene(str(box_glb), scenes_config())
    with pytest.raises(InputError, match="at least") as refused:
        check_view_size(scene, 1e-4)
    smallest = float(re.search(r"at least ([\d.]+) m", str(refused.value)).group(1))
    check_view_size(scene, smallest)  # taken
    with pytest.raises(InputError):
        check_view_size(scene, smallest * 0.99)


# P3 ------------------------------------------------------------------------------------------------------------

def test_a_cut_off_png_floor_plan_is_one_line_without_libpng_s_own(tmp_path, capfd, png):
    # P3: "libpng error: Read Error" came before "...: not a readable floor-plan image"
    plan = cv2.imencode(".png", np.full((40, 40), 254, np.uint8))[1].tobytes()
    (tmp_path / "plan.png").write_bytes(plan[:len(plan) // 2])
    assert main(["scene", "info", f"floorplan:{tmp_path / 'plan.png'}?resolution=0.05"]) == 2
    line = stderr_line(capfd)
    assert line.endswith("plan.png: a truncated PNG (the file ends inside its IDAT chunk) (floor-plan image)"), line


@pytest.mark.parametrize("cut", ["half", "no_iend", "signature"])
def test_a_cut_off_png_image_is_refused_before_libpng_reads_it(tmp_path, capfd, png, cut):
    from frontiernet.sequences.images import read_rgb

    data = {"half": png[:len(png) // 2], "no_iend": png[:-12], "signature": png[:8]}[cut]
    (tmp_path / "rgb.png").write_bytes(data)
    where = {"half": "inside its IDAT chunk", "no_iend": "before its closing IEND chunk",
             "signature": "before its first chunk"}[cut]
    with pytest.raises(InputError, match=re.escape(f"rgb.png: a truncated PNG (the file ends {where}) (image)")):
        read_rgb(tmp_path / "rgb.png")
    assert capfd.readouterr().err == ""


def test_libpng_s_own_reason_for_a_damaged_png_goes_into_our_message_not_beside_it(tmp_path, capfd, png):
    from frontiernet.array_files import read_image

    damaged = bytearray(png)
    damaged[60:90] = bytes(30)  # inside the IDAT chunk: its checksum no longer matches
    (tmp_path / "crc.png").write_bytes(bytes(damaged))
    with pytest.raises(InputError, match=r"crc\.png: not a readable image \(libpng: .+\)$"):
        read_image(tmp_path / "crc.png", cv2.IMREAD_COLOR)
    assert capfd.readouterr().err == ""
    (tmp_path / "good.png").write_bytes(png)
    assert read_image(tmp_path / "good.png", cv2.IMREAD_COLOR).shape == (120, 160, 3)


def test_a_cut_off_png_in_a_shard_is_refused_without_libpng_s_line(capfd, png):
    from datagen.dataset import _decode_sample

    with pytest.raises(ValueError, match=r"000000/rgb\.png does not decode to a \(120, 160, 3\) uint8 image"):
        _decode_sample(lambda name: png[:len(png) // 2], {"height": 120, "width": 160, "rgb_format": "png"}, "000000")
    assert capfd.readouterr().err == ""


def test_what_others_write_to_stderr_meanwhile_is_kept(capfd):
    from frontiernet.array_files import native_stderr

    with native_stderr() as caught:
        os.write(2, b"libpng error: Read Error\nanother thread's line\n")
    assert caught.lines == ["libpng error: Read Error"]
    assert capfd.readouterr().err == "another thread's line\n"


# P13 -----------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name, build, words", [
    ("trunc.glb", "glb_half", r"a corrupt or truncated \.glb file \(its header says the file has [\d,]+ bytes, it "
                              r"holds [\d,]+: the end is cut off\)"),
    ("short.glb", "glb_8", r"a corrupt or truncated \.glb file \(8 bytes, fewer than the 12 of a \.glb header\)"),
    ("other.glb", "zip", r"a corrupt or truncated \.glb file \(its first bytes are not the 'glTF' a \.glb file starts "
                         r"with: another format named \.glb\?\)"),
    ("badidx.obj", "v 0 0 0\nv 1 0 0\nf 1 2 3\n", r"a corrupt or truncated \.obj file \(a face names a vertex the "
                                                  r"file does not have; trimesh: index 2 is out of bounds"),
    ("bad.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n0\n",
     r"a corrupt or truncated \.ply file \(a property or element the data needs is not declared: 'y'\)"),
])
def test_a_corrupt_mesh_file_is_said_in_words_not_exception_names(tmp_path, box_glb, capfd, name, build, words):
    # P13: "(trimesh: JSONDecodeError: Expecting ',' delimiter ...)", "(trimesh: IndexError: ...)", "(... KeyError: 'y')"
    whole = box_glb.read_bytes()
    data = {"glb_half": whole[:len(whole) // 2], "glb_8": whole[:8], "zip": b"PK\x03\x04" + bytes(40)}.get(build)
    (tmp_path / name).write_bytes(data if data is not None else build.encode())
    assert main(["scene", "info", str(tmp_path / name)]) == 2
    line = stderr_line(capfd)
    assert re.search(rf"{re.escape(name)}: cannot read mesh: {words}", line), line


# P15 -----------------------------------------------------------------------------------------------------------

def make(path: Path, kind: str) -> Path:
    """Something other than a regular file named `path`: a ``folder``, a ``pipe`` or a ``loop`` (path -> x -> path)."""
    if kind == "folder":
        path.mkdir()
    elif kind == "pipe":
        os.mkfifo(path)
    else:
        os.symlink(path.name, path.with_name("x" + path.suffix))
        os.symlink("x" + path.suffix, path)
    return path


def what_it_is(path: Path, kind: str, what: str) -> str:
    return {"folder": f"{path}: is a folder, expected a file ({what})",
            "pipe": f"{path}: not a regular file, expected a file ({what})",
            "loop": f"{path}: {what} not found: a symbolic link loop ({path} -> x{path.suffix} -> {path.name}), which "
                    "leads back to itself"}[kind]


@pytest.mark.parametrize("kind", ["folder", "loop", "pipe"])
def test_an_hm3d_scene_s_glb_of_the_wrong_kind_is_named_so(tmp_path, capfd, kind):
    # P15: "hm3/00003-q: HM3D scene folder holds no .glb file" for a q.glb that is a pipe, a folder or a link loop
    scene = tmp_path / "00003-q"
    scene.mkdir()
    glb = make(scene / "q.glb", kind)
    line = what_it_is(glb, kind, "HM3D scene mesh")
    if kind == "pipe":
        assert cli_in_subprocess("scene", "info", f"hm3d:{scene}") == (2, ["frontiernet scene: error: " + line])
    else:
        assert main(["scene", "info", f"hm3d:{scene}"]) == 2
        assert stderr_line(capfd) == "frontiernet scene: error: " + line


def test_an_hm3d_folder_whose_only_glb_is_a_folder_names_it(tmp_path, capfd):
    scene = tmp_path / "00004-r"
    scene.mkdir()
    make(scene / "other.glb", "folder")
    assert main(["scene", "info", f"hm3d:{scene}"]) == 2
    assert stderr_line(capfd).endswith(f"{scene / 'other.glb'}: is a folder, expected a file (HM3D scene mesh)")


@pytest.mark.parametrize("kind", ["folder", "loop", "pipe"])
def test_a_kth_plan_s_occ_map_of_the_wrong_kind_is_named_so(tmp_path, capfd, kind):
    # P15: "kth4: floor-plan folder has no occ_map.npy" for an occ_map.npy that is a folder or a pipe
    plan = tmp_path / "plan"
    plan.mkdir()
    kth_folder(plan, [[30, 30]])
    (plan / "occ_map.npy").unlink()
    occ = make(plan / "occ_map.npy", kind)
    line = "frontiernet scene: error: " + what_it_is(occ, kind, "KTH plan occupancy grid")
    for spec in (f"floorplan:{plan}", str(plan)):  # (without floorplan: the folder is still taken for a plan)
        if kind == "pipe":
            assert cli_in_subprocess("scene", "info", spec) == (2, [line])
        else:
            assert main(["scene", "info", spec]) == 2
            assert stderr_line(capfd) == line


@pytest.mark.parametrize("kind", ["folder", "pipe"])
def test_a_kth_plan_s_start_poses_of_the_wrong_kind_is_named_so_by_bench(tmp_path, capfd, kind):
    # P15: "--scene-starts: none of the scenes ships start poses" for a start_poses.json that is a pipe
    plan = tmp_path / "plan"
    plan.mkdir()
    kth_folder(plan, [[30, 30]])
    (plan / "start_poses.json").unlink()
    starts = make(plan / "start_poses.json", kind)
    out = tmp_path / "b"
    args = ["bench", "--scenes", f"floorplan:{plan}", "--scene-starts", "--methods", "classic", "--starts", "1",
            "--max-steps", "4", "--out", str(out)]
    line = "frontiernet bench: error: " + what_it_is(starts, kind, "KTH plan start-pose file")
    if kind == "pipe":
        assert cli_in_subprocess(*args) == (2, [line])
    else:
        assert main(args) == 2
        assert stderr_line(capfd) == line
    assert not out.exists()


# P16 -----------------------------------------------------------------------------------------------------------

def test_an_output_link_of_a_loop_is_named_a_loop(tmp_path, capfd, box_glb):
    # P16: "loopa.png: a symbolic link to loopb.png, which does not exist; make its target first, ..."
    os.symlink("loopa.png", tmp_path / "loopb.png")
    os.symlink("loopb.png", tmp_path / "loopa.png")
    out = tmp_path / "loopa.png"
    assert main(["scene", "topdown", str(box_glb), "--out", str(out), "--force"]) == 2
    assert stderr_line(capfd) == (f"frontiernet scene: error: {out}: a symbolic link loop ({out} -> loopb.png -> "
                                  "loopa.png), which leads back to itself; remove a link of the loop, or choose "
                                  "another output")
    assert os.readlink(out) == "loopb.png" and os.readlink(tmp_path / "loopb.png") == "loopa.png"


# P18 -----------------------------------------------------------------------------------------------------------

def test_shipped_starts_outside_every_room_are_the_start_file_s_error(tmp_path, capfd):
    # P18: six "shut in by doors too narrow" warnings, then sampled starts and exit 0
    plan = tmp_path / "plan"
    plan.mkdir()
    spec = kth_folder(plan, [[0, 0], [30, 30], [5, 95]])  # (0, 0) and (5, 95): free, outside the building
    out = tmp_path / "b"
    assert main(["bench", "--scenes", spec, "--scene-starts", "--methods", "classic", "--starts", "1",
                 "--max-steps", "4", "--out", str(out)]) == 2
    assert stderr_line(capfd) == (
        f"frontiernet bench: error: {plan / 'start_poses.json'}: starts 0 (row 0, col 0), 2 (row 5, col 95) lie "
        "outside every space of valid_space.npy (0 there: outside the building, or a wall or door frame between "
        "spaces); a start must be a pixel of a room or corridor")
    assert not out.exists()


def test_shipped_starts_shut_in_are_left_out_in_one_warning(tmp_path, caplog):
    from frontiernet.benchmark.plan import start_poses
    from frontiernet.config import load_config

    spec = kth_folder(tmp_path, [[30, 75], [30, 80], [30, 30]], wall=60, door=(28, 33))  # room 2: a 0.25 m door
    with caplog.at_level("WARNING"):
        poses = start_poses(spec, 2, 0, load_config("explore"), scene_starts=True)
    warnings = [record.getMessage() for record in caplog.records if "shipped start" in record.getMessage()]
    assert len(warnings) == 1, warnings
    assert re.search(r"shipped starts 0 at \([\d.]+, [\d.]+\), 1 at \([\d.]+, [\d.]+\) lie outside the region the "
                     r"robot can travel: shut in by doors too narrow for it, or nearer a wall than "
                     r"planner\.clearance_m = [\d.]+ m; left out, sampled starts take their place", warnings[0])
    assert poses[0][:2] == pytest.approx(((30 + 0.5) * 0.05, (60 - 30 - 0.5) * 0.05), abs=1e-4)


def test_the_shared_kth_plans_start_poses_all_lie_in_their_rooms(shared_data):
    from frontiernet.scenes import load_scene
    from conftest import scenes_config

    for folder in sorted((shared_data / "floorplans" / "kth").iterdir()):
        if (folder / "start_poses.json").is_file() and json.loads((folder / "start_poses.json").read_text())[
                "start_poses"]:
            scene = load_scene(f"floorplan:{folder}", scenes_config())
            assert len(scene.metadata.extra["start_xy"]) == len(
                json.loads((folder / "start_poses.json").read_text())["start_poses"])

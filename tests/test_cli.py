"""The command line: outputs users rely on, and bad input as one line with exit code 2."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from frontiernet.cli.main import main
from frontiernet.errors import InputError
from frontiernet.geometry import parse_pose_text


def test_scene_info_reports_bounds_triangles_and_explorable_volume(plan_spec, capsys):
    assert main(["scene", "info", plan_spec]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["source"] == "floorplan"
    assert np.allclose(info["size_m"], [7.0, 4.0, 2.6], atol=1e-3)  # walls span cols 10-150, rows 10-90
    # two rooms of 3.05 x 3.4 m inside, 2.6 m high, less the voxels their surfaces touch
    rooms = 2 * 3.05 * 3.4 * 2.6
    assert 0.75 * rooms < info["explorable_volume_m3"] < 1.05 * rooms
    assert info["voxels_explorable"] * 0.001 == pytest.approx(info["explorable_volume_m3"], rel=1e-3)


def test_render_writes_rgb_depth_in_metres_and_camera(plan_spec, tmp_path, capsys):
    out = tmp_path / "view"
    assert main(["render", plan_spec, "--pose", "2.0,1.5,1.2,0deg", "--out", str(out)]) == 0
    depth = np.load(out / "depth.npy")
    assert depth.shape == (480, 480) and depth.dtype == np.float32
    # looking along +x from x = 2.0 at the middle wall, whose face is at x = 3.85 m
    assert depth[240, 240] == pytest.approx(3.85 - 2.0, abs=0.01)
    rgb = np.asarray(Image.open(out / "rgb.png"))
    assert rgb.shape == (480, 480, 3)
    camera = json.loads((out / "camera.json").read_text())
    assert np.allclose(np.array(camera["T_world_cam"])[:3, 3], [2.0, 1.5, 1.2])
    assert (out / "depth.png").is_file() and (out / "normals.png").is_file()


def test_a_render_of_no_surface_says_so(plan_spec, tmp_path, capsys):
    # eighth probe (E11): "valid depth 0%, range nan-nan m" for a view without depth (a 1 mm camera range)
    config = tmp_path / "near.yaml"
    config.write_text("camera: {width: 16, height: 16, focal_px: 10, max_depth: 0.001}\n")
    out = tmp_path / "view"
    assert main(["render", plan_spec, "--pose", "2.0,1.5,1.2,0", "--config", str(config), "--no-check",
                 "--out", str(out)]) == 0
    assert capsys.readouterr().out.strip() == (f"wrote {out}: valid depth 0%, no surface within the camera's "
                                               "max_depth of 0.001 m")


def test_poses_read_the_same_on_every_command():
    # render's --pose, explore's --start and the benchmark's start poses: degrees unless 'rad'
    assert parse_pose_text("1,2,1.2,90") == pytest.approx((1, 2, 1.2, np.pi / 2, 0.0))
    assert parse_pose_text("1,2,1.2,90deg,-10") == pytest.approx((1, 2, 1.2, np.pi / 2, np.radians(-10)))
    assert parse_pose_text("1,2,1.2,1.5rad, 0.1RAD") == pytest.approx((1, 2, 1.2, 1.5, 0.1))
    assert parse_pose_text("1,2,1.2,-45", "--start", pitch=False) == pytest.approx((1, 2, 1.2, -np.pi / 4))
    with pytest.raises(InputError, match="--start '1,2,1.2,0,5': expected x,y,z,yaw "):
        parse_pose_text("1,2,1.2,0,5", "--start", pitch=False)
    with pytest.raises(InputError, match="pitch must lie strictly between -90 and 90"):
        parse_pose_text("1,2,1.2,0,1.6rad")
    with pytest.raises(InputError, match="'2rad3' is not a number"):
        parse_pose_text("1,2,1.2,2rad3")


@pytest.mark.parametrize("args, message", [
    (["render", "{plan}", "--pose", "50,50,1.2,0", "--out", "{out}"], "outside"),
    (["render", "{plan}", "--pose", "0.6,2.5,1.2,0", "--out", "{out}"], "obstacle"),
    (["render", "{plan}", "--pose", "2,2.5,abc,0", "--out", "{out}"], "not a number"),
    (["render", "{plan}", "--pose", "2,2.5,1.2", "--out", "{out}"], "expected x,y,z,yaw"),
    # overflowed float32 rays: RuntimeWarnings and a view with no depth, exit 0 (the seventh probe's D8)
    (["render", "{plan}", "--pose", "1e300,2.5,1.2,0", "--no-check", "--out", "{out}"],
     "'1e300' m is farther from the world origin than any scene (1e+05 m at most"),
    (["scene", "info", "no/such/scene.glb"], "not found"),
    (["scene", "info", "floorplan:x.png?resolution=-1"], "resolution must be a number > 0 (or null), got -1"),
    (["scene", "topdown", "{plan}", "--out", "{out}/top.txt"], "top.txt: not an image file name"),
])
def test_bad_input_is_one_line_and_exit_code_2(plan_spec, tmp_path, capsys, args, message):
    args = [a.format(plan=plan_spec, out=tmp_path / "out") for a in args]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err and "Traceback" not in err
    assert not (tmp_path / "out" / "rgb.png").exists()


@pytest.mark.parametrize("args, message", [
    (["explore", "--scen", "x", "--out", "o"], "unrecognized option --scen (did you mean --scene?)"),
    (["datagen", "--scenes", "procedural:0", "--views", "3", "--out", "o"],
     "unrecognized option --views (did you mean --views-per-scene?)"),  # no abbreviation is read
    (["bench", "--scenes", "procedural:0", "--method=classic", "--out", "o"],
     "unrecognized option --method (did you mean --methods?)"),
    (["bench", "explore", "--scene", "procedural:0", "--nonsense", "1"], "unrecognized option --nonsense"),
])
def test_a_misspelt_or_abbreviated_option_is_named_with_what_was_meant(args, message, tmp_path, capsys,
                                                                       monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exit_info:
        main(args)
    err = capsys.readouterr().err.strip()
    assert exit_info.value.code == 2 and message in err and "\n" not in err
    assert not (tmp_path / "o").exists()


def test_the_installed_command_exits_2_without_traceback(tmp_path):
    result = subprocess.run([sys.executable, "-m", "frontiernet.cli.main", "render", str(tmp_path / "none.obj"),
                             "--pose", "0,0,1,0", "--out", str(tmp_path / "o")], capture_output=True, text=True)
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr
    assert "none.obj" in result.stderr


def test_outputs_are_written_atomically_with_normal_permissions(tmp_path):
    import os

    from frontiernet.io import atomic_path, write_json

    target = write_json(tmp_path / "a.json", {"x": 1})
    assert oct(target.stat().st_mode & 0o777) == oct(0o666 & ~_umask())
    with pytest.raises(RuntimeError), atomic_path(tmp_path / "a.json") as tmp:
        tmp.write_text("half")
        raise RuntimeError("the writer fails half-way")
    assert json.loads((tmp_path / "a.json").read_text()) == {"x": 1}  # the old file is intact
    assert os.listdir(tmp_path) == ["a.json"]  # no temporary left behind
    with pytest.raises(InputError, match="a.json/b.json: cannot write"):  # a file where a folder should be
        write_json(tmp_path / "a.json" / "b.json", {"x": 2})


def _umask() -> int:
    import os

    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_the_command_line_starts_without_loading_torch():
    # every command's parser (plugins' `datagen`, `train`, `deploy` and `bench inference` too)
    # is built on each start; torch and HDBSCAN imports there took seconds of `frontiernet --help`
    code = ("import json, sys; from frontiernet.cli.main import build_parser; parser = build_parser(); "
            "print(json.dumps({'heavy': [m for m in ('torch', 'hdbscan', 'open3d', 'sklearn') if m in sys.modules], "
            "'commands': sorted(parser._subparsers._group_actions[0].choices)}))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    started = json.loads(result.stdout)
    assert started["heavy"] == [], f"imported at start-up: {started['heavy']}"
    assert {"datagen", "train", "export", "bench", "explore"} <= set(started["commands"])

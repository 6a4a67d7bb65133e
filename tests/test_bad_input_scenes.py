"""Bad input to what builds and renders a scene, and to the paths outputs are written to: one line,
exit 2, nothing written over (issue 55's probes; docs/bad_input.md)."""

from __future__ import annotations

import pytest

from frontiernet.cli.main import main


def test_scene_starts_where_no_scene_ships_any_are_refused(tmp_path, one_line_error):
    # issue 55's second probe: --scene-starts on procedural scenes ran every run from drawn starts
    out = tmp_path / "b"
    assert main(["bench", "--scenes", "procedural:3", "--methods", "classic", "--starts", "1", "--repeats", "1",
                 "--max-steps", "60", "--scene-starts", "--out", str(out)]) == 2
    assert "--scene-starts: none of the scenes ships start poses" in one_line_error()
    assert not out.exists()


@pytest.mark.parametrize("background", ["[300, 0, 0]", "[1, 2]", "[-1, 0, 0.5]"])  # ("red": the key takes a list)
def test_a_background_that_is_no_colour_is_one_line_before_the_scene_loads(tmp_path, background, one_line_error):
    # issue 55's third probe: [300, 0, 0] was an internal error (OverflowError) after the scene loaded
    (tmp_path / "c.yaml").write_text(f"camera:\n  background: {background}\n")
    assert main(["render", "procedural:3", "--pose", "3,3,1.2,0", "--out", str(tmp_path / "o"),
                 "--config", str(tmp_path / "c.yaml")]) == 2
    assert "camera.background must be a list of 3 integers in [0, 255], got" in one_line_error()
    assert not (tmp_path / "o").exists()


def test_a_scene_scaled_past_the_voxel_limit_is_one_line(tmp_path, one_line_error):
    # issue 55's third probe: a box scaled 1e5 (600 km) overflowed the voxel count, an internal error
    import trimesh

    trimesh.creation.box(extents=(6.0, 4.0, 3.0)).export(tmp_path / "box.glb")
    assert main(["scene", "info", f"mesh:{tmp_path / 'box.glb'}?scale=1e5"]) == 2
    assert "check its scale (metres)" in one_line_error()


def test_outputs_that_are_not_regular_files_are_refused_and_kept(plan_spec, tmp_path, one_line_error):
    # issue 55's third probe: `--json /dev/full` was renamed over: the device became a JSON file
    import os
    import stat

    from frontiernet.errors import InputError
    from frontiernet.io import write_json

    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    assert main(["scene", "topdown", plan_spec, "--out", str(fifo), "--force"]) == 2
    assert "pipe: not a regular file" in one_line_error()
    with pytest.raises(InputError, match="not a regular file"):
        write_json(fifo, {"a": 1})
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)


@pytest.mark.parametrize("options, message", [
    ("&occupied_below=300", "occupied_below (300) must be at most free_above (250)"),  # walls and free at once
    ("&free_above=10", "occupied_below (50) must be at most free_above (10)"),
])
def test_floor_plan_thresholds_that_contradict_are_refused(plan_spec, options, message, one_line_error):
    assert main(["scene", "info", plan_spec + options]) == 2
    assert message in one_line_error()


def refused_render_config(tmp_path, text: str, one_line_error) -> str:
    """The one line `render` refuses a `--config` file holding `text` with (exit 2, no output folder)."""
    (tmp_path / "c.yaml").write_text(text)
    assert main(["render", "procedural:3", "--pose", "3,3,1.2,0", "--out", str(tmp_path / "o"),
                 "--config", str(tmp_path / "c.yaml")]) == 2
    assert not (tmp_path / "o").exists()
    return one_line_error()


def test_a_focal_length_past_a_pinhole_field_of_view_is_refused(tmp_path, one_line_error):
    # issue 55's third probe: focal_px 1e-9 rendered "valid depth 100%, range 0.00-0.00 m"
    assert "camera.focal_px >= 0.04 * camera.width must hold (a field of view over 170 degrees" in \
        refused_render_config(tmp_path, "camera:\n  focal_px: 1.0e-9\n", one_line_error)


def test_a_config_section_set_to_null_is_one_line(tmp_path, one_line_error):
    # issue 55's fourth probe: `camera: null` in a render config was an internal error (TypeError)
    assert "c.yaml: config key 'camera' is a section (its keys: width, height" in refused_render_config(
        tmp_path, "camera: null\n", one_line_error)
    assert main(["explore", "--scene", "procedural:3", "--out", str(tmp_path / "e"), "planner=null"]) == 2
    assert "override: config key 'planner' is a section" in one_line_error()


def test_a_floor_plan_resolution_that_leaves_no_building_is_one_line(tmp_path, one_line_error):
    # issue 55's fourth probe: ?resolution=1e-6 (a 100-pixel plan 0.1 mm wide) asked for 2 TiB (MemoryError)
    import cv2
    import numpy as np

    plan = np.full((100, 100), 255, np.uint8)
    plan[[0, -1], :] = plan[:, [0, -1]] = 0
    cv2.imwrite(str(tmp_path / "plan.png"), plan)
    assert main(["scene", "info", f"floorplan:{tmp_path / 'plan.png'}?resolution=1e-6"]) == 2
    assert "100 x 100 pixels at 1e-06 m/pixel span 0.0001 x 0.0001 m, less than 1 m a side" in one_line_error()


@pytest.mark.skipif(not __import__("os").path.isdir("/proc/self"), reason="needs /proc, a folder no file can be made in")
@pytest.mark.parametrize("argv", [["render", "procedural:3", "--pose", "3,3,1.2,0"],
                                  ["explore", "--scene", "procedural:3", "--max-steps", "2"]])
def test_an_output_folder_where_nothing_can_be_made_is_one_line(argv, one_line_error):
    # issue 55's fourth probe: `train out=/proc/t` was an internal error (FileNotFoundError) after its setup
    assert main([*argv, "--out", "/proc/frontiernet-probe/o"]) == 2
    assert "/proc/frontiernet-probe/o: cannot write in /proc" in one_line_error()

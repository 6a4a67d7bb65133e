"""Bad input of the ninth probe of issue 55 (docs/bad_input.md): config keys whose declared
range let a hang, an internal error or nonsense through (configs/ranges/), and messages that named the wrong key,
option or reason. Each refusal is one line, exit code 2, before the scene is built (a missing scene is given:
the old code, which let the value through, named that instead) and before any folder is made. Each test failed
before its fix."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import box_scene, room_boxes, sim_section
from test_bad_input_probe6 import refused  # exit 2, one line, no --out

from frontiernet.cli.main import main
from frontiernet.config_ranges import parse_relation
from frontiernet.errors import InputError

MISSING = "/nonexistent-probe9/none.glb"  # a scene the old code loaded (and refused) before the value tested
TC = ["sim.camera.width=64", "sim.camera.height=64", "sim.camera.focal_px=40"]


def explore_refuses(override: str, message: str, tmp_path, one_line_error, method: str = "classic") -> str:
    out = tmp_path / "out"
    return refused(["explore", "--scene", MISSING, "--max-steps", "4", "--no-video", "--method", method,
                    "--out", out, override, *TC], message, one_line_error, out)


# ----------------------------------------------------------------------------- E1: a hang in scipy's filter

@pytest.mark.parametrize("override, message", [
    # 1e9 px, scaled to the working size, ran scipy's minimum / maximum filter for minutes, deaf to SIGTERM
    ("ablations.discontinuity.window_px=1000000000", "ablations.discontinuity.window_px must be an integer in [2, 4096], "
     "got 1000000000"),
    ("ablations.discontinuity.window_px=1000", "ablations.discontinuity.window_px <= ablations.discontinuity."
     "source_size_px must hold (the window is in pixels of a source_size_px image"),
    ("ablations.discontinuity.source_size_px=1000000000", "ablations.discontinuity.source_size_px must be an integer "
     "in [1, 4096]"),
])
def test_the_discontinuity_window_is_bounded_by_the_image_it_is_measured_in(override, message, tmp_path,
                                                                           one_line_error):
    explore_refuses(override, message, tmp_path, one_line_error, method="discontinuity-gain")


# ----------------------------------------------------------------------------- E2: MemoryError

def test_a_huge_reachable_dilation_is_refused_up_front(tmp_path, one_line_error):
    explore_refuses("steps.reachable_dilation_m=1e9", "steps.reachable_dilation_m must be a number in [0, 5], got "
                    "1000000000.0", tmp_path, one_line_error)


def test_the_reachable_dilation_takes_any_radius_without_a_disk_of_its_size():
    # the disk was allocated whole: 1e9 m at 0.1 m voxels asked for 149 GiB (an internal error in explore)
    from frontiernet.exploration.steps import dilated_columns

    columns = np.zeros((40, 30), bool)
    columns[10, 12] = True
    assert dilated_columns(columns, 0.1, 1e9).all()
    grown = dilated_columns(columns, 0.1, 0.25)  # a disk of 2 cells: 13 of them
    assert grown.sum() == 13 and grown[12, 12] and grown[11, 13] and not grown[12, 13]


# ----------------------------------------------------------------------------- E5: int64 overflow, two warnings

def test_a_revisit_cell_below_a_centimetre_is_refused(tmp_path, one_line_error):
    explore_refuses("steps.revisit_cell_m=1e-30", "steps.revisit_cell_m must be a number >= 0.01, got 1e-30",
                    tmp_path, one_line_error)


# ----------------------------------------------------------------------------- E10, E14, E20: relations

def test_an_inverted_seer_candidate_ring_is_refused(tmp_path, one_line_error):
    out = tmp_path / "out"
    refused(["explore", "--scene", MISSING, "--max-steps", "4", "--no-video", "--method", "classic", "--out", out,
             "seer.candidate_rmin_m=5", "seer.candidate_rmax_m=1", *TC],
            "seer.candidate_rmin_m <= seer.candidate_rmax_m must hold", one_line_error, out)


@pytest.mark.parametrize("window", ["[5,6]", "[-2,-1]"])
def test_a_height_window_without_the_camera_height_is_refused(window, tmp_path, one_line_error):
    # [5, 6] m above the camera dropped every frontier the robot saw: "no frontiers left" at 12 % coverage
    explore_refuses(f"tracking.height_window_m={window}", "tracking.height_window_m[0] <= 0 <= "
                    "tracking.height_window_m[1] must hold (heights relative to the camera", tmp_path, one_line_error)


@pytest.mark.parametrize("values, holds", [
    ({"w": [-0.9, 0.6]}, True), ({"w": [0, 0]}, True), ({"w": [5, 6]}, False), ({"w": [-2, -1]}, False),
    ({"w": None}, None), ({"w": [1]}, None),  # null turns the rule off; a short list is its range's to refuse
])
def test_a_relation_reads_the_items_of_a_list_key(values, holds):
    assert parse_relation("w[0] <= 0 <= w[1]", "why", "test").holds(values) is holds


def test_a_planning_band_past_the_camera_height_is_refused(tmp_path, one_line_error):
    # "no free space ... keeps planner.clearance_m = 0.2 m from obstacles": the band's floor, not the clearance
    explore_refuses("planner.height_band_m=1e9", "planner.height_band_m < motion.camera_height_m must hold",
                    tmp_path, one_line_error)


def test_a_band_that_takes_in_the_floor_is_named_not_the_clearance():
    from frontiernet.exploration.region import start_sampler
    from frontiernet.exploration.run import load_run_config
    from frontiernet.simulator.voxels import voxelize_scene

    scene = box_scene(*room_boxes(4.0, 3.0, 2.5), name="room")
    voxels = voxelize_scene(scene, sim_section("voxels"))
    conf = load_run_config(overrides=["motion.camera_height_m=0.25", "planner.height_band_m=0.24"])  # 3 layers
    with pytest.raises(InputError, match=r"planner.height_band_m = 0.24 m, reaches the floor: .* use a smaller "
                                         r"planner.height_band_m"):
        start_sampler(scene, voxels, conf)[1](np.random.default_rng(0))


# ----------------------------------------------------------------------------- E15: one ray a view

@pytest.mark.parametrize("stride, message", [
    (4096, "ground_truth.observe_stride_px must be an integer in [1, 64], got 4096"),
    (64, "ground_truth.observe_stride_px < camera.width must hold"),  # one ray a row of a 64 px camera
])
def test_an_observe_stride_past_the_image_is_refused(stride, message, tmp_path, one_line_error):
    out = tmp_path / "out"
    refused(["datagen", "--scenes", "procedural:4", "--views-per-scene", "1", "--no-progress", "--out", out, "--set",
             "camera.width=64", "camera.height=64", "camera.focal_px=40", f"ground_truth.observe_stride_px={stride}"],
            message, one_line_error, out)


# ----------------------------------------------------------------------------- E19: the margin, not the scene

def test_a_huge_lateral_margin_is_refused(tmp_path, one_line_error):
    explore_refuses("sim.voxels.lateral_margin_m=1e9", "sim.voxels.lateral_margin_m must be a number in [0, 20], got "
                    "1000000000.0", tmp_path, one_line_error)


def test_a_grid_grown_past_max_voxels_by_the_margin_names_the_margin():
    from frontiernet.simulator.voxels import voxelize_scene

    scene = box_scene(*room_boxes(4.0, 3.0, 2.5), name="room")  # ~44 x 34 x 28 voxels without the margin
    with pytest.raises(InputError, match=r"a margin of 10 m a side; voxels.lateral_margin_m 10 m a side is what "
                                         r"makes it so large: use a smaller margin"):
        voxelize_scene(scene, sim_section("voxels", lateral_margin_m=10.0, max_voxels=100_000))
    with pytest.raises(InputError, match=r"check its scale \(metres\)"):  # (the scene itself too large: as before)
        voxelize_scene(scene, sim_section("voxels", lateral_margin_m=0.2, max_voxels=1_000))


# ----------------------------------------------------------------------------- E22-E25: messages

def test_a_procedural_option_that_leaves_no_building_is_named(one_line_error):
    # "widen the footprint or room size options", the footprint untouched
    line = refused(["scene", "info", "procedural:4?wall_thickness=10&max_attempts=3"],
                   "no valid building after 3 attempts with wall_thickness=10 (shipped: 0.15)", one_line_error)
    assert "max_attempts" not in line.split("attempts", 1)[1]


def test_a_plan_of_fractions_names_the_grey_levels(tmp_path, one_line_error):
    plan = np.zeros((100, 100), np.float32)
    plan[10:90, 10:90] = 1.0  # free space as 1, walls as 0: every pixel is below occupied_below (50)
    np.save(tmp_path / "plan_f.npy", plan)
    refused(["scene", "info", f"floorplan:{tmp_path / 'plan_f.npy'}?resolution=0.05"],
            "no free space inside a building: its values lie in [0, 1]; free space is above free_above (250), walls "
            "below occupied_below (50) and no pixel is free", one_line_error)


def test_an_existing_file_with_a_question_mark_is_that_file(tmp_path, one_line_error):
    from frontiernet.scenes.spec import expand_specs, parse_spec

    path = tmp_path / "a?b.glb"
    path.write_bytes(b"glTF")
    (tmp_path / "axb.glb").write_bytes(b"glTF")  # what '?' would match as a glob
    spec = parse_spec(str(path))
    assert (spec.source, spec.argument, spec.options) == ("mesh", str(path), {})
    spec = parse_spec(f"mesh:{path}?up=y")
    assert (spec.source, spec.argument, spec.options) == ("mesh", str(path), {"up": "y"})
    assert expand_specs([str(path)]) == [str(path)]
    refused(["scene", "info", str(tmp_path / "c?d.glb")], f"option 'd.glb' is not key=value ('?' starts the options; "
            f"no file or folder is named '{tmp_path / 'c?d.glb'}')", one_line_error)


def test_a_symbolic_link_loop_is_named(tmp_path, one_line_error):
    from frontiernet.io import input_file, input_folder

    (tmp_path / "loop1.glb").symlink_to("loop2.glb")
    (tmp_path / "loop2.glb").symlink_to("loop1.glb")
    loop = tmp_path / "loop1.glb"
    refused(["scene", "info", loop], f"{loop}: mesh file not found: a symbolic link loop ({loop} -> loop2.glb -> "
            "loop1.glb)", one_line_error)
    with pytest.raises(InputError, match="folder not found: a symbolic link loop"):
        input_folder(loop, "dataset")
    (tmp_path / "dangling.yaml").symlink_to("nowhere.yaml")
    with pytest.raises(InputError, match="config file not found: a symbolic link to nowhere.yaml, which does not exist"):
        input_file(tmp_path / "dangling.yaml", "config file")
    with pytest.raises(InputError, match=r"none.yaml: config file not found$"):  # a plain missing file: as before
        input_file(tmp_path / "none.yaml", "config file")

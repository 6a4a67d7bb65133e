"""Nonsense the sixth bad-input probe of issue 55 found accepted (docs/bad_input.md), other than the config
relations (tests/test_config_ranges.py): each is now one line naming the value, exit code 2, no folder made,
or (a spec given twice) run once. Each test failed before its fix: the command ran with the value."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from frontiernet.cli.main import main
from frontiernet.errors import InputError


@pytest.mark.parametrize("argv, message", [
    # mapgen sets these per run: the user's value was overridden in silence
    (["mapgen", "--scenes", "procedural:0", "--out", "{out}", "--set", "run.depth=sonar"],
     "run.depth: mapgen does not read it (each run's depth is its entry's in mapgen.runs), got 'sonar'"),
    (["mapgen", "--scenes", "procedural:0", "--out", "{out}", "--set", "run.max_steps=20"],
     "run.max_steps: mapgen does not read it (each run's budget is mapgen.max_steps)"),
    # an empty --scene explored the default scene
    (["demo", "--scene", "", "--out", "{out}"], "empty scene spec"),
    # --map-free won over the planner.mode=map given beside it
    (["explore", "--scene", "procedural:0", "--map-free", "planner.mode=map", "--out", "{out}"],
     "--map-free contradicts planner.mode=map: give one of them"),
    # an option and the key it sets, given different values: one ran in silence (the seventh probe's D12)
    (["explore", "--scene", "procedural:0", "--seed", "1", "run.seed=2", "--out", "{out}"],
     "--seed 1 contradicts run.seed=2: give one of them"),
    (["explore", "--scene", "procedural:0", "--max-steps", "4", "run.max_steps=5", "--out", "{out}"],
     "--max-steps 4 contradicts run.max_steps=5: give one of them"),
    (["demo", "--max-steps", "4", "run.max_steps=5", "--out", "{out}"],
     "--max-steps 4 contradicts run.max_steps=5: give one of them"),
    (["bench", "--scenes", "procedural:0", "--methods", "classic", "--seed", "3", "--out", "{out}", "--set",
      "run.seed=4"], "--seed 3 contradicts run.seed=4: give one of them"),
    # eighth probe (E8): the key --model stands for with a map predictor's method was dropped (config.yaml recorded it)
    (["explore", "--scene", "procedural:0", "--method", "mapex", "--model", "mine.safetensors", "--out", "{out}",
      "mapex.predictor=other.safetensors"],
     "--model mine.safetensors contradicts mapex.predictor=other.safetensors: give one of them"),
    (["bench", "explore", "--scene", "procedural:0", "--method", "seer", "--model", "mine.safetensors", "--json",
      "seer.predictor=other.safetensors"],
     "--model mine.safetensors contradicts seer.predictor=other.safetensors: give one of them"),
    (["bench", "explore", "--scene", "procedural:0", "--depth", "gt", "--json", "run.depth=emulated"],
     "--depth gt contradicts run.depth=emulated: give one of them"),
    # a focal length of 1e30 px (a field of view of 0 degrees) rendered blank frames
    (["explore", "--scene", "procedural:0", "sim.camera.focal_px=1e30", "--out", "{out}"],
     "sim.camera.focal_px <= 100 * sim.camera.width must hold"),
    # near_clip_m past the camera's range: a dataset of no frontier pixel
    (["datagen", "--scenes", "procedural:0", "--views-per-scene", "1", "--out", "{out}", "--set",
      "ground_truth.near_clip_m=5"], "ground_truth.near_clip_m < camera.max_depth must hold"),
    # eighth probe (E21): refused per scene, as the scenes' failures ("procedural:3: ... (no view was made of 2
    # failed scene(s)"), after every scene had loaded; 18 lay inside the declared int [6, 26]
    (["datagen", "--scenes", "procedural:0", "procedural:1", "--views-per-scene", "1", "--out", "{out}", "--set",
      "ground_truth.frontier_connectivity=18"], "error: ground_truth.frontier_connectivity must be one of 6, 26, got 18"),
    (["datagen", "--scenes", "procedural:0", "--views-per-scene", "1", "--out", "{out}", "--set",
      "ground_truth.gain.yaw_offsets_deg=[]"], "error: len(ground_truth.gain.yaw_offsets_deg) >= 1 must hold (a gain "
                                              "view per heading: with none, no gain is measured)"),
    (["explore", "--scene", "procedural:0", "--method", "seer", "--out", "{out}", "seer.yaw_offsets_deg=[]"],
     "error: len(seer.yaw_offsets_deg) >= 1 must hold"),
])
def test_accepted_nonsense_is_one_line_before_any_folder(argv, message, tmp_path, one_line_error):
    out = tmp_path / "o"
    assert main([arg.format(out=out) for arg in argv]) == 2
    assert message in one_line_error()
    assert not out.exists()


def test_an_option_and_its_key_naming_one_depth_source_in_two_spellings_agree(tmp_path, capsys):
    # eighth probe (E17): "--depth gt contradicts run.depth=ground_truth: give one of them", both names of one source
    out = tmp_path / "o"
    assert main(["explore", "--scene", "procedural:3", "--max-steps", "1", "--method", "classic", "--no-video",
                 "--depth", "gt", "--out", str(out), "run.depth=ground_truth", "sim.camera.width=32",
                 "sim.camera.height=32", "sim.camera.focal_px=20"]) == 0
    assert "(ground_truth depth)" in capsys.readouterr().out
    assert main(["explore", "--scene", "procedural:3", "--depth", "gt", "run.depth=emulated", "--out",
                 str(tmp_path / "o2")]) == 2  # another source still contradicts it
    assert "--depth gt contradicts run.depth=emulated: give one of them" in capsys.readouterr().err


@pytest.mark.parametrize("value", ["99:99:99:99", "00:24:00:00", "00:00:60:00"])
def test_a_max_time_with_fields_past_their_clock_is_refused(value):
    from train.main import check_max_time

    check_max_time("01:23:59:59")
    with pytest.raises(InputError, match="trainer.max_time: a wall-clock limit is DD:HH:MM:SS"):
        check_max_time(value)  # 99:99:99:99 was read as 103 days


@pytest.mark.parametrize("intrinsics, message", [
    ("1e9,1e9,32,24", "--intrinsics: a focal length of 1e+09 px is over 100 x the 64 x 48 image's side"),
    # seventh probe: a focal of 0.001 px (a field of view of ~180 degrees) sized a map of 40 PiB (MemoryError)
    ("0.001,0.001,32,24", "--intrinsics: a focal length of 0.001 px is under 0.04 x the 64 x 48 image's side"),
])
def test_intrinsics_of_no_pinhole_camera_are_refused_for_a_photo(intrinsics, message, tmp_path, one_line_error):
    import cv2

    cv2.imwrite(str(tmp_path / "rgb.png"), np.zeros((48, 64, 3), np.uint8))
    np.save(tmp_path / "depth.npy", np.ones((48, 64), np.float32))
    out = tmp_path / "o"
    assert main(["predict", "--image", str(tmp_path / "rgb.png"), "--depth", str(tmp_path / "depth.npy"),
                 "--intrinsics", intrinsics, "--out", str(out)]) == 2
    assert message in one_line_error()
    assert not out.exists()


def test_a_complex_floor_plan_array_is_refused(tmp_path, one_line_error):
    plan = np.full((60, 60), 254 + 1j)  # was read with its imaginary part dropped
    plan[0] = 0
    np.save(tmp_path / "plan.npy", plan)
    assert main(["scene", "topdown", f"{tmp_path / 'plan.npy'}?resolution=0.05", "--out", str(tmp_path / "t.png")]) == 2
    assert "floor-plan array must hold real numbers or booleans, got complex128" in one_line_error()


def test_a_scene_given_twice_in_another_spelling_runs_once(tmp_path, caplog):
    from frontiernet.scenes.spec import expand_specs

    (tmp_path / "a.glb").write_bytes(b"")
    with caplog.at_level(logging.WARNING):
        specs = expand_specs(["procedural:3", "procedural:03", f"{tmp_path}/a.glb?up=z&scale=1",
                              f"{tmp_path}/./a.glb?scale=1&up=z", "procedural:2-4"])
    assert specs == ["procedural:3", f"{tmp_path}/a.glb?up=z&scale=1", "procedural:2", "procedural:4"]
    assert "scene procedural:03 is procedural:3, given already: it runs once" in caplog.text


def test_datagen_warns_of_a_dataset_without_a_frontier_pixel(tmp_path, capsys):
    from datagen.cli import print_summary

    summary = {"views": 4, "scenes": 1, "shards": 1, "shards_planned": 1, "views_this_run": 4, "seconds": 1.0,
               "views_per_second": 4.0, "frontier_view_fraction": 0.0, "frontier_pixel_ratio": 0.0,
               "candidates_per_view": 0.0, "gain_class_pixels": [10, 0], "failed_scenes": []}
    print_summary(summary, tmp_path)
    assert "has a frontier pixel: nothing to learn frontiers from" in capsys.readouterr().err
    print_summary({**summary, "frontier_pixel_ratio": 0.01, "frontier_view_fraction": 0.5}, tmp_path)
    assert capsys.readouterr().err == ""


# ----------------------------------------------------------------------------- the seventh probe's first finds

@pytest.mark.parametrize("override, message", [
    ("motion.translation_m=1e-300", "motion.translation_m must be a number >= 0.01"),  # was numpy's size limit
    ("run.video_fps=1e-300", "run.video_fps must be a number in [0.01, 1000]"),  # ffmpeg's lines, then exit 1
    ("run.video_fps=1e300", "run.video_fps must be a number in [0.01, 1000]"),
])
def test_motion_and_video_rates_past_what_runs_are_refused(override, message, tmp_path, one_line_error):
    out = tmp_path / "o"
    assert main(["explore", "--scene", "procedural:3", "--max-steps", "4", "--method", "classic", "--out", str(out),
                 override]) == 2
    assert message in one_line_error()
    assert not out.exists()


def test_a_tum_quaternion_of_huge_components_is_a_rotation(tmp_path):
    from frontiernet.geometry import quaternion_rotations

    # 1e200 squared overflowed to inf and scipy found the quaternion of zero length (an internal error)
    assert np.allclose(quaternion_rotations([[0, 0, 0, 1e200], [0, 0, 2e-3, 0]], "q").as_quat(),
                       [[0, 0, 0, 1], [0, 0, 1, 0]])
    for bad, words in (([0, 0, 0, 0], "zero length"), ([0, 0, 0, np.inf], "not finite")):
        with pytest.raises(InputError, match=f"q: a quaternion .*{words}"):
            quaternion_rotations(bad, "q")


def test_set_given_twice_keeps_both_lists():
    from frontiernet.cli.main import build_parser

    # seventh probe: `datagen --set a=1 --set b=2` dropped a=1 in silence (a bad value in it then ran)
    args = build_parser().parse_args(["datagen", "--scenes", "procedural:0", "--set", "a=1", "--set", "b=2", "c=3"])
    assert args.set == ["a=1", "b=2", "c=3"]
    assert build_parser().parse_args(["datagen", "--scenes", "procedural:0"]).set == []


@pytest.mark.parametrize("argv", [["bench", "map", "--scene", ""], ["bench", "explore", "--scene", ""],
                                  ["datagen", "bench", "--scene", ""]])
def test_an_empty_benchmark_scene_is_not_the_default(argv, one_line_error):
    assert main(argv) == 2  # seventh probe: ran the default scene
    assert "--scene '': an empty scene spec" in one_line_error()


def test_a_ray_stride_past_any_image_is_refused(tmp_path, one_line_error):
    out = tmp_path / "o"  # seventh probe: 1e9 kept one ray a frame and ended at 0.0 % coverage
    assert main(["explore", "--scene", "procedural:3", "--out", str(out), "map.ray_stride_px=1000000000"]) == 2
    assert "map.ray_stride_px must be an integer in [1, 64]" in one_line_error()
    assert not out.exists()

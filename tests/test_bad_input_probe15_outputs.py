"""Bad input of the fifteenth probe of issue 55 (docs/bad_input.md, "The fifteenth probe"): outputs written with
``--force`` over the very file the command reads (Q9): ``scene topdown`` over its floor plan, ``render`` its
``rgb.png`` over the plan it rendered, ``predict`` its ``input.png`` over the photo, and (the same class)
``explore`` its ``config.yaml`` over the ``--config`` it read. Each refusal: one line on stderr naming the file and
what it is, exit code 2, the input left as it was."""

from __future__ import annotations

import shutil

import cv2
import numpy as np
import pytest

from frontiernet.cli.main import main


@pytest.fixture
def floor_plan(tmp_path):
    plan = np.full((200, 200), 255, np.uint8)
    plan[:5], plan[-5:], plan[:, :5], plan[:, -5:] = 0, 0, 0, 0
    plan[100:103, 5:150] = 0
    path = tmp_path / "fp.png"
    cv2.imwrite(str(path), plan)
    return path


def refused_keeping(path, args, one_line_error, message) -> None:
    before = path.read_bytes()
    assert main(args) == 2
    assert one_line_error().endswith(message)
    assert path.read_bytes() == before


def test_a_top_view_over_its_own_floor_plan_is_refused(floor_plan, one_line_error):
    refused_keeping(floor_plan, ["scene", "topdown", f"floorplan:{floor_plan}?resolution=0.05", "--out", str(floor_plan),
                                 "--force"], one_line_error,
                    f"--out {floor_plan}: is the scene {floor_plan}, which this command reads; writing its results "
                    "there would destroy it: choose another --out")


def test_a_render_into_the_folder_of_its_floor_plan_named_rgb_png_is_refused(floor_plan, tmp_path, one_line_error):
    folder = tmp_path / "rp"
    folder.mkdir()
    plan = shutil.copyfile(floor_plan, folder / "rgb.png")
    refused_keeping(plan, ["render", f"floorplan:{plan}?resolution=0.05", "--pose", "2,2,1.2,0", "--out", str(folder),
                           "--force"], one_line_error,
                    f"--out {plan}: is the scene {plan}, which this command reads; writing its results there would "
                    "destroy it: choose another --out")


def test_predict_into_the_folder_of_its_image_named_input_png_is_refused(tmp_path, one_line_error):
    rendered = tmp_path / "in"
    assert main(["render", "procedural:3", "--pose", "3,3,1.2,0", "--out", str(rendered)]) == 0
    folder = tmp_path / "pp"
    folder.mkdir()
    image = shutil.copyfile(rendered / "rgb.png", folder / "input.png")
    refused_keeping(image, ["predict", "--image", str(image), "--depth", str(rendered / "depth.npy"), "--out",
                            str(folder), "--force"], one_line_error,
                    f"--out {image}: is the image (--image) {image}, which this command reads; writing its results "
                    "there would destroy it: choose another --out")
    assert sorted(path.name for path in folder.iterdir()) == ["input.png"]


def test_explore_into_the_folder_of_its_config_named_config_yaml_is_refused(tmp_path, one_line_error):
    folder = tmp_path / "ex"
    folder.mkdir()
    config = folder / "config.yaml"
    config.write_text("run:\n  seed: 4\n")
    refused_keeping(config, ["explore", "--scene", "procedural:3", "--max-steps", "2", "--no-video", "--method",
                             "classic", "--config", str(config), "--out", str(folder), "--force"], one_line_error,
                    f"--out {config}: is the config file {config}, which this command reads; writing its results "
                    "there would destroy it: choose another --out")


@pytest.mark.parametrize("override, message", [
    ("anchoring.hdbscan.min_cluster_size=30", "anchoring.hdbscan.min_cluster_size=30: anchoring makes the 3D frontiers "
                                              "of --intrinsics, and none is given: give --intrinsics, or leave it out"),
    ("depth.depth_anything_v2.path=/nonexistent", "depth.depth_anything_v2.path=/nonexistent: a setting of the depth "
                                                  "model depth_anything_v2, and no depth model runs (--depth gives a "
                                                  "file, or none): leave it out"),
])
def test_predict_refuses_an_override_it_would_not_read(override, message, tmp_path, one_line_error):
    # Q15: both ran, the override never read, nothing recorded
    rendered = tmp_path / "in"
    assert main(["render", "procedural:3", "--pose", "3,3,1.2,0", "--out", str(rendered)]) == 0
    out = tmp_path / "p"
    assert main(["predict", "--image", str(rendered / "rgb.png"), "--depth", str(rendered / "depth.npy"), "--out",
                 str(out), override]) == 2
    assert one_line_error().endswith(message)
    assert not out.exists()

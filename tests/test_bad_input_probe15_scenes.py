"""Bad input of the fifteenth probe of issue 55 (docs/bad_input.md, "The fifteenth probe") to scene specs and
benchmark options: ``bench --depth ''`` ran every run, each failing, and left a folder (Q2); one procedural
scene spelt ``procedural:+3``, ``'procedural: 3'`` or ``procedural:1_000`` beside ``procedural:3`` ran and was
counted twice (Q3). Each refusal: one line on stderr naming the value, exit code 2, before any folder is made."""

from __future__ import annotations

import numpy as np
import pytest

from frontiernet.cli.main import main
from frontiernet.errors import InputError


def test_an_empty_depth_list_is_refused_before_the_benchmark_folder(tmp_path, one_line_error):
    out = tmp_path / "b"
    assert main(["bench", "--scenes", "procedural:3", "--max-steps", "4", "--methods", "classic", "--depth", "",
                 "--starts", "1", "--out", str(out)]) == 2
    assert one_line_error().endswith("depth source '' (--depth, run.depth) is unknown; valid: gt, ground_truth, "
                                     "emulated, depth_anything_v2, metric3d_v2")
    assert not out.exists()


@pytest.mark.parametrize("seed", ["+3", " 3", "1_000", "\u0663", "\uff13", "3.0", "0x3"])
def test_a_seed_not_written_in_the_digits_0_to_9_is_refused(seed):
    from frontiernet.scenes.spec import checked_spec

    with pytest.raises(InputError, match=r"procedural seed must be an integer >= 0 in the digits 0-9 alone"):
        checked_spec(f"procedural:{seed}")


def test_seeds_in_plain_digits_and_ranges_still_read():
    from frontiernet.scenes.spec import checked_spec, expand_specs, scene_identity

    assert checked_spec("procedural:003").argument == "003"
    assert scene_identity("procedural:03") == scene_identity("procedural:3")
    assert expand_specs(["procedural:2-4"]) == ["procedural:2", "procedural:3", "procedural:4"]
    with pytest.raises(InputError, match="procedural seed must be >= 0"):
        checked_spec("procedural:-3")
    with pytest.raises(InputError, match="a range of seeds names several scenes"):
        checked_spec("procedural:3-5")
    with pytest.raises(InputError, match=r"a seed range is procedural:FIRST-LAST"):
        expand_specs(["procedural:+1-3"])


@pytest.mark.parametrize("command", [["datagen", "--views-per-scene", "1", "--no-progress"], ["mapgen"]])
def test_datagen_and_mapgen_refuse_a_second_spelling_before_any_view(command, tmp_path, one_line_error):
    out = tmp_path / "d"
    assert main([command[0], "--scenes", "procedural:3", "procedural:+3", *command[1:], "--out", str(out)]) == 2
    assert "scene spec 'procedural:+3': procedural seed must be an integer" in one_line_error()
    assert not out.exists()


def test_a_resolution_given_to_a_kth_plan_folder_is_refused(tmp_path, one_line_error):
    # Q14: ?resolution=0.5 on a 0.05 m/pixel plan folder made a 427 x 325 m building: minutes and 6.6 GB to load
    folder = tmp_path / "plan"
    folder.mkdir()
    plan = np.full((60, 80), 255, np.uint8)
    plan[:3], plan[-3:], plan[:, :3], plan[:, -3:] = 0, 0, 0, 0
    np.save(folder / "occ_map.npy", plan)
    spec = f"floorplan:{folder}?resolution=0.5"
    assert main(["scene", "info", spec]) == 2
    assert one_line_error().endswith(f"scene spec '{spec}': ?resolution= scales an image floor plan; a KTH / MapEx "
                                     "plan folder is 0.05 m/pixel (scenes.floorplan.kth_resolution): leave resolution "
                                     "out, or set kth_resolution for plans of another scale")
    assert main(["scene", "info", f"floorplan:{folder}"]) == 0

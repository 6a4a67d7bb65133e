"""`frontiernet datagen consistency`: the gain labels' agreement with themselves (resampled gain,
nearby views carried over through depth), the ceiling of any model's gain Dice."""

from __future__ import annotations

import numpy as np
import pytest

from datagen.consistency import label_consistency, load_consistency_config, majority_class, nearby_pose, warp_to_view
from frontiernet.cli.main import main

SMALL = ["camera.width=96", "camera.height=96", "camera.focal_px=60"]
K = np.array([[60.0, 0, 47.5], [0, 60.0, 47.5], [0, 0, 1]])


def test_warp_follows_a_sideways_step_in_front_of_a_wall():
    depth = np.full((96, 96), 2.0, np.float32)  # a wall 2 m ahead, facing the camera
    T_a = np.eye(4)
    T_b = np.eye(4)
    T_b[0, 3] = 0.1  # 0.1 m to the right: the wall moves 60 * 0.1 / 2 = 3 px to the left
    rows, cols, seen = warp_to_view(depth, K, T_a, depth, K, T_b, max_depth_m=3.5)
    v, u = np.mgrid[0:96, 0:96]
    assert np.array_equal(rows, v)
    assert np.array_equal(cols[seen], u[seen] - 3)
    assert not seen[:, :3].any() and seen[:, 3:].all()  # the first 3 columns leave B's image
    # a nearer surface in B hides A's wall there
    occluded = depth.copy()
    occluded[:, 40:50] = 1.0
    _, _, seen_occluded = warp_to_view(depth, K, T_a, occluded, K, T_b, max_depth_m=3.5)
    assert not seen_occluded[:, 43:53].any() and seen_occluded[:, 60:].all()


def test_nearby_pose_moves_and_turns_by_the_asked_amounts():
    T = np.eye(4)
    T[:3, :3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]  # an OpenCV camera looking along world +x
    moved = nearby_pose(T, 0.1, np.deg2rad(5.0), np.pi / 2)
    assert np.allclose(moved[:3, 3], [0, 0.1, 0])
    forward = moved[:3, :3] @ [0, 0, 1]
    assert np.isclose(np.degrees(np.arctan2(forward[1], forward[0])), 5.0) and np.isclose(forward[2], 0)


def test_majority_class_per_pixel():
    maps = np.array([[[1, 2]], [[1, 3]], [[4, 3]]])
    assert majority_class(maps, 5).tolist() == [[1, 3]]


@pytest.mark.slow
def test_labels_measured_at_every_voxel_agree_with_themselves_and_sampled_ones_do_not():
    exact = load_consistency_config(overrides=SMALL + [
        "ground_truth.gain.sample_fraction=1.0", "ground_truth.gain.max_samples=1000000",
        "consistency.translation_m=0.0", "consistency.rotation_deg=0.0"])
    result = label_consistency(["procedural:12"], 4, exact, seed=0)["total"]
    # gain measured at every frontier voxel is deterministic: the same pose gives the same labels,
    # and a 'nearby' view 0 m and 0 deg away is carried over pixel for pixel
    for kind in ("resampled", "consensus", "nearby"):
        assert result[kind]["pairs"] == 4 and result[kind]["pixels"] == 4 * 96 * 96
        assert result[kind]["gain_dice_with_class_0"] == 1.0 and result[kind]["gain_band_exact"] == 1.0
        assert result[kind]["df_error_px"] == 0.0
    sampled = load_consistency_config(overrides=SMALL + ["consistency.resampled_labelings=3"])
    noisy = label_consistency(["procedural:12"], 4, sampled, seed=0)["total"]
    assert noisy["resampled"]["df_error_px"] == 0.0  # F and D do not depend on the gain samples ...
    assert noisy["resampled"]["gain_band_exact"] < 1.0  # ... the gain classes do
    assert noisy["consensus"]["gain_band_exact"] < 1.0
    assert 0 < noisy["nearby"]["gain_dice_with_class_0"] < 1 and noisy["nearby"]["df_error_px"] > 0


def test_bad_consistency_input_is_one_line_exit_2(one_line_error):
    assert main(["datagen", "consistency", "--scenes", "procedural:12", "--views-per-scene", "0"]) == 2
    assert "--views-per-scene must be an integer in [1, 10000000], got 0" in one_line_error()
    assert main(["datagen", "consistency", "--scenes", "procedural:12", "--set", "consistency.max_tries=0"]) == 2
    assert "consistency.max_tries" in one_line_error()
    assert main(["datagen", "consistency", "--scenes", "procedural:12", "--set",
                 "consistency.resampled_labelings=1.5"]) == 2
    assert "consistency.resampled_labelings must be an integer in [1, 100], got 1.5" in one_line_error()
    assert main(["datagen", "consistency", "--scenes", "procedural:12", "--set",
                 "consistency.translation_m=-1"]) == 2
    assert "consistency.translation_m" in one_line_error()
    # a nearby view past the camera's range shares no pixel: rows of NaN (the seventh probe's D14)
    assert main(["datagen", "consistency", "--scenes", "procedural:12", "--set", "consistency.translation_m=1e30"]) == 2
    assert "consistency.translation_m < camera.max_depth must hold" in one_line_error()


def test_a_check_that_found_no_pair_says_so_instead_of_nan():
    from datagen.consistency import KINDS, Agreement, format_consistency

    empty = Agreement(11).summary()
    result = {"settings": {"views_per_scene": 1, "translation_m": 3.0, "rotation_deg": 5.0, "sample_fraction": 0.1},
              "scenes": {"procedural:12": {kind: empty for kind in KINDS}}, "total": {kind: empty for kind in KINDS}}
    text = format_consistency(result)
    assert "nan" not in text and "no pair: no nearby view was found" in text

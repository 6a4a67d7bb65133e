"""Anchoring (paper III-E): frontier pixels -> 3D frontiers, checked against built geometry.

The synthetic views are 200 x 200 px (f = 150 px) from a level camera looking along world
+x: image u (camera x) is world -y, image v (camera y) is world -z. A near wall at 1.5 m
covers the left of the image and a far wall at 3.0 m the right, so the space the near
wall hides (its shadow) lies behind it, on the left of the edge's ray.
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import TWO_ROOM, box_scene, room_boxes
from datagen.config import load_datagen_config
from datagen.ground_truth import GroundTruthGenerator
from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.frontiers import (AnchoringSettings, FrontierObservation, anchor_frontiers, anchor_prediction,
                                   class_lower_bounds, decode_gain, gain_classes)
from frontiernet.geometry import pose_from_heading
from frontiernet.simulator.raycast import cast_rays
from frontiernet.simulator.voxels import voxelize_scene

SIZE, FOCAL, NEAR, FAR = 200, 150.0, 1.5, 3.0
K = np.array([[FOCAL, 0.0, (SIZE - 1) / 2], [0.0, FOCAL, (SIZE - 1) / 2], [0.0, 0.0, 1.0]])
POSE = pose_from_heading(1.0, 2.0, 1.2, yaw=0.0)
EDGES = [1, 50, 150, 300, 450, 750, 1000, 1500, 2000, 2500, 3500]
LABELS = {"bin_edges": EDGES, "bin_unit_m3": 0.01, "frontier_threshold_px": 0.5}


@pytest.fixture(scope="module")
def conf():
    return load_config("explore").anchoring


def _conf(**overrides):
    return load_config("explore", overrides=[f"anchoring.{k}={v}" for k, v in overrides.items()]).anchoring


def edge_view(near_columns: list[tuple[int, int]], band_px: int = 3):
    """Depth with the near wall over the given [u0, u1) column ranges (far wall elsewhere) and
    a frontier band `band_px` wide either side of every near/far edge."""
    depth = np.full((SIZE, SIZE), FAR, np.float32)
    mask = np.zeros((SIZE, SIZE), bool)
    for u0, u1 in near_columns:
        depth[:, u0:u1] = NEAR
        for edge in (u0, u1):
            if 0 < edge < SIZE:
                mask[:, max(edge - band_px, 0):edge + band_px] = True
    return depth, mask, np.full((SIZE, SIZE), 5.0, np.float32)


def to_camera(points, T=POSE):
    return (np.atleast_2d(points) - T[:3, 3]) @ T[:3, :3]


def project(points_cam):
    return points_cam[:, 0] * FOCAL / points_cam[:, 2] + K[0, 2], points_cam[:, 1] * FOCAL / points_cam[:, 2] + K[1, 2]


def test_one_edge_gives_one_frontier_between_foreground_and_background(conf):
    depth, mask, gain = edge_view([(0, 100)])
    frontiers = anchor_frontiers(mask, gain, depth, K, POSE, conf)
    assert len(frontiers) == 1
    f = frontiers[0]
    assert isinstance(f, FrontierObservation) and f.num_pixels == mask.sum()
    assert 97 <= f.pixel[0] <= 102 and abs(f.pixel[1] - 99.5) <= 1
    cam = to_camera(f.position)[0]
    # on the centre pixel's ray, halfway between the near (1.5 m) and far (3.0 m) walls
    assert cam[2] == pytest.approx((NEAR + FAR) / 2)
    np.testing.assert_allclose(project(cam[None]), [[f.pixel[0]], [f.pixel[1]]], atol=1e-6)
    assert f.gain_m3 == pytest.approx(5.0)
    np.testing.assert_array_equal(f.T_world_cam, POSE)


def test_view_direction_looks_into_the_space_the_near_wall_hides(conf):
    depth, mask, gain = edge_view([(0, 100)])
    f = anchor_frontiers(mask, gain, depth, K, POSE, conf)[0]
    right, forward = POSE[:3, 0], POSE[:3, 2]
    assert np.linalg.norm(f.direction) == pytest.approx(1.0) and f.direction[2] == 0.0
    assert f.direction @ forward > 0.5 and f.direction @ right < -0.5  # forward and to the occluder's side
    # a little along it lies behind the near wall: left of the edge and farther than the wall
    ahead = to_camera(f.position + 0.3 * f.direction)
    u, _ = project(ahead)
    assert u[0] < 99.5 and ahead[0, 2] > NEAR


def test_two_separated_edges_give_two_frontiers_facing_the_shadow_between_them(conf):
    depth, mask, gain = edge_view([(60, 140)])  # a pillar in front of the far wall
    frontiers = sorted(anchor_frontiers(mask, gain, depth, K, POSE, conf), key=lambda f: f.pixel[0])
    assert len(frontiers) == 2
    left, right = frontiers
    assert abs(left.pixel[0] - 60) <= 3 and abs(right.pixel[0] - 140) <= 3
    camera_right = POSE[:3, 0]
    assert left.direction @ camera_right > 0.5 and right.direction @ camera_right < -0.5
    for f in frontiers:
        assert to_camera(f.position)[0, 2] == pytest.approx((NEAR + FAR) / 2)


def test_invalid_background_counts_as_the_farthest_valid_depth(conf):
    depth, mask, gain = edge_view([(0, 100)])
    depth[:, 100:] = np.nan  # nothing in range behind the edge ...
    depth[190:, :] = 3.4     # ... but the floor is seen up to 3.4 m
    f = anchor_frontiers(mask, gain, depth, K, POSE, conf)[0]
    assert to_camera(f.position)[0, 2] == pytest.approx((NEAR + 3.4) / 2)


@pytest.mark.parametrize("case", ["empty", "few", "zero_gain", "too_near", "no_depth", "flat"])
def test_nothing_to_cluster_gives_no_frontiers(conf, case):
    depth, mask, gain = edge_view([(0, 100)])
    if case == "empty":
        mask[:] = False
    elif case == "few":
        mask[:] = False
        mask[50:55, 98:101] = True  # 15 pixels < min_cluster_size
    elif case == "zero_gain":
        gain[:] = 0.0
    elif case == "too_near":
        depth *= 0.1  # frontier depth 0.225 m < min_depth_m
    elif case == "flat":
        depth[:] = 2.3  # no depth edge: no occluded side
    else:
        depth[:] = np.nan
    assert anchor_frontiers(mask, gain, depth, K, POSE, conf) == []


def test_zero_gain_pixels_are_kept_when_asked():
    depth, mask, gain = edge_view([(0, 100)])
    gain[:] = 0.0
    frontiers = anchor_frontiers(mask, gain, depth, K, POSE, _conf(drop_zero_gain=False))
    assert len(frontiers) == 1 and frontiers[0].gain_m3 == 0.0


def test_moving_the_camera_moves_the_frontier_with_it(conf):
    depth, mask, gain = edge_view([(0, 100)])
    moved = pose_from_heading(-3.0, 0.5, 0.8, yaw=1.1)
    a = anchor_frontiers(mask, gain, depth, K, POSE, conf)[0]
    b = anchor_frontiers(mask, gain, depth, K, moved, conf)[0]
    relative = moved @ np.linalg.inv(POSE)
    np.testing.assert_allclose(b.position, relative[:3, :3] @ a.position + relative[:3, 3], atol=1e-9)
    np.testing.assert_allclose(b.direction, relative[:3, :3] @ a.direction, atol=1e-9)


def test_pitched_camera_directions_are_levelled_only_when_asked(conf):
    depth, mask, gain = edge_view([(0, 100)])
    pitched = pose_from_heading(1.0, 2.0, 1.2, yaw=0.3, pitch=-0.4)
    level = anchor_frontiers(mask, gain, depth, K, pitched, conf)[0]
    free = anchor_frontiers(mask, gain, depth, K, pitched, _conf(horizontal_directions=False))[0]
    assert level.direction[2] == 0.0 and np.linalg.norm(level.direction) == pytest.approx(1.0)
    assert free.direction[2] < -0.1  # the tilted camera's ray points down
    horizontal = free.direction[:2] / np.linalg.norm(free.direction[:2])
    np.testing.assert_allclose(level.direction[:2], horizontal, atol=1e-9)


def test_subsampling_keeps_one_frontier_and_counts_image_pixels():
    depth, mask, gain = edge_view([(0, 100)])
    frontiers = anchor_frontiers(mask, gain, depth, K, POSE, _conf(max_pixels=300), np.random.default_rng(3))
    assert len(frontiers) == 1 and frontiers[0].num_pixels == mask.sum()


# Two blocks of grid points: many equal mutual-reachability weights, and the order hdbscan takes them in
# decides whether point 10 joins the second cluster (found by a search over random blocks).
TIED_FEATURES = np.array([[4, 2], [4, 3], [4, 4], [4, 5], [5, 2], [5, 3], [5, 4], [5, 5], [10, 7], [10, 8], [10, 9],
                          [11, 1], [11, 2], [11, 3], [11, 4], [12, 1], [12, 2], [12, 3], [12, 4], [13, 1], [13, 2],
                          [13, 3], [13, 4]], np.float64)


def _argsort_reversing_ties(monkeypatch):
    """Stand in for a CPU whose numpy sorts equal keys in another order: the default (unstable)
    argsort puts ties last index first; the stable kind stays stable."""
    argsort = np.argsort

    def reversing(a, axis=-1, kind=None, order=None, **kwargs):
        if kind is not None or np.ndim(a) != 1:
            return argsort(a, axis=axis, kind=kind, order=order, **kwargs)
        return len(a) - 1 - argsort(np.asarray(a)[::-1], kind="stable")
    monkeypatch.setattr(np, "argsort", reversing)


def test_clusters_do_not_depend_on_how_the_cpu_sorts_equal_weights(monkeypatch):
    import hdbscan
    from hdbscan import hdbscan_

    from frontiernet.frontiers import anchoring

    settings = AnchoringSettings.from_config(_conf(**{"hdbscan.min_cluster_size": 5, "hdbscan.min_samples": 4,
                                                      "hdbscan.cluster_selection_epsilon": 0.0}))
    here = anchoring.cluster_labels(TIED_FEATURES, settings)
    with monkeypatch.context() as installed:  # hdbscan as installed, sorting with numpy's default argsort ...
        installed.setattr(anchoring, "_hdbscan", lambda: hdbscan)
        installed.setattr(hdbscan_, "np", np)
        as_installed = anchoring.cluster_labels(TIED_FEATURES, settings)
        _argsort_reversing_ties(installed)
        assert not np.array_equal(as_installed, anchoring.cluster_labels(TIED_FEATURES, settings))  # ... moves a point
    _argsort_reversing_ties(monkeypatch)
    elsewhere = anchoring.cluster_labels(TIED_FEATURES, settings)
    np.testing.assert_array_equal(here, elsewhere)
    assert set(here) == {0, 1}


@pytest.mark.parametrize("mode, value", [("lower_bound", 4.5), ("midpoint", 6.0)])
def test_prediction_gain_is_the_decoded_class(mode, value):
    depth, mask, _ = edge_view([(0, 100)])
    distance = np.where(mask, 0.0, 10.0).astype(np.float32)
    gain_class = np.full(mask.shape, 5, np.uint8)  # 4.5 to 7.5 m^3
    frontiers = anchor_prediction(distance, gain_class, depth, K, POSE, _conf(gain_decoding=mode), LABELS)
    assert len(frontiers) == 1 and frontiers[0].gain_m3 == pytest.approx(value)


def test_expected_decoding_weighs_the_class_midpoints_by_the_network_probabilities():
    depth, mask, _ = edge_view([(0, 100)])
    distance = np.where(mask, 0.0, 10.0).astype(np.float32)
    gain_class = np.full(mask.shape, 5, np.uint8)
    logits = np.full((11, *mask.shape), -30.0, np.float32)
    logits[5] = logits[7] = 0.0  # half 6.0 m^3 (class 5's midpoint), half 12.5 m^3 (class 7's)
    conf = _conf(gain_decoding="expected")
    frontiers = anchor_prediction(distance, gain_class, depth, K, POSE, conf, LABELS, gain_logits=logits)
    assert len(frontiers) == 1 and frontiers[0].gain_m3 == pytest.approx(9.25, rel=1e-5)
    # no logits (labels, a class known for certain): the midpoint
    assert anchor_prediction(distance, gain_class, depth, K, POSE, conf, LABELS)[0].gain_m3 == pytest.approx(6.0)


def test_expected_decoding_keeps_class_0_pixels_at_0_and_reads_only_the_asked_pixels():
    classes = np.array([[0, 5, 5]])
    logits = np.zeros((11, 1, 3), np.float32)  # every class alike: the mean of the midpoints
    mean = float(np.mean(decode_gain(np.arange(11), EDGES, 0.01, "midpoint")))
    np.testing.assert_allclose(decode_gain(classes, EDGES, 0.01, "expected", logits), [[0, mean, mean]], rtol=1e-6)
    where = np.array([[True, True, False]])
    np.testing.assert_allclose(decode_gain(classes, EDGES, 0.01, "expected", logits, where), [[0, mean, 6.0]],
                               rtol=1e-6)
    with pytest.raises(InputError, match="gain logits"):
        decode_gain(classes, EDGES, 0.01, "expected", logits[:, :, :2])


def test_prediction_threshold_comes_from_the_config_or_the_labels():
    depth, mask, _ = edge_view([(0, 100)])
    distance = np.where(mask, 0.8, 10.0).astype(np.float32)
    gain_class = np.full(mask.shape, 3, np.int64)
    assert len(anchor_prediction(distance, gain_class, depth, K, POSE, _conf(frontier_threshold_px="null"),
                                 {**LABELS, "frontier_threshold_px": 1.0})) == 1
    assert anchor_prediction(distance, gain_class, depth, K, POSE, _conf(frontier_threshold_px=0.3), LABELS) == []


def test_gain_decoding_lower_bound_and_midpoint():
    classes = np.array([[0, 1, 2], [9, 10, 10]])
    np.testing.assert_allclose(decode_gain(classes, EDGES, 0.01, "lower_bound"), [[0, 0.01, 0.5], [20, 25, 25]])
    np.testing.assert_allclose(decode_gain(classes, EDGES, 0.01, "midpoint"),
                               [[0, 0.255, 1.0], [22.5, 30, 30]], rtol=1e-6)
    assert decode_gain(classes, EDGES).dtype == np.float32
    np.testing.assert_allclose(decode_gain(np.arange(11), EDGES), class_lower_bounds(EDGES), rtol=1e-6)
    # a midpoint falls back into its own class
    every = np.arange(11)
    np.testing.assert_array_equal(gain_classes(decode_gain(every, EDGES, 0.01, "midpoint"), EDGES), every)


def test_datagen_reexports_the_library_gain_classes():
    from datagen import labels

    assert labels.gain_classes is gain_classes and labels.class_lower_bounds is class_lower_bounds


@pytest.mark.parametrize("call, message", [
    (lambda: decode_gain(np.array([11]), EDGES), "gain classes"),
    (lambda: decode_gain(np.array([1.0]), EDGES), "integers"),
    (lambda: decode_gain(np.array([1]), EDGES, 0.01, "upper"), "lower_bound"),
    (lambda: decode_gain(np.array([1]), [5, 1]), "bin_edges"),
])
def test_bad_gain_decoding_inputs_are_named(call, message):
    with pytest.raises(InputError, match=message):
        call()


def _bad_inputs():
    depth, mask, gain = edge_view([(0, 100)])
    nan_K, sheared = K.copy(), POSE.copy()
    nan_K[0, 0] = np.nan
    sheared[0, 1] = 0.5
    return {
        "mask_shape": ((mask[None], gain, depth, K, POSE), "frontier_mask"),
        "gain_shape": ((mask, gain[:, :-1], depth, K, POSE), "gain_m3"),
        "depth_shape": ((mask, gain, depth[:-1], K, POSE), "depth"),
        "gain_nan": ((mask, np.where(mask, np.nan, gain), depth, K, POSE), "gain_m3"),
        "mask_float": ((mask.astype(float), gain, depth, K, POSE), "frontier_mask"),
        "K_shape": ((mask, gain, depth, K[:2], POSE), "K"),
        "K_nan": ((mask, gain, depth, nan_K, POSE), "K"),
        "pose_nan": ((mask, gain, depth, K, np.full((4, 4), np.nan)), "T_world_cam"),
        "pose_sheared": ((mask, gain, depth, K, sheared), "T_world_cam"),
    }


@pytest.mark.parametrize("name", list(_bad_inputs()))
def test_bad_inputs_raise_input_error(conf, name):
    args, message = _bad_inputs()[name]
    with pytest.raises(InputError, match=message):
        anchor_frontiers(*args, conf)


def test_bad_prediction_inputs_and_settings_are_named(conf):
    depth, mask, _ = edge_view([(0, 100)])
    distance = np.where(mask, 0.0, 10.0).astype(np.float32)
    classes = np.ones(mask.shape, np.int64)
    with pytest.raises(InputError, match="gain_class"):
        anchor_prediction(distance, classes[:, :5], depth, K, POSE, conf, LABELS)
    with pytest.raises(InputError, match="bin_edges"):
        anchor_prediction(distance, classes, depth, K, POSE, conf, {"frontier_threshold_px": 0.5})
    for override, message in [("gradient_kernel_px=8", "gradient_kernel_px"), ("cluster_gain=median", "cluster_gain"),
                              ("hdbscan.min_samples=0", "min_samples"), ("feature_weights.pixel=-1", "pixel")]:
        key, value = override.split("=")
        with pytest.raises(InputError, match=message):
            anchor_frontiers(mask, np.ones(mask.shape, np.float32), depth, K, POSE,
                             load_config("explore", overrides=[f"anchoring.{key}={value}"]).anchoring)


# -- end to end: ground truth of a rendered view through a doorway -------------------------------------

@pytest.fixture(scope="module")
def doorway_frontiers():
    """Ground-truth labels of a 240 px view from room A through the door into room B (which the
    6 m range covers, so every frontier comes from the door's occlusion), anchored."""
    lower, upper = room_boxes(6.0, 4.0, 2.5)
    (px0, px1), (dy0, dy1) = TWO_ROOM["partition_x"], TWO_ROOM["door_y"]
    lower += [(px0, 0, 0), (px0, dy1, 0), (px0, dy0, TWO_ROOM["door_height"])]
    upper += [(px1, dy0, 2.5), (px1, 4.0, 2.5), (px1, dy1, 2.5)]
    scene = box_scene(lower, upper, "two-room")
    gt_conf = load_datagen_config(overrides=["camera.max_depth=6.0", "camera.width=240", "camera.height=240",
                                             "camera.focal_px=150"])
    pose = pose_from_heading(1.0, 1.95, 1.2, yaw=0.0)
    truth = GroundTruthGenerator(scene, voxelize_scene(scene, gt_conf.voxels), gt_conf)(pose, np.random.default_rng(0))
    gain = gt_conf.ground_truth.gain
    labels = {"bin_edges": list(gain.bin_edges), "bin_unit_m3": float(gain.bin_unit_m3), "frontier_threshold_px": 0.5}
    frontiers = anchor_prediction(truth.distance_field, truth.gain_class, truth.depth, truth.K, pose,
                                  load_config("explore").anchoring, labels)
    return scene, pose, frontiers


def test_ground_truth_doorway_gives_frontiers_on_the_door_jambs(doorway_frontiers):
    scene, pose, frontiers = doorway_frontiers
    origin = pose[:3, 3]
    (_, px1), (dy0, dy1) = TWO_ROOM["partition_x"], TWO_ROOM["door_y"]
    for jamb_y, side in ((dy1, +1.0), (dy0, -1.0)):  # left jamb (+y) hides room B's +y part, and vice versa
        corner = np.array([TWO_ROOM["partition_x"][0], jamb_y])
        edge_ray = (corner - origin[:2]) / np.linalg.norm(corner - origin[:2])
        near = []
        for f in frontiers:
            offset = f.position[:2] - origin[:2]
            off_ray = abs(offset[0] * edge_ray[1] - offset[1] * edge_ray[0])  # distance to the jamb's edge ray
            if off_ray < 0.2 and px1 < f.position[0] < 6.0 and f.position[2] < TWO_ROOM["door_height"]:
                near.append(f)
        assert near, f"no frontier on the edge ray of the jamb at y = {jamb_y}"
        f = max(near, key=lambda f: f.num_pixels)
        assert f.gain_m3 > 0 and f.direction[0] > 0.3 and side * f.direction[1] > 0.3
        # a step along the view direction is space the camera did not see (behind the partition)
        target = f.position + 0.5 * f.direction
        ray = np.concatenate([origin, target - origin])[None].astype(np.float32)
        assert cast_rays(scene, ray)["t_hit"][0] < 1.0

"""Ground truth checked against the geometry: doorway edges, the distance field, gains."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import TWO_ROOM, box_scene, room_boxes
from datagen.config import load_datagen_config
from datagen.ground_truth import GroundTruthGenerator
from datagen.labels import discontinuity_mask, distance_field, gain_classes
from frontiernet.errors import InputError
from frontiernet.geometry import pose_from_heading, rotation_from_yaw_pitch
from frontiernet.simulator.raycast import cast_rays
from frontiernet.simulator.voxels import voxelize_scene

CAMERA = (1.0, 1.95, 1.2)  # in room A of the two-room scene, level with the door's centre line


@pytest.fixture(scope="module")
def doorway(two_room_scene, two_room_voxels):
    """Ground truth looking from room A through the door; the range covers room B entirely,
    so every frontier comes from the door's occlusion."""
    conf = load_datagen_config(overrides=["camera.max_depth=6.0"])
    generator = GroundTruthGenerator(two_room_scene, two_room_voxels, conf)
    truth = generator(pose_from_heading(*CAMERA, yaw=0.0), np.random.default_rng(0))
    return generator, truth


def _project(generator, points):
    """World points -> (N, 2) pixel (u, v) for the doorway camera."""
    T = pose_from_heading(*CAMERA, yaw=0.0)
    cam = (np.asarray(points, float) - T[:3, 3]) @ T[:3, :3]
    K = generator.camera.K
    return np.stack([K[0, 0] * cam[:, 0] / cam[:, 2] + K[0, 2], K[1, 1] * cam[:, 1] / cam[:, 2] + K[1, 2]], 1)


def _segment_distance(points, a, b):
    ab = b - a
    t = np.clip(((points - a) @ ab) / (ab @ ab), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * ab), axis=1)


def test_frontier_pixels_lie_on_the_doorway_edges(doorway):
    generator, truth = doorway
    F = truth.frontier_mask
    assert F.sum() > 200
    (px0, px1), (y0, y1), top = TWO_ROOM["partition_x"], TWO_ROOM["door_y"], TWO_ROOM["door_height"]
    edges = []  # the door opening's outline on both faces of the partition: jambs and lintel
    for x in (px0, px1):
        corners = _project(generator, [(x, y0, 0.0), (x, y0, top), (x, y1, top), (x, y1, 0.0)])
        edges += [(corners[i], corners[i + 1]) for i in range(3)]
    v, u = np.nonzero(F)
    pixels = np.stack([u, v], 1).astype(float)
    distance = np.min([_segment_distance(pixels, a, b) for a, b in edges], axis=0)
    assert np.mean(distance <= 3.0) > 0.95, f"{np.mean(distance <= 3.0):.3f} of F within 3 px of the door outline"
    # both jambs and the lintel carry frontier pixels
    left, right = _project(generator, [(px1, y1, 1.0), (px1, y0, 1.0)])[:, 0]
    assert np.any(np.abs(u - left) < 4) and np.any(np.abs(u - right) < 4)
    lintel = _project(generator, [(px1, 1.95, top)])[0, 1]
    assert np.any(np.abs(v - lintel) < 4)
    # nothing away from the door: the walls of room A have no frontier pixels
    assert not F[:, : int(left) - 10].any() and not F[:, int(right) + 10:].any()


def test_distance_field_is_zero_on_F_and_grows_one_pixel_per_pixel(doorway):
    _, truth = doorway
    D, F = truth.distance_field, truth.frontier_mask
    assert np.all(D[F] == 0.0)
    assert np.all(D[~F] >= 1.0) and D.max() == pytest.approx(10.0)
    # the left jamb is a vertical line of F: leftwards from it D goes 1, 2, 3, ... up to r
    row = 240
    column = np.flatnonzero(F[row])[0]
    np.testing.assert_allclose(D[row, column - np.arange(1, 10)], np.arange(1, 10))
    assert D[row, column - 15] == 10.0


@pytest.mark.parametrize("volume", ["unobserved", "occluded"])
def test_doorway_gain_is_the_second_rooms_volume_seen_from_it(two_room_scene, two_room_voxels, volume):
    # seen at an angle, the door hides most of room B: its frontier voxels face +x
    camera, yaw = np.array([1.0, 0.6, 1.2]), np.arctan2(1.95 - 0.6, 2.0)
    conf = load_datagen_config(overrides=[f"ground_truth.gain.volume={volume}"])
    generator = GroundTruthGenerator(two_room_scene, two_room_voxels, conf)
    truth = generator(pose_from_heading(*camera, yaw=yaw), np.random.default_rng(0))
    voxels, gains = truth.frontier_voxels, truth.frontier_voxel_gain
    px0, px1 = TWO_ROOM["partition_x"]
    in_door = truth.gain_sampled & (voxels[:, 0] > px0) & (voxels[:, 0] < px1 + 0.15) \
        & (np.abs(voxels[:, 2] - 1.2) < 0.4)
    assert in_door.any()
    voxel, gain = voxels[in_door][0], gains[in_door][0]
    # independent Monte Carlo estimate: random points of the building that the mesh (not the
    # voxels) shows to a camera at the voxel and hides from the first camera, best heading
    # among those looking into room B
    rng = np.random.default_rng(1)
    lo, hi = TWO_ROOM["interior"]
    points = lo + rng.random((60000, 3)) * (hi - lo)
    (y0, y1), top = TWO_ROOM["door_y"], TWO_ROOM["door_height"]
    in_wall = (points[:, 0] > px0) & (points[:, 0] < px1) \
        & ~((points[:, 1] > y0) & (points[:, 1] < y1) & (points[:, 2] < top))
    volume_per_point = (hi - lo).prod() / len(points)
    points = points[~in_wall]
    K, cam_ = generator.camera.K, generator.camera

    def seen(origin, R):
        cam = (points - origin) @ R
        with np.errstate(divide="ignore", invalid="ignore"):
            u = K[0, 0] * cam[:, 0] / cam[:, 2] + K[0, 2]
            v = K[1, 1] * cam[:, 1] / cam[:, 2] + K[1, 2]
        inside = (cam[:, 2] > 0) & (cam[:, 2] <= cam_.max_depth) & (u >= -0.5) & (u <= cam_.width - 0.5) \
            & (v >= -0.5) & (v <= cam_.height - 0.5)
        rays = np.concatenate([np.broadcast_to(origin, points.shape), points - origin], 1)
        return inside & (cast_rays(two_room_scene, rays)["t_hit"] >= 0.999)

    unseen = ~seen(camera, rotation_from_yaw_pitch(yaw))
    if volume == "occluded":  # ... and only what lies in the first camera's frustum (any depth)
        cam = (points - camera) @ rotation_from_yaw_pitch(yaw)
        with np.errstate(divide="ignore", invalid="ignore"):
            u, v = K[0, 0] * cam[:, 0] / cam[:, 2] + K[0, 2], K[1, 1] * cam[:, 1] / cam[:, 2] + K[1, 2]
        unseen &= (cam[:, 2] > conf.ground_truth.near_clip_m) & (u >= -0.5) & (u <= cam_.width - 0.5) \
            & (v >= -0.5) & (v <= cam_.height - 0.5)
    best = max(np.sum(seen(voxel, rotation_from_yaw_pitch(np.deg2rad(heading))) & unseen) * volume_per_point
               for heading in range(-90, 91, 5))
    assert best > 5.0  # a good part of room B (29 m^3) is visible from the door
    assert 0.75 * best <= gain <= 1.1 * best, f"voxel gain {gain:.2f} m^3, Monte Carlo best view {best:.2f} m^3"


def test_big_room_behind_a_door_has_more_gain_than_a_closet():
    def scene_with_room_behind(depth: float):
        lower, upper = room_boxes(3.0 + depth, 4.0, 2.5)
        lower += [(2.9, 0, 0), (2.9, 2.4, 0), (2.9, 1.5, 2.0)]
        upper += [(3.1, 1.5, 2.5), (3.1, 4.0, 2.5), (3.1, 2.4, 2.5)]
        if depth < 2:  # a closet: narrow in y as well
            lower += [(3.1, 0, 0), (3.1, 2.9, 0)]
            upper += [(3.0 + depth, 1.0, 2.5), (3.0 + depth, 4.0, 2.5)]
        return box_scene(lower, upper, f"behind-{depth}")

    conf = load_datagen_config()
    gains = []
    for depth in (5.0, 0.8):
        scene = scene_with_room_behind(depth)
        generator = GroundTruthGenerator(scene, voxelize_scene(scene, conf.voxels), conf)
        truth = generator(pose_from_heading(1.2, 1.95, 1.2, yaw=0.0), np.random.default_rng(0))
        assert truth.frontier_mask.any()
        gains.append(float(np.median(truth.gain[truth.frontier_mask])))
    big, closet = gains
    assert big > 3 * closet
    assert gain_classes(big, conf.ground_truth.gain.bin_edges) > gain_classes(closet, conf.ground_truth.gain.bin_edges)


def test_closed_room_seen_whole_has_no_frontier_pixels():
    scene = box_scene(*room_boxes(3.0, 3.0, 2.5), "closed-room")
    conf = load_datagen_config()
    generator = GroundTruthGenerator(scene, voxelize_scene(scene, conf.voxels), conf)
    truth = generator(pose_from_heading(0.4, 1.5, 1.2, yaw=0.0, pitch=-0.1), np.random.default_rng(0))
    assert np.isfinite(truth.depth).all()  # every wall within range
    assert not truth.frontier_mask.any()
    assert not truth.frontier_projected.any()  # behind the camera is out of view, not a frontier
    assert np.all(truth.distance_field == 10.0) and not truth.gain_class.any()


def test_ground_truth_keeps_the_rendered_view(doorway, two_room_scene):
    generator, truth = doorway
    frame = generator.renderer.render(truth.T_world_cam)
    np.testing.assert_array_equal(truth.rgb, frame.rgb)
    np.testing.assert_array_equal(truth.depth, frame.depth)
    assert truth.gain.dtype == np.float32 and truth.gain_class.dtype == np.int64
    assert np.all(truth.gain[truth.gain_class == 0] <= 0.01)


def test_same_seed_same_ground_truth(two_room_scene, two_room_voxels):
    generator = GroundTruthGenerator(two_room_scene, two_room_voxels, load_datagen_config())
    T = pose_from_heading(*CAMERA, yaw=0.2)
    a = generator(T, np.random.default_rng(5))
    b = generator(T, np.random.default_rng(5))
    for key, value in a.arrays().items():
        np.testing.assert_array_equal(value, b.arrays()[key], err_msg=key)


def test_discontinuity_marks_occlusion_edges_not_slanted_floors():
    v = np.arange(200, dtype=np.float32)[:, None]
    floor = np.broadcast_to(300 * 1.0 / np.maximum(v - 99.5, 1e-3), (200, 200)).astype(np.float32)
    floor = np.where(floor <= 3.5, floor, np.nan).astype(np.float32)
    disc = load_datagen_config().ground_truth.discontinuity
    rule = (int(disc.window_px), float(disc.relative_jump), float(disc.min_jump_m))
    mask = discontinuity_mask(floor, *rule, invalid_is_far=False)
    assert not mask[110:].any()  # a floor seen from 1 m up: smooth
    step = np.full((50, 50), 3.0, np.float32)
    step[:, 25:] = 1.5  # a door frame in front of a wall
    mask = discontinuity_mask(step, *rule, bool(disc.invalid_is_far))
    assert mask[:, 24:26].all() and not mask[:, :23].any() and not mask[:, 27:].any()


def test_gain_classes_use_the_public_bin_edges():
    edges = [1, 50, 150, 300, 450, 750, 1000, 1500, 2000, 2500, 3500]
    gains = np.array([0.0, 0.01, 0.0101, 0.5, 0.51, 25.0, 30.0, 35.0, 100.0])
    np.testing.assert_array_equal(gain_classes(gains, edges), [0, 0, 1, 1, 2, 9, 10, 10, 10])


def test_distance_field_of_an_empty_mask_is_r_everywhere():
    assert np.all(distance_field(np.zeros((8, 9), bool), 10.0) == 10.0)


@pytest.mark.parametrize("override, message", [
    ("ground_truth.observe_stride_px=0", "observe_stride_px"),
    ("ground_truth.frontier_connectivity=8", "frontier_connectivity"),
    ("ground_truth.r_ray_m=-1", "r_ray_m"),
    ("ground_truth.gain.label_region=everywhere", "label_region"),
    ("ground_truth.gain.volume=behind", "ground_truth.gain.volume"),
    ("ground_truth.gain.spread=smooth", "ground_truth.gain.spread"),
])
def test_bad_ground_truth_settings_are_named(two_room_scene, two_room_voxels, override, message):
    with pytest.raises(InputError, match=message):
        generator = GroundTruthGenerator(two_room_scene, two_room_voxels, load_datagen_config(overrides=[override]))
        generator(pose_from_heading(*CAMERA, yaw=0.0), np.random.default_rng(0))


def _angled_door_truth(scene, voxels, *overrides):
    generator = GroundTruthGenerator(scene, voxels, load_datagen_config(overrides=list(overrides)))
    return generator(pose_from_heading(1.0, 0.6, 1.2, yaw=np.arctan2(1.95 - 0.6, 2.0)), np.random.default_rng(0))


def test_occluded_gain_is_the_part_of_the_unobserved_gain_in_view(two_room_scene, two_room_voxels):
    unobserved = _angled_door_truth(two_room_scene, two_room_voxels)
    occluded = _angled_door_truth(two_room_scene, two_room_voxels, "ground_truth.gain.volume=occluded")
    # the same frontier voxels and samples (the definition changes no random draw)
    np.testing.assert_array_equal(unobserved.frontier_voxels, occluded.frontier_voxels)
    np.testing.assert_array_equal(unobserved.gain_sampled, occluded.gain_sampled)
    sampled = unobserved.gain_sampled
    a, b = unobserved.frontier_voxel_gain[sampled], occluded.frontier_voxel_gain[sampled]
    assert np.all(b <= a + 1e-4)  # a subset of the counted voxels
    assert np.any(b < a - 0.05)  # the parts of room A this view missed no longer count ...
    assert b.max() > 5.0  # ... room B behind the door still does (its share: the Monte Carlo test above)


def test_region_spread_gives_each_connected_frontier_one_gain(two_room_scene, two_room_voxels):
    from scipy import ndimage

    truth = _angled_door_truth(two_room_scene, two_room_voxels, "ground_truth.gain.spread=region")
    voxels, gains = truth.frontier_voxels, truth.frontier_voxel_gain
    grid = np.rint((voxels - voxels.min(0)) / 0.1).astype(int)
    occupied = np.zeros(grid.max(0) + 1, bool)
    occupied[tuple(grid.T)] = True
    labelled, count = ndimage.label(occupied, ndimage.generate_binary_structure(3, 3))
    region = labelled[tuple(grid.T)]
    assert count >= 1
    for r in range(1, count + 1):
        inside = region == r
        assert truth.gain_sampled[inside].any()  # every region is measured (fewer regions than samples)
        assert np.allclose(gains[inside], gains[inside & truth.gain_sampled].max())
    blended = _angled_door_truth(two_room_scene, two_room_voxels)
    assert not np.allclose(blended.frontier_voxel_gain, gains)


def test_default_gain_definition_keeps_the_dataset_hash():
    from datagen.config import config_hash

    conf = load_datagen_config()
    bare = load_datagen_config()
    del bare.ground_truth.gain["volume"], bare.ground_truth.gain["spread"]
    assert config_hash(conf) == config_hash(bare)  # datasets made before the keys still resume
    assert config_hash(load_datagen_config(overrides=["ground_truth.gain.spread=region"])) != config_hash(conf)

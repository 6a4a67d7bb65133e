"""GLEAM's exploration metrics (frontiernet/exploration/surface.py): surface coverage, AUC, Chamfer."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import box_scene, explore_section, room_boxes, scenes_config, sim_section
from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.exploration.surface import SurfaceCoverage, coverage_auc, even_surface_samples
from frontiernet.geometry import pose_from_heading
from frontiernet.mapping import OccupancyMap
from frontiernet.simulator.camera import PinholeCamera, Renderer
from frontiernet.simulator.voxels import voxelize_scene

# a closed room, interior [0, 4] x [0, 3] x [0, 2.5] m, walls, floor and ceiling 0.25 m thick
ROOM = (4.0, 3.0, 2.5)
SMALL = PinholeCamera(120, 120, 75.0, 75.0, 59.5, 59.5, 3.5)  # the paper's field of view, 120 px
EYE = (0.8, 1.5, 1.2)  # one frame from here along +x: the wall x = 4 is 3.2 m away, within range


def surface_conf(**changes) -> dict:
    return explore_section("surface", **{"num_points": 4000, **changes})


@pytest.fixture(scope="module")
def room():
    lower, upper = room_boxes(*ROOM, wall=0.25)
    scene = box_scene(lower, upper, "surface-room")
    voxels = voxelize_scene(scene, sim_section("voxels"))
    return scene, voxels, SurfaceCoverage(scene, surface_conf(), seed=0, voxels=voxels), Renderer(scene, SMALL, (0, 0, 0))


def mapped(room, poses, like_voxels: bool = True) -> OccupancyMap:
    _, voxels, _, renderer = room
    conf = load_config("explore").map
    occupancy = OccupancyMap.like(voxels, conf) if like_voxels else \
        OccupancyMap.from_bounds(np.array([[-0.5, -0.5, -0.5], [4.5, 3.5, 3.0]]), conf)
    for T in poses:
        frame = renderer.render(T)
        occupancy.integrate(frame.depth, frame.K, T)
    return occupancy


def full_turn():
    """Level, up- and down-looking frames every 30 degrees from the room's middle."""
    return [pose_from_heading(2.0, 1.5, 1.2, np.radians(yaw), np.radians(pitch))
            for pitch in (-50.0, 0.0, 50.0) for yaw in range(0, 360, 30)]


# -- samples ------------------------------------------------------------------------------------------


def test_samples_are_the_inner_faces_only(room):
    _, _, surface, _ = room
    points = surface.points
    assert points.dtype == np.float64 and points.shape == (surface.num_samples, 3)
    assert surface.num_sampled == 4000 and 0.2 * 4000 < surface.num_samples < 0.8 * 4000  # outer faces dropped
    # all on the interior's 6 faces, but for a few on box faces hidden in the walls (the boxes
    # overlap) in the same voxels as the inner faces: within half a voxel of the interior (plus the
    # explorable filter's 1 % probes)
    upper, half_voxel = np.array(ROOM), 0.051 + 1e-6
    assert np.all(points >= -half_voxel) and np.all(points <= upper + half_voxel)
    on_face = np.minimum(np.abs(points), np.abs(points - upper)).min(axis=1)
    assert np.all(on_face < half_voxel) and np.mean(on_face < 1e-6) > 0.95
    for axis in range(3):
        for value in (0.0, upper[axis]):
            share = np.mean(np.abs(points[:, axis] - value) < 1e-6)
            area = np.prod(np.delete(upper, axis)) / (2 * (12.0 + 7.0 * 2.5))
            assert share == pytest.approx(area, abs=0.03), (axis, value)  # evenly spread over the area
    with pytest.raises(ValueError):
        points[0, 0] = 1.0  # read-only


def test_samples_are_evenly_spaced_and_deterministic(room):
    scene, voxels, surface, _ = room
    again = SurfaceCoverage(scene, surface_conf(), seed=0, voxels=voxels)
    np.testing.assert_array_equal(again.points, surface.points)
    other = SurfaceCoverage(scene, surface_conf(), seed=1, voxels=voxels)
    assert not np.array_equal(other.points[:50], surface.points[:50])
    points = even_surface_samples(scene.vertices, scene.triangles, 2000, seed=3)
    assert points.shape == (2000, 3)
    from scipy.spatial import cKDTree

    spacing, _ = cKDTree(points).query(points, k=2)  # Poisson disk: no two samples close together
    assert spacing[:, 1].min() > 0.5 * np.sqrt(float(scene.triangle_areas().sum()) / (5 * 2000))


# -- coverage and Chamfer -------------------------------------------------------------------------------


def test_empty_map_covers_nothing(room):
    _, voxels, surface, _ = room
    empty = OccupancyMap.like(voxels, load_config("explore").map)
    assert surface.covered_fraction(empty) == 0.0
    assert surface.chamfer(empty) == {"chamfer_m": float("inf"), "completeness": 0.0}
    far = OccupancyMap.from_bounds(np.array([[50.0, 50.0, 0.0], [51.0, 51.0, 1.0]]), load_config("explore").map)
    assert surface.covered_fraction(far) == 0.0  # a map off the samples' grid


def test_full_turn_covers_the_room_and_reconstructs_it(room):
    _, _, surface, _ = room
    occupancy = mapped(room, full_turn())
    covered = surface.covered_fraction(occupancy)
    assert covered > 0.8
    chamfer = surface.chamfer(occupancy)
    assert chamfer["chamfer_m"] < 0.1 and chamfer["completeness"] > 0.8
    # the same frames in a map over another grid cover the same surface, about
    assert surface.covered_fraction(mapped(room, full_turn(), like_voxels=False)) == pytest.approx(covered, abs=0.03)
    scene, voxels, _, _ = room
    strict = SurfaceCoverage(scene, surface_conf(tolerance_voxels=0), seed=0, voxels=voxels)
    assert 0.5 < strict.covered_fraction(occupancy) <= covered  # the own voxel only: fewer


def test_one_frame_covers_what_the_camera_sees(room):
    _, _, surface, _ = room
    T = pose_from_heading(*EYE, 0.0)
    occupancy = mapped(room, [T])
    covered = surface.covered_mask(occupancy)
    assert covered.dtype == bool and covered.shape == (surface.num_samples,)
    assert 0.05 < surface.covered_fraction(occupancy) < 0.6  # 0.43: the far wall, floor and ceiling ahead
    points = surface.points
    ahead = (points[:, 0] > 4.0 - 1e-6) & (np.abs(points[:, 1] - EYE[1]) < 0.8) & (np.abs(points[:, 2] - EYE[2]) < 0.8)
    assert ahead.sum() > 10 and covered[ahead].all()  # the wall in front, the image's middle
    behind = points[:, 0] < EYE[0] - 0.2
    assert behind.sum() > 10 and not covered[behind].any()
    # every covered sample lies in the view (camera frame: z forward), up to the tolerance voxel
    local = (points[covered] - T[:3, 3]) @ T[:3, :3]
    half = np.tan(np.radians(SMALL.horizontal_fov_deg / 2))
    assert np.all(local[:, 2] > 0) and np.all(np.abs(local[:, :2]) <= local[:, 2:] * half + 0.2)
    chamfer = surface.chamfer(occupancy)
    assert 0.1 < chamfer["chamfer_m"] < np.inf and 0.05 < chamfer["completeness"] < 0.6


def test_covered_fraction_grows_with_frames(room):
    _, _, surface, _ = room
    poses = full_turn()
    fractions = [surface.covered_fraction(mapped(room, poses[:n])) for n in (0, 1, 6, 36)]
    assert fractions == sorted(fractions) and fractions[0] == 0.0


# -- AUC ------------------------------------------------------------------------------------------------


def test_auc_of_constant_ramp_and_early_stop():
    assert coverage_auc(np.full(11, 0.4), 10) == pytest.approx(0.4)
    assert coverage_auc(np.linspace(0.0, 1.0, 101), 100) == pytest.approx(0.5)
    assert coverage_auc([0.7], 50) == pytest.approx(0.7)  # stopped at once: holds its only value
    # stopped after 2 of 4 steps: the last value is held to the budget
    assert coverage_auc([0.0, 0.5, 1.0], 4) == pytest.approx(coverage_auc([0.0, 0.5, 1.0, 1.0, 1.0], 4)) \
        == pytest.approx((0.25 + 0.75 + 1.0 + 1.0) / 4)
    assert 0.0 <= coverage_auc(np.random.default_rng(0).random(30), 40) <= 1.0


# -- bad inputs -----------------------------------------------------------------------------------------


@pytest.mark.parametrize("changes, named", [
    ({"num_points": 0}, "surface.num_points"), ({"num_points": 1.5}, "surface.num_points"),
    ({"num_points": True}, "surface.num_points"), ({"tolerance_voxels": -1}, "surface.tolerance_voxels"),
    ({"tolerance_voxels": 4}, "surface.tolerance_voxels"),
    ({"max_distance_to_explorable_m": -0.1}, "surface.max_distance_to_explorable_m"),
    ({"completeness_threshold_m": 0}, "surface.completeness_threshold_m"),
    ({"completeness_threshold_m": float("nan")}, "surface.completeness_threshold_m"),
    ({"max_distance_to_explorable_m": 0.001}, "no surface sample"),
])
def test_bad_config_raises_input_error(room, changes, named):
    scene, voxels, _, _ = room
    with pytest.raises(InputError, match=named):
        SurfaceCoverage(scene, surface_conf(**changes), seed=0, voxels=voxels)


def test_bad_inputs_raise_input_error(room):
    scene, voxels, surface, _ = room
    conf = surface_conf()
    del conf["tolerance_voxels"]
    with pytest.raises(InputError, match="tolerance_voxels"):
        SurfaceCoverage(scene, conf, seed=0, voxels=voxels)
    with pytest.raises(InputError, match="seed"):
        SurfaceCoverage(scene, surface_conf(), seed=-1, voxels=voxels)
    with pytest.raises(InputError, match="coverage_map must be an OccupancyMap"):
        surface.covered_fraction(np.zeros((3, 3, 3), bool))
    with pytest.raises(InputError, match="robot_map must be an OccupancyMap"):
        surface.chamfer(None)
    for fractions, steps, named in [([], 10, "non-empty"), (np.zeros((2, 2)), 10, "1D"), ([0.2, 1.5], 10, r"\[0, 1\]"),
                                    ([0.2, np.nan], 10, r"\[0, 1\]"), ([-0.1], 10, r"\[0, 1\]"),
                                    (np.zeros(12), 10, "max_steps \\+ 1 = 11"), ([0.5], 0, "max_steps"),
                                    ([0.5], 2.5, "max_steps")]:
        with pytest.raises(InputError, match=named):
            coverage_auc(fractions, steps)


def test_shared_house(shared_data):
    from frontiernet.scenes import load_scene

    path = shared_data / "scenes" / "aws_small_house.glb"
    if not path.is_file():
        pytest.skip(f"{path} not found")
    scene = load_scene(str(path), scenes_config())
    surface = SurfaceCoverage(scene, load_config("explore"), seed=0,
                              voxels=voxelize_scene(scene, sim_section("voxels")))
    assert surface.num_sampled == 20000 and 0.5 * 20000 < surface.num_samples < 0.95 * 20000
    voxels_conf = load_config("explore").map
    assert surface.covered_fraction(OccupancyMap.from_bounds(scene.bounds, voxels_conf)) == 0.0

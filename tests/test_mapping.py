"""The 3D log-odds occupancy map, checked on real depth frames of a closed room."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from conftest import box_scene, room_boxes, sim_section
from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.geometry import pose_from_heading
from frontiernet.mapping import FREE, OCCUPIED, UNKNOWN, OccupancyMap, depth_edges, frustum_volume
from frontiernet.simulator.camera import PinholeCamera, Renderer
from frontiernet.simulator.voxels import voxelize_scene

ROOM = (4.0, 3.0, 2.5)  # interior [0, 4] x [0, 3] x [0, 2.5] m
WALL = 0.25  # thick walls: the scene grid's corner (bounds - 0.2 m margin) is half a voxel off the faces
CAMERA = (1.0, 1.5, 1.2)  # looks along +x at the wall x = 4, 3 m away (within the 3.5 m range)
# voxel boundaries half a voxel off the walls' faces: each face lies inside one voxel layer
BOUNDS = np.array([[-0.45, -0.45, -0.45], [4.45, 3.45, 2.95]])
SMALL = PinholeCamera(120, 120, 75.0, 75.0, 59.5, 59.5, 3.5)  # the paper's field of view, 120 px


@pytest.fixture(scope="module")
def room():
    lower, upper = room_boxes(*ROOM, wall=WALL)
    return box_scene(lower, upper, "mapping-room")


@pytest.fixture(scope="module")
def renderer(room):
    return Renderer(room, SMALL, (0, 0, 0))


def map_conf(**changes) -> dict:
    conf = dict(load_config("explore").map)
    conf.update(changes)
    return conf


PLAIN_MONOCULAR = dict(monocular_log_odds_miss=None, monocular_max_incidence_deg=None)
"""The map keys of the monocular sensor model that are on by default, off: a monocular frame then
updates the map as the ground truth's does, but for the depth-edge filter."""


def integrated(renderer, poses, **changes) -> OccupancyMap:
    occupancy = OccupancyMap.from_bounds(BOUNDS, map_conf(**changes))
    for T in poses:
        frame = renderer.render(T)
        occupancy.integrate(frame.depth, frame.K, T)
    return occupancy


def surround_poses(position=CAMERA) -> list[np.ndarray]:
    """Level, up and down views in four headings: together they see the whole room."""
    return [pose_from_heading(*position, yaw=yaw, pitch=pitch)
            for yaw in np.deg2rad([0, 90, 180, 270]) for pitch in (-0.7, 0.0, 0.7)]


def test_one_frame_free_to_the_wall_occupied_wall_unknown_behind(renderer):
    T = pose_from_heading(*CAMERA, yaw=0.0)
    occupancy = integrated(renderer, [T])
    axis = [(x, 1.5, 1.2) for x in (1.0, 2.0, 3.0, 3.9, 4.0, 4.1, 4.3, 0.5)]
    assert occupancy.state_at(np.array(axis)).tolist() == [FREE, FREE, FREE, FREE, OCCUPIED, UNKNOWN, UNKNOWN,
                                                           UNKNOWN]
    # the whole visible face of the wall is occupied, the layer in front of it free (voxel centres)
    y, z = np.meshgrid(np.arange(1, 30) * 0.1, np.arange(1, 25) * 0.1, indexing="ij")
    face = np.stack([np.full(y.size, 4.0), y.ravel(), z.ravel()], 1)
    assert np.mean(occupancy.state_at(face) == OCCUPIED) > 0.98
    assert np.mean(occupancy.state_at(face - [0.1, 0, 0]) == FREE) > 0.98
    assert np.all(occupancy.state_at(face + [0.3, 0, 0]) == UNKNOWN)
    # one frame: hit and miss once
    i, j, k = occupancy.world_to_index(np.array([[4.0, 1.5, 1.2], [2.0, 1.5, 1.2]])).T
    np.testing.assert_allclose(occupancy.log_odds[i, j, k], [0.85, -0.4], rtol=1e-6)


def test_map_agrees_with_the_scene_voxels(room, renderer):
    voxels = voxelize_scene(room, sim_section("voxels"))
    occupancy = OccupancyMap.like(voxels, map_conf())
    for T in surround_poses()[::2]:
        frame = renderer.render(T)
        occupancy.integrate(frame.depth, frame.K, T)
    occupied, free = occupancy.occupied_mask(), occupancy.free_mask()
    assert occupied.sum() > 500 and free.sum() > 10000
    assert np.mean(voxels.occupied[occupied]) > 0.97, "occupied map voxels lie on the surface"
    # free map voxels lie in the interior (rays grazing the floor cross a few of its voxels before their hit)
    assert np.mean(voxels.explorable[free]) > 0.95


def test_known_volume_grows_and_stays_within_the_grid(renderer):
    occupancy = OccupancyMap.from_bounds(BOUNDS, map_conf())
    grid_m3 = np.prod(occupancy.shape) * occupancy.voxel_size ** 3
    volumes = [occupancy.known_volume_m3]
    for T in surround_poses():
        frame = renderer.render(T)
        occupancy.integrate(frame.depth, frame.K, T)
        volumes.append(occupancy.known_volume_m3)
        assert occupancy.known_volume_m3 == pytest.approx(occupancy.observed.sum() * occupancy.voxel_size ** 3)
    assert volumes[0] == 0 and np.all(np.diff(volumes) >= 0) and volumes[-1] <= grid_m3
    assert volumes[-1] > 0.8 * np.prod(ROOM), "the surround views see most of the room"
    assert np.all(occupancy.unknown_mask() == ~occupancy.observed)
    assert not np.any(occupancy.free_mask() & occupancy.occupied_mask())


def test_repeated_frames_saturate_at_the_clamp(renderer):
    conf = map_conf()
    T = pose_from_heading(*CAMERA, yaw=0.0)
    occupancy = integrated(renderer, [T] * 12)
    i, j, k = occupancy.world_to_index(np.array([[4.0, 1.5, 1.2], [2.0, 1.5, 1.2]])).T
    assert occupancy.log_odds[i, j, k].tolist() == pytest.approx([conf["log_odds_max"], conf["log_odds_min"]])
    assert occupancy.log_odds.max() <= conf["log_odds_max"] and occupancy.log_odds.min() >= conf["log_odds_min"]


def test_each_voxel_is_updated_once_per_frame_and_a_hit_wins():
    """Two nearly parallel rays: one ends in a voxel the other passes through."""
    occupancy = OccupancyMap.from_bounds(np.array([[-0.05, -1.05, -1.05], [4.05, 1.05, 1.05]]),
                                         map_conf(ray_stride_px=1))
    T = pose_from_heading(0.0, 0.0, 0.0, yaw=0.0)  # camera z = world +x
    K = np.array([[300.0, 0.0, 0.5], [0.0, 300.0, 0.0], [0.0, 0.0, 1.0]])
    occupancy.integrate(np.array([[2.0, 3.0]], np.float32), K, T)
    i, j, k = occupancy.world_to_index(np.array([[1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [3.0, 0.0, 0.0]])).T
    np.testing.assert_allclose(occupancy.log_odds[i, j, k], [-0.4, 0.85, 0.85], rtol=1e-6)


@pytest.mark.parametrize("invalid_depth", ["free", "skip"])
def test_invalid_and_out_of_range_depth(invalid_depth):
    occupancy = OccupancyMap.from_bounds(np.array([[-0.05, -3.05, -3.05], [6.05, 3.05, 3.05]]),
                                         map_conf(invalid_depth=invalid_depth))
    T = pose_from_heading(0.0, 0.0, 0.0, yaw=0.0)
    depth = np.full((60, 60), np.nan, np.float32)
    occupancy.integrate(depth, SMALL.K / 2 + np.diag([0, 0, 0.5]), T)
    states = occupancy.state_at(np.array([[1.0, 0, 0], [3.0, 0, 0], [3.7, 0, 0]]))
    if invalid_depth == "free":
        assert states.tolist() == [FREE, FREE, UNKNOWN], "invalid depth is free up to max_range_m"
    else:
        assert occupancy.known_volume_m3 == 0.0 and states.tolist() == [UNKNOWN] * 3
    beyond = OccupancyMap.from_bounds(occupancy.bounds, map_conf(invalid_depth=invalid_depth))
    beyond.integrate(np.full((60, 60), 10.0, np.float32), SMALL.K / 2 + np.diag([0, 0, 0.5]), T)
    assert beyond.state_at(np.array([[3.0, 0, 0], [3.7, 0, 0], [5.0, 0, 0]])).tolist() == [FREE, UNKNOWN, UNKNOWN]
    assert not beyond.occupied_mask().any(), "depth beyond the range is no hit"


def smeared_doorway() -> np.ndarray:
    """(60, 60) depth: a door frame at 1 m (columns < 28), the room behind at 3 m, and between
    them four columns smeared from one to the other as a monocular decoder does."""
    depth = np.full((60, 60), 3.0, np.float32)
    depth[:, :28] = 1.0
    depth[:, 28:32] = [1.4, 1.8, 2.2, 2.6]
    return depth


def test_depth_edges_are_the_discontinuities_not_slopes_or_invalid_pixels():
    sharp = np.full((20, 20), 3.0, np.float32)
    sharp[:, :10] = 1.0
    sharp[0, 0] = np.nan
    edges = depth_edges(sharp, 0.1)
    assert edges.dtype == bool and edges.shape == sharp.shape
    assert np.flatnonzero(edges[5]).tolist() == [9, 10], "the pixels either side of the jump"
    assert not edges[0, 0] and not edges[1:, 0].any(), "an invalid neighbour is no edge"
    slope = np.tile(np.linspace(2.0, 3.0, 40, dtype=np.float32), (20, 1))  # 2.5 cm a pixel: a wall seen at a slant
    assert not depth_edges(slope, 0.1).any()
    assert depth_edges(smeared_doorway(), 0.1)[:, 27:33].all()


def test_flying_pixels_are_hits_in_free_space_unless_depth_edges_are_skipped():
    """The smeared columns between a door frame and the room behind would mark occupied voxels
    in the free space of the doorway; skipping depth edges keeps the doorway free and both
    surfaces occupied."""
    T = pose_from_heading(0.0, 0.0, 0.0, yaw=0.0)  # camera z = world +x
    K = SMALL.K / 2 + np.diag([0, 0, 0.5])
    bounds = np.array([[-0.05, -3.05, -3.05], [6.05, 3.05, 3.05]])
    maps = {}
    for skip in (False, True):
        maps[skip] = OccupancyMap.from_bounds(bounds, map_conf(ray_stride_px=1, **PLAIN_MONOCULAR))
        maps[skip].integrate(smeared_doorway(), K, T, monocular=skip)
    occupied_x = {skip: occupancy.index_to_world(np.argwhere(occupancy.occupied_mask()))[:, 0]
                  for skip, occupancy in maps.items()}
    between = {skip: int(np.sum((x > 1.2) & (x < 2.8))) for skip, x in occupied_x.items()}
    assert between[False] > 0, "flying pixels become occupied voxels in free space"
    assert between[True] == 0
    assert np.any(np.abs(occupied_x[True] - 1.0) < 0.1) and np.any(np.abs(occupied_x[True] - 3.0) < 0.1)
    off = OccupancyMap.from_bounds(bounds, map_conf(ray_stride_px=1, depth_edge_rtol=None, **PLAIN_MONOCULAR))
    off.integrate(smeared_doorway(), K, T, monocular=True)
    np.testing.assert_array_equal(off.log_odds, maps[False].log_odds)  # null: no filter


def test_the_monocular_sensor_model_places_near_hits_only_and_frees_short_of_far_depth():
    """A wall 3 m ahead and a post 1.5 m ahead, seen by a monocular source: with
    ``monocular_hit_range_m`` 2 the post is occupied and the wall is no hit; with
    ``monocular_free_fraction`` 0.8 the wall's rays are free up to 2.4 m only, so an error that
    puts the wall too far cannot carve through it. Ground-truth depth (monocular False) keeps the
    plain rule, whatever the monocular keys say."""
    T = pose_from_heading(0.0, 0.0, 0.0, yaw=0.0)  # camera z = world +x
    K = SMALL.K / 2 + np.diag([0, 0, 0.5])
    bounds = np.array([[-0.05, -3.05, -3.05], [6.05, 3.05, 3.05]])
    depth = np.full((60, 60), 3.0, np.float32)
    depth[:, 20:24] = 1.5
    keys = dict(ray_stride_px=1, monocular_hit_range_m=2.0, monocular_free_fraction=0.8)
    probes = np.array([[1.0, 0, 0], [2.2, 0, 0], [2.7, 0, 0], [3.0, 0, 0]])  # on the wall's ray (centre pixel)
    maps = {}
    for monocular in (False, True):
        maps[monocular] = OccupancyMap.from_bounds(bounds, map_conf(**keys))
        maps[monocular].integrate(depth, K, T, monocular=monocular)
    assert maps[False].state_at(probes).tolist() == [FREE, FREE, FREE, OCCUPIED], "ground truth: the plain rule"
    assert maps[True].state_at(probes).tolist() == [FREE, FREE, UNKNOWN, UNKNOWN]
    occupied_x = maps[True].index_to_world(np.argwhere(maps[True].occupied_mask()))[:, 0]
    assert len(occupied_x) and np.all(np.abs(occupied_x - 1.5) < 0.1), "only the near post is a hit"
    plain = OccupancyMap.from_bounds(bounds, map_conf(ray_stride_px=1, depth_edge_rtol=None, **PLAIN_MONOCULAR))
    plain.integrate(depth, K, T, monocular=True)
    np.testing.assert_array_equal(plain.log_odds, maps[False].log_odds)  # null keys: the plain rule
    miss = OccupancyMap.from_bounds(bounds, map_conf(ray_stride_px=1, monocular_log_odds_miss=-0.85))
    miss.integrate(depth, K, T, monocular=True)
    np.testing.assert_allclose(miss.log_odds[tuple(miss.world_to_index(probes[:1]).T)], [-0.85])


def test_far_monocular_hits_are_weak_hits_that_a_later_miss_clears():
    """With ``monocular_far_hit_max`` a monocular depth beyond ``monocular_hit_range_m`` is a
    hit that raises its voxel to at most that log-odds, however often it repeats; rays that
    later pass the voxel clear it. Near hits keep OctoMap's rule."""
    T = pose_from_heading(0.0, 0.0, 0.0, yaw=0.0)
    K = SMALL.K / 2 + np.diag([0, 0, 0.5])
    bounds = np.array([[-0.05, -3.05, -3.05], [6.05, 3.05, 3.05]])
    occupancy = OccupancyMap.from_bounds(bounds, map_conf(ray_stride_px=1, monocular_hit_range_m=2.0,
                                                          monocular_far_hit_max=0.5))
    wall, post = np.array([[3.0, 0.0, 0.0]]), np.array([[1.5, 0.0, 0.0]])
    for _ in range(3):
        occupancy.integrate(np.full((60, 60), 3.0, np.float32), K, T, monocular=True)
    np.testing.assert_allclose(occupancy.log_odds[tuple(occupancy.world_to_index(wall).T)], [0.5], rtol=1e-6)
    assert occupancy.state_at(wall).tolist() == [OCCUPIED]
    for _ in range(2):  # the wall was a misplaced far depth: nearer views see through it
        occupancy.integrate(np.full((60, 60), 4.0, np.float32), K, T, monocular=True)
    assert occupancy.state_at(wall).tolist() == [FREE]
    before = occupancy.log_odds[tuple(occupancy.world_to_index(post).T)]
    occupancy.integrate(np.full((60, 60), 1.5, np.float32), K, T, monocular=True)
    np.testing.assert_allclose(occupancy.log_odds[tuple(occupancy.world_to_index(post).T)] - before, [0.85], rtol=1e-5)


def test_oblique_monocular_pixels_are_left_out_and_ground_truth_keeps_them():
    """A floor 1 m below a level camera meets its rays at incidence atan(x / 1 m) from its normal
    (x: distance along it): :func:`grazing_pixels` flags the pixels past the angle (against the
    exact angle), and with ``monocular_max_incidence_deg`` a monocular frame leaves them out of the
    map (neither hit nor free) while the nearer floor, a frontal wall and the ground truth's frame
    are integrated as before."""
    from frontiernet.mapping.checks import grazing_pixels

    K = np.array([[120.0, 0, 119.5], [0, 120.0, 119.5], [0, 0, 1]])
    v = (np.arange(240) - 119.5) / 120.0  # image y (down) per unit depth
    floor = np.where(v[:, None] > 0.05, 1.0 / np.maximum(v[:, None], 1e-9), np.inf) * np.ones((1, 240))
    depth = np.minimum(floor, 3.0).astype(np.float32)  # a wall 3 m ahead above the floor's horizon
    flagged = grazing_pixels(depth, K, 60.0, 9)
    u = (np.arange(240) - 119.5) / 120.0
    cos = v[:, None] / np.sqrt(1 + u[None] ** 2 + v[:, None] ** 2)  # floor normal (0, 1, 0) in the camera frame
    angle = np.degrees(np.arccos(cos))
    interior = np.zeros_like(flagged)
    interior[8:-8, 8:-8] = True
    on_floor = interior & (floor < 2.6)  # a window clear of the wall
    clear = on_floor & (np.abs(angle - 60.0) > 2.0)  # and off the threshold
    assert np.array_equal(flagged[clear], angle[clear] > 60.0) and flagged[on_floor].any()
    assert not flagged[interior & (floor > 3.5)].any()  # the wall is frontal
    noisy = (depth * np.random.default_rng(0).uniform(0.9, 1.1, depth.shape))[:235, :231].astype(np.float32)
    for stride in (2, 3):  # the map's ray stride: the judged pixels' verdicts are the full image's, the rest False
        full, strided = grazing_pixels(noisy, K, 60.0, 9), grazing_pixels(noisy, K, 60.0, 9, stride)
        assert np.array_equal(strided[::stride, ::stride], full[::stride, ::stride]) and full[::stride, ::stride].any()
        strided[::stride, ::stride] = False
        assert not strided.any()
    T = pose_from_heading(0.0, 0.0, 0.0, yaw=0.0)  # camera z = world +x, image down = world -z
    bounds = np.array([[-0.05, -3.05, -1.55], [6.05, 3.05, 1.55]])
    keys = dict(ray_stride_px=1, depth_edge_rtol=None, monocular_max_incidence_deg=60.0)
    maps = {}
    for monocular in (False, True):
        maps[monocular] = OccupancyMap.from_bounds(bounds, map_conf(**keys))
        maps[monocular].integrate(depth, K, T, monocular=monocular)
    far_floor = np.array([[2.3, 0.0, -1.0]])  # seen at 66 deg
    near_floor = np.array([[1.2, 0.0, -1.0]])  # 50 deg
    wall = np.array([[3.0, 0.0, 0.5]])
    assert maps[False].state_at(far_floor).tolist() == [OCCUPIED]
    assert maps[True].state_at(far_floor).tolist() == [UNKNOWN]
    for probe in (near_floor, wall):
        assert maps[True].state_at(probe).tolist() == maps[False].state_at(probe).tolist() == [OCCUPIED]
    with pytest.raises(InputError, match="monocular_max_incidence_deg"):
        OccupancyMap.from_bounds(bounds, map_conf(monocular_max_incidence_deg=90.0))
    with pytest.raises(InputError, match="monocular_normal_window_px"):
        OccupancyMap.from_bounds(bounds, map_conf(monocular_normal_window_px=8))


def test_stride_two_sees_nearly_what_stride_one_sees(renderer):
    poses = surround_poses()[:3]
    fine = integrated(renderer, poses, ray_stride_px=1)
    coarse = integrated(renderer, poses, ray_stride_px=2)
    assert coarse.free_mask().sum() == pytest.approx(fine.free_mask().sum(), rel=0.03)
    assert coarse.occupied_mask().sum() == pytest.approx(fine.occupied_mask().sum(), rel=0.1)


def test_camera_outside_the_grid_integrates_where_rays_enter(renderer):
    T = pose_from_heading(*CAMERA, yaw=0.0)
    part = OccupancyMap.from_bounds(np.array([[2.05, -0.45, -0.45], [4.45, 3.45, 2.95]]), map_conf())
    frame = renderer.render(T)
    part.integrate(frame.depth, frame.K, T)
    assert part.state_at(np.array([[2.1, 1.5, 1.2], [3.0, 1.5, 1.2], [4.0, 1.5, 1.2], [4.3, 1.5, 1.2]])).tolist() \
        == [FREE, FREE, OCCUPIED, UNKNOWN]
    whole = integrated(renderer, [T])
    assert np.mean(part.observed != whole.observed[25:]) < 1e-3  # the same voxels (up to rounding at corners)


def test_visible_known_volume(room, renderer):
    view = load_config("explore").tracking.gain_view
    args = (int(view.width_px), float(view.focal_px), float(view.max_depth_m))
    T = np.stack([pose_from_heading(*CAMERA, yaw=0.0), pose_from_heading(2.0, 1.0, 1.0, yaw=2.0)])
    empty = OccupancyMap.from_bounds(BOUNDS, map_conf())
    np.testing.assert_array_equal(empty.visible_known_volume(T, *args), [0.0, 0.0])
    voxels = voxelize_scene(room, sim_section("voxels"))
    occupancy = OccupancyMap.like(voxels, map_conf())
    for pose in surround_poses():
        frame = renderer.render(pose)
        occupancy.integrate(frame.depth, frame.K, pose)
    known = occupancy.visible_known_volume(T, *args)
    # the same frusta in the true scene: everything explorable, up to the walls
    truth = np.empty(2)
    centre = (args[0] - 1) / 2.0
    directions = PinholeCamera(args[0], args[0], args[1], args[1], centre, centre, np.inf).ray_directions().reshape(-1, 3)
    frustum_volume(T[:, :3, 3].copy(), T[:, :3, :3].copy(), directions.astype(np.float64), args[2], args[1],
                   voxels.origin, voxels.voxel_size, ~voxels.occupied, voxels.explorable, truth)
    assert truth.min() > 5.0
    np.testing.assert_allclose(known, truth, rtol=0.07)  # the map misses a few voxels (blind spots, edges)
    assert occupancy.visible_known_volume(T[0], *args).shape == (1,)
    # unknown volume: all of the frusta in the empty map (nothing stops the rays), little in the mapped room
    unknown_empty = empty.visible_unknown_volume(T, *args)
    assert np.all(unknown_empty > truth)
    assert np.all(occupancy.visible_unknown_volume(T, *args) < 0.2 * truth)  # blind spots near the camera


def test_slice_2d_marks_walls_occupied_and_the_room_free(renderer):
    occupancy = integrated(renderer, surround_poses()[1::3])  # the level views
    free, occupied = occupancy.slice_2d(1.0, 1.4)
    assert free.shape == occupied.shape == occupancy.shape[:2]
    (i_wall, _, _), (i_in, _, _), (i_out, _, _) = occupancy.world_to_index(
        np.array([[4.0, 1.5, 1.2], [2.5, 1.5, 1.2], [4.3, 1.5, 1.2]]))
    inner = slice(5, -5)  # y in [0.05, 2.95]: inside the room
    assert occupied[i_wall, inner].all() and not free[i_wall, inner].any()
    seen = slice(10, -10)  # y in [0.55, 2.45]: what the level view along +x sees 1.5 m ahead
    assert free[i_in, seen].all() and not occupied[i_in, inner].any()
    assert not free[i_out].any() and not occupied[i_out].any()
    assert occupied[occupancy.world_to_index(np.array([0.0, 1.5, 1.2]))[0]].any()  # the wall behind
    empty_free, empty_occupied = occupancy.slice_2d(10.0, 11.0)  # above the grid: unknown
    assert not empty_free.any() and not empty_occupied.any()


def test_slice_2d_follows_every_map_update(renderer):
    occupancy = integrated(renderer, surround_poses()[1:2])  # one level view
    free, _ = occupancy.slice_2d(1.0, 1.4)
    assert not free.flags.writeable  # kept for the next caller of the same band
    again, _ = occupancy.slice_2d(1.0, 1.4)
    np.testing.assert_array_equal(again, free)
    for pose in surround_poses()[4::3]:  # more frames: more free cells
        frame = renderer.render(pose)
        occupancy.integrate(frame.depth, frame.K, pose)
    more, _ = occupancy.slice_2d(1.0, 1.4)
    assert more.sum() > free.sum()
    i, j, _ = occupancy.world_to_index(np.array([[2.0, 2.6, 1.2]]))[0]
    assert not more[i, j]  # not yet seen ...
    occupancy.clear_sphere(np.array([2.0, 2.6, 1.2]), 0.3)
    assert occupancy.slice_2d(1.0, 1.4)[0][i, j]  # ... freed by the robot's footprint


def test_slice_2d_patched_after_updates_equals_a_fresh_map_and_never_changes_what_it_gave(renderer):
    poses = surround_poses() + surround_poses((3.0, 1.0, 1.2))

    def apply(occupancy, step):  # one map update: a frame, every fifth step the robot's footprint
        if step % 5 == 4:
            occupancy.clear_sphere(poses[step][:3, 3], 0.3)
        else:
            frame = renderer.render(poses[step])
            occupancy.integrate(frame.depth, frame.K, poses[step])

    kept = OccupancyMap.from_bounds(BOUNDS, map_conf())
    apply(kept, 0)
    bands = [(1.0, 1.4), (0.6, 1.8), (1.2, 1.2), (0.0, 0.1)]  # views kept between updates, then patched
    given = [kept.slice_2d(*band) for band in bands]
    first = [[view.copy() for view in pair] for pair in given]
    for step in range(1, len(poses)):
        apply(kept, step)
        fresh = OccupancyMap.from_bounds(BOUNDS, map_conf())
        for earlier in range(step + 1):  # the same updates, no view asked for in between
            apply(fresh, earlier)
        for band in bands:
            for patched, whole in zip(kept.slice_2d(*band), fresh.slice_2d(*band)):
                np.testing.assert_array_equal(patched, whole)
    for pair, before in zip(given, first):  # what a caller was given stays as it was
        for view, copy in zip(pair, before):
            np.testing.assert_array_equal(view, copy)
    assert not np.array_equal(kept.slice_2d(*bands[0])[0], first[0][0])


def test_a_change_record_holds_every_voxel_the_updates_changed(renderer):
    """``OccupancyMap.changes()``: what a consumer that patches derived arrays relies on: no voxel outside
    the box taken changed since the last take, and nothing is reported before an update."""
    poses = surround_poses()
    occupancy = OccupancyMap.from_bounds(BOUNDS, map_conf())
    record, states = occupancy.changes(), occupancy.changes(status_only=True)
    assert record.take() is None and states.take() is None
    smaller = 0
    for step, pose in enumerate([*poses, *poses]):  # the second round sees again what the map knows
        before = occupancy.observed.copy(), occupancy.log_odds.copy(), occupancy.occupied_mask()
        if step % 3 == 2:
            occupancy.clear_sphere(pose[:3, 3], 0.3)
        else:
            frame = renderer.render(pose)
            occupancy.integrate(frame.depth, frame.K, pose)
        box, state_box = record.take(), states.take()
        changed = (occupancy.observed != before[0]) | (occupancy.log_odds != before[1])
        flipped = (occupancy.observed != before[0]) | (occupancy.occupied_mask() != before[2])
        assert box is not None  # (a footprint already free changes nothing inside it)
        changed[box] = False
        assert not changed.any()
        assert (state_box is None) == (not flipped.any())  # status only: the voxels whose state flipped
        if state_box is not None:
            assert flipped[state_box].any(axis=(1, 2))[[0, -1]].all()  # a tight box: flips on its faces
            flipped[state_box] = False
        smaller += state_box is None or np.prod([s.stop - s.start for s in state_box]) < np.prod(
            [s.stop - s.start for s in box])
        assert not flipped.any()
        assert record.take() is None and states.take() is None
    assert smaller >= len(poses) + len(poses) // 2  # as a rule far smaller than the box the frame touched


def test_state_at_off_the_grid_and_save_load(renderer, tmp_path):
    occupancy = integrated(renderer, [pose_from_heading(*CAMERA, yaw=0.0)])
    far = occupancy.state_at(np.array([[100.0, 0, 0], [np.nan, 1.0, 1.0], [-5.0, 1.5, 1.2]]))
    assert far.dtype == np.int8 and far.tolist() == [UNKNOWN] * 3
    path = occupancy.save(tmp_path / "map.npz")
    loaded = OccupancyMap.load(path)
    np.testing.assert_array_equal(loaded.log_odds, occupancy.log_odds)
    np.testing.assert_array_equal(loaded.observed, occupancy.observed)
    assert loaded.settings == occupancy.settings and loaded.known_volume_m3 == occupancy.known_volume_m3
    np.testing.assert_array_equal(loaded.origin, occupancy.origin)
    (tmp_path / "bad.npz").write_bytes(b"not a map")
    with pytest.raises(InputError, match="bad.npz"):
        OccupancyMap.load(tmp_path / "bad.npz")


def test_clear_sphere_frees_the_robot_footprint():
    occupancy = OccupancyMap.from_bounds(np.array([[0.0, 0.0, 0.0], [2.0, 2.0, 2.0]]), map_conf())
    occupancy.clear_sphere(np.array([1.0, 1.0, 1.0]), 0.2)
    assert occupancy.state_at(np.array([[1.0, 1.0, 1.0], [1.15, 1.0, 1.0], [1.35, 1.0, 1.0]])).tolist() \
        == [FREE, FREE, UNKNOWN]
    assert occupancy.known_volume_m3 == pytest.approx(occupancy.observed.sum() * 1e-3)


def test_a_contact_stays_occupied_whatever_frames_and_the_robot_sphere_say(renderer):
    # a thing the camera misses (a shelf's edge end-on) felt by the robot's bump sensor (issue 54)
    contact = np.array([2.5, 1.5, 1.2])  # on the camera's line of sight to the wall x = 4: every frame passes it
    T = pose_from_heading(*CAMERA, yaw=0.0)
    occupancy = OccupancyMap.from_bounds(BOUNDS, map_conf())
    record = occupancy.changes(status_only=True)
    occupancy.mark_contact(contact)
    assert occupancy.state_at(contact[None])[0] == OCCUPIED and occupancy.known_volume_m3 == pytest.approx(1e-3)
    assert record.take() is not None  # told like any update: the band views and the change records follow
    before = occupancy.slice_2d(1.0, 1.4)[1].copy()
    for _ in range(5):
        frame = renderer.render(T)
        occupancy.integrate(frame.depth, frame.K, T)
        occupancy.clear_sphere(contact, 0.2)
    assert occupancy.state_at(np.array([contact, [2.0, 1.5, 1.2]])).tolist() == [OCCUPIED, FREE]
    assert occupancy.log_odds[tuple(occupancy.world_to_index(contact[None])[0])] == map_conf()["log_odds_max"]
    assert occupancy.slice_2d(1.0, 1.4)[1][tuple(occupancy.world_to_index(contact[None])[0][:2])] and before.any()
    occupancy.mark_contact(np.array([99.0, 0.0, 0.0]))  # off the grid: nothing


def test_cylinder_touches_an_occupied_column_exactly_when_it_overlaps_its_square():
    occupancy = OccupancyMap.from_bounds(np.array([[0.0, 0.0, 0.0], [2.0, 2.0, 2.0]]), map_conf())
    depth = np.full((9, 9), 1.0, np.float32)  # a frame looking along +x from x = 0.05 hits the voxel layer [1.0, 1.1)
    T = np.array([[0, 0, 1, 0.05], [-1, 0, 0, 1.05], [0, -1, 0, 1.05], [0, 0, 0, 1]], np.float64)
    occupancy.integrate(depth, np.array([[4.0, 0, 4], [0, 4.0, 4], [0, 0, 1]]), T)
    assert occupancy.state_at(np.array([[1.05, 1.05, 1.05]]))[0] == OCCUPIED
    band = (0.95, 1.15)
    # the occupied column's face is at x = 1.0: a cylinder at x = 0.75 reaches it with r > 0.25 only
    assert not occupancy.cylinder_touches_occupied(np.array([0.75, 1.05]), 0.24, *band)
    assert occupancy.cylinder_touches_occupied(np.array([0.75, 1.05]), 0.26, *band)
    # diagonally off the lit patch's corner the distance is to that corner, not to a centre
    i, k = 10, 10  # the voxel column x in [1.0, 1.1), z in [1.0, 1.1)
    j_last = int(np.flatnonzero(occupancy.occupied_mask()[i, :, k]).max())
    corner = np.array([1.0, occupancy.origin[1] + (j_last + 1) * 0.1])
    centre = np.array([corner[0] - 0.1, corner[1] + 0.1])
    assert not occupancy.cylinder_touches_occupied(centre, 0.14, *band)  # sqrt(0.1^2 + 0.1^2) = 0.1414
    assert occupancy.cylinder_touches_occupied(centre, 0.15, *band)
    # an obstacle anywhere in the band counts (a counter top below the camera), one outside it does not
    assert occupancy.cylinder_touches_occupied(np.array([0.75, 1.05]), 0.26, 1.15, 1.5) is False
    assert occupancy.cylinder_touches_occupied(np.array([0.75, 1.05]), 0.26, 0.7, 1.02)
    with pytest.raises(InputError, match="finite"):
        occupancy.cylinder_touches_occupied(np.array([np.nan, 1.0]), 0.2, *band)


def test_bad_inputs_raise_input_errors(two_room_voxels):
    occupancy = OccupancyMap.from_bounds(BOUNDS, map_conf())
    depth, K, T = np.ones((60, 80), np.float32), SMALL.K.copy(), np.eye(4)
    K[0, 2], K[1, 2] = 39.5, 29.5
    bad_pose = T.copy()
    bad_pose[0, 3] = np.nan
    cases = [
        ((np.ones((4, 4, 1), np.float32), K, T), "depth"),
        ((np.ones((60, 80), np.uint16), K, T), "depth"),
        ((depth, K[:2], T), "K"),
        ((depth, SMALL.K, T), "K"),  # principal point of a 120 x 120 image
        ((depth, K, bad_pose), "T_world_cam"),
        ((depth, K, np.diag([2.0, 1.0, 1.0, 1.0])), "T_world_cam"),
        ((depth, K, np.eye(3)), "T_world_cam"),
    ]
    for args, name in cases:
        with pytest.raises(InputError, match=name):
            occupancy.integrate(*args)
    for key, value in [("invalid_depth", "maybe"), ("ray_stride_px", 0), ("voxel_size", -0.1),
                       ("log_odds_min", 1.0), ("log_odds_hit", float("nan")), ("depth_edge_rtol", 0.0),
                       ("monocular_hit_range_m", 0.0), ("monocular_free_fraction", 1.5),
                       ("monocular_free_fraction", 0.0), ("monocular_log_odds_miss", 0.4),
                       ("monocular_far_hit_max", 4.0)]:
        with pytest.raises(InputError, match=key):
            OccupancyMap.from_bounds(BOUNDS, map_conf(**{key: value}))
    with pytest.raises(InputError, match="voxel_size"):
        OccupancyMap.like(two_room_voxels, map_conf(voxel_size=0.05))
    with pytest.raises(InputError, match="bounds"):
        OccupancyMap.from_bounds(BOUNDS[::-1], map_conf())
    with pytest.raises(InputError, match="points"):
        occupancy.state_at(np.zeros((3, 2)))
    with pytest.raises(InputError, match="z_min"):
        occupancy.slice_2d(2.0, 1.0)
    with pytest.raises(InputError, match="T_world_cams"):
        occupancy.visible_known_volume(np.eye(3), 32, 15.0, 3.5)


def test_the_library_never_imports_datagen():
    code = "import sys, frontiernet.mapping; sys.exit('datagen' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 0


def test_bench_map_reports_update_and_query_times_as_ratios_to_a_render(tmp_path, capsys):
    from argparse import Namespace

    from PIL import Image

    from frontiernet.cli.bench import run_map

    plan = np.full((80, 100), 254, np.uint8)  # one 4 x 3 m room, 0.05 m per pixel
    plan[10:70, 10:16] = plan[10:70, 84:90] = plan[10:16, 10:90] = plan[64:70, 10:90] = 0
    Image.fromarray(plan).save(tmp_path / "room.png")
    spec = f"floorplan:{tmp_path / 'room.png'}?resolution=0.05"
    assert run_map(Namespace(scene=spec, frames=2, views=3, json=True)) == 0
    result = json.loads(capsys.readouterr().out)
    for stride in (1, 2, 4):
        assert result[f"integrate_stride{stride}_over_render"] > 0
    assert result["integrate_edges_over_render"] > 0
    assert result["views"] == 3 and result["known_m3"] > 1.0

"""Classic map-based frontiers (Yamauchi 1997): frontier cells of the planner's band, regions, goals."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from omegaconf import OmegaConf

from conftest import box_scene, room_boxes
from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.frontiers.map_frontiers import _split_long, frontier_regions, frontier_settings, map_frontiers
from frontiernet.geometry import pose_from_heading
from frontiernet.mapping import OccupancyMap
from frontiernet.simulator.camera import PinholeCamera, Renderer

SMALL = PinholeCamera(120, 120, 75.0, 75.0, 59.5, 59.5, 3.5)  # the paper's field of view, 120 px
Z = 1.2  # camera height, metres
# room A: interior [0, 4] x [0, 3] x [0, 2.5] m; the map's voxel faces lie half a voxel off the walls
ROOM_BOUNDS = np.array([[-0.45, -0.45, -0.45], [4.45, 3.45, 2.95]])
# room B, interior [4.2, 8] x [0, 3], behind a door y in [1, 2] in room A's wall x in [4, 4.2]
DOOR_Y, DOOR_CENTRE = (1.0, 2.0), np.array([4.1, 1.5])
TWO_ROOM_BOUNDS = np.array([[-0.45, -0.45, -0.45], [8.45, 3.45, 2.95]])


def conf(**changes) -> dict:
    """The explore config with `changes` made where each key lives: the planner's band, the
    tracker's gain view, or map_frontiers' own keys."""
    explore = OmegaConf.to_container(load_config("explore"))
    for key, value in changes.items():
        if key == "height_band_m":
            explore["planner"][key] = value
        elif key in ("width_px", "focal_px", "max_depth_m"):
            explore["tracking"]["gain_view"][key] = value
        else:
            explore["map_frontiers"][key] = value
    return explore


def doorway_boxes():
    lower, upper = room_boxes(4.0, 3.0, 2.5, door=DOOR_Y)
    lower_b, upper_b = room_boxes(3.8, 3.0, 2.5)
    del lower_b[3], upper_b[3]  # room B's wall at its x = 0 is room A's door wall
    shift = np.array([4.2, 0.0, 0.0])
    return lower + [tuple(np.add(c, shift)) for c in lower_b], upper + [tuple(np.add(c, shift)) for c in upper_b]


def seen_map(boxes, bounds, xy, yaws_deg) -> tuple[OccupancyMap, np.ndarray]:
    """The map after level frames from (x, y, Z) at these headings, and the last pose."""
    renderer = Renderer(box_scene(*boxes, "map-frontiers"), SMALL, (0, 0, 0))
    occupancy = OccupancyMap.from_bounds(bounds, load_config("explore").map)
    for yaw in yaws_deg:
        T = pose_from_heading(xy[0], xy[1], Z, np.radians(yaw))
        frame = renderer.render(T)
        occupancy.integrate(frame.depth, frame.K, T)
        occupancy.clear_sphere(T[:3, 3], 0.5)  # the robot's body (the band's low layer under the camera)
    return occupancy, T


@pytest.fixture(scope="module")
def half_seen_room():
    """Room A seen from its middle at headings 0 to 180 degrees: its -y side is unseen."""
    return seen_map(room_boxes(4.0, 3.0, 2.5), ROOM_BOUNDS, (2.0, 1.5), range(0, 181, 45))


@pytest.fixture(scope="module")
def doorway_map():
    """Rooms A and B seen from (1, 1.5) in A at headings -120 to 120 degrees: the frame along +x sees
    through the door up to its 3.5 m range (x = 4.5), so B is unseen; so is a nook behind the robot."""
    return seen_map(doorway_boxes(), TWO_ROOM_BOUNDS, (1.0, 1.5), (0, 60, -60, 120, -120))


def band_cell(occupancy, position) -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
    """(free, unknown) of the planner's band at Z and the cell holding `position`."""
    band = load_config("explore").planner.height_band_m
    free, occupied = occupancy.slice_2d(Z - band, Z + band)
    i, j = np.floor((position[:2] - occupancy.origin[:2]) / occupancy.voxel_size).astype(int)
    return free, ~free & ~occupied, (i, j)


def unknown_neighbour_steps(unknown, i, j) -> np.ndarray:
    """(2,) sum of the steps from cell (i, j) to its unknown 4-neighbours."""
    steps = [np.array(s) for s in ((1, 0), (-1, 0), (0, 1), (0, -1))]
    return sum((s for s in steps if 0 <= i + s[0] < unknown.shape[0] and 0 <= j + s[1] < unknown.shape[1]
                and unknown[i + s[0], j + s[1]]), np.zeros(2))


def stub_map(free, occupied=None):
    """A stand-in OccupancyMap whose band slice is the given (X, Y) arrays, 0.1 m cells at the origin."""
    occupied = np.zeros_like(free) if occupied is None else occupied
    return SimpleNamespace(slice_2d=lambda z0, z1: (free, occupied), voxel_size=0.1, origin=np.zeros(3))


# -- no frontiers where nothing is left to explore ----------------------------------------------------


def test_an_empty_map_has_no_frontiers():
    occupancy = OccupancyMap.from_bounds(ROOM_BOUNDS, load_config("explore").map)
    assert map_frontiers(occupancy, Z, conf(), np.eye(4)) == []


def test_a_closed_room_seen_all_around_has_no_frontiers():
    # unknown space remains outside the walls, but none of it touches free space
    occupancy, T = seen_map(room_boxes(4.0, 3.0, 2.5), ROOM_BOUNDS, (2.0, 1.5), range(0, 360, 45))
    assert map_frontiers(occupancy, Z, conf(), T) == []


# -- frontiers on real maps -----------------------------------------------------------------------------


def test_frontiers_lie_on_the_unseen_side_on_free_cells_and_point_into_the_unknown(half_seen_room):
    occupancy, T = half_seen_room
    frontiers = map_frontiers(occupancy, Z, conf(), T, gain="uniform")
    assert len(frontiers) >= 2  # both edges of the unseen wedge
    for frontier in frontiers:
        assert frontier.position[1] < 1.5 and frontier.position[2] == Z  # the unseen -y half, at the robot height
        free, unknown, (i, j) = band_cell(occupancy, frontier.position)
        steps = unknown_neighbour_steps(unknown, i, j)
        assert free[i, j] and np.any(steps != 0)  # a free cell of the band next to unknown space
        ahead = np.rint(frontier.direction[:2]).astype(int) + (i, j)  # the cell one step along it
        assert frontier.direction[:2] @ steps > 0 or unknown[tuple(ahead)]
        assert frontier.direction[1] < 0 and frontier.direction[2] == 0
        assert np.linalg.norm(frontier.direction) == pytest.approx(1.0)
        assert frontier.num_pixels >= conf()["map_frontiers"]["min_cells"] and np.all(np.isnan(frontier.pixel))
        np.testing.assert_array_equal(frontier.T_world_cam, T)
        assert frontier.T_world_cam is not T


def test_a_doorway_into_an_unseen_room_gives_a_frontier_pointing_into_it(doorway_map):
    occupancy, T = doorway_map
    frontiers = map_frontiers(occupancy, Z, conf(), T)
    at_door = [f for f in frontiers if np.linalg.norm(f.position[:2] - DOOR_CENTRE) < 0.5]
    assert len(at_door) == 1
    assert at_door[0].direction[0] > 0.9  # into room B (+x)


# -- gains --------------------------------------------------------------------------------------------


def test_unknown_volume_gain_is_larger_towards_a_big_unknown_room_than_a_nook(doorway_map):
    occupancy, T = doorway_map
    frontiers = map_frontiers(occupancy, Z, conf(), T, gain="unknown_volume")
    door = min(frontiers, key=lambda f: np.linalg.norm(f.position[:2] - DOOR_CENTRE))
    nook = min(frontiers, key=lambda f: f.position[0])  # behind the robot, between it and the wall x = 0
    assert nook.position[0] < 1.0 and nook.direction[0] < 0
    assert door.gain_m3 > 10.0 * nook.gain_m3 > 0.0


def test_uniform_gain_is_the_configured_value(doorway_map):
    occupancy, T = doorway_map
    frontiers = map_frontiers(occupancy, Z, conf(uniform_gain_m3=7.5), T, gain="uniform")
    assert frontiers and all(f.gain_m3 == 7.5 for f in frontiers)


def test_an_unknown_gain_name_is_an_input_error_naming_it():
    occupancy = OccupancyMap.from_bounds(ROOM_BOUNDS, load_config("explore").map)
    with pytest.raises(InputError, match="one of unknown_volume, uniform, got 'volume'"):
        map_frontiers(occupancy, Z, conf(), np.eye(4), gain="volume")


# -- regions: noise and long frontiers ----------------------------------------------------------------


def test_a_long_frontier_is_split_into_pieces_no_longer_than_max_extent():
    free = np.zeros((80, 40), bool)
    free[:, :20] = True  # free below y = 2 m, unknown above: one straight 8 m frontier row at j = 19
    frontiers = map_frontiers(stub_map(free), Z, conf(max_extent_m=3.0), np.eye(4), gain="uniform")
    assert len(frontiers) == 3  # 7.9 m between the end cell centres: ceil(7.9 / 3) pieces
    assert sum(f.num_pixels for f in frontiers) == 80
    assert all((f.num_pixels - 1) * 0.1 <= 3.0 for f in frontiers)  # a straight piece of n cells is n - 1 long
    xs = sorted(f.position[0] for f in frontiers)
    assert np.all(np.diff(xs) > 2.0)  # spread along the row
    for frontier in frontiers:
        np.testing.assert_allclose(frontier.position[1:], [1.95, Z])
        np.testing.assert_allclose(frontier.direction, [0.0, 1.0, 0.0])
    assert len(map_frontiers(stub_map(free), Z, conf(max_extent_m=8.0), np.eye(4), gain="uniform")) == 1


def test_a_bent_frontier_is_split_into_pieces_whose_cells_lie_within_max_extent():
    is_frontier = np.zeros((60, 60), bool)
    is_frontier[39, :40] = is_frontier[:40, 39] = True  # an L of two 4 m arms (0.1 m cells)
    cells, piece = frontier_regions(is_frontier, 5, 25.0)
    assert len(cells) == 79 and piece.max() + 1 >= 4  # 7.8 m of frontier in pieces of at most 2.5 m
    for p in range(piece.max() + 1):
        members = cells[piece == p]
        assert np.max(np.linalg.norm(members[:, None] - members[None], axis=-1)) <= 25.0


def test_regions_below_min_cells_are_noise_and_dropped():
    free = np.ones((40, 40), bool)
    free[10, 10] = False  # a one-cell hole: 4 frontier cells around it
    free[25:27, 25:27] = False  # a 2 x 2 hole: 8 frontier cells around it
    frontiers = map_frontiers(stub_map(free), Z, conf(min_cells=5), np.eye(4), gain="uniform")
    assert [f.num_pixels for f in frontiers] == [8]
    assert np.linalg.norm(frontiers[0].position[:2] - 2.6) < 0.2
    assert sorted(f.num_pixels for f in map_frontiers(stub_map(free), Z, conf(min_cells=4), np.eye(4),
                                                      gain="uniform")) == [4, 8]


# -- config and input checks --------------------------------------------------------------------------


def test_map_frontiers_use_the_planner_band_and_the_tracker_gain_view():
    settings = frontier_settings(conf(height_band_m=0.5, width_px=16, focal_px=7.5, max_depth_m=3.0))
    assert (settings["height_band_m"], settings["width_px"], settings["focal_px"], settings["max_depth_m"]) \
        == (0.5, 16, 7.5, 3.0)


@pytest.mark.parametrize("z, pose, changes, message", [
    (float("nan"), np.eye(4), {}, "z must be a finite number"),
    (Z, np.diag([1.0, 1.0, 2.0, 1.0]), {}, "T_world_cam must be a rigid transform"),
    (Z, np.eye(4), {"min_cells": 0}, "map_frontiers.min_cells must be a positive number"),
    (Z, np.eye(4), {"width_px": 2.5}, "tracking.gain_view.width_px must be a positive integer"),
    (Z, np.eye(4), {"max_extent_m": -1.0}, "map_frontiers.max_extent_m must be a positive number"),
    (Z, np.eye(4), {"height_band_m": None}, "planner.height_band_m is missing"),
])
def test_bad_inputs_are_input_errors_naming_the_value(z, pose, changes, message):
    occupancy = OccupancyMap.from_bounds(ROOM_BOUNDS, load_config("explore").map)
    with pytest.raises(InputError, match=message):
        map_frontiers(occupancy, z, conf(**changes), pose)


def test_a_long_region_of_few_far_apart_cells_is_split_into_single_cells_not_empty_pieces():
    """A chunk of a bent region can hold few cells spanning more than their count of maximum
    extents (KTH runs failed on it: an empty piece); each cell becomes its own piece."""
    cells = np.array([[0, 0], [0, 10], [0, 20], [5, 20]], np.int64)
    pieces = _split_long(np.arange(4), cells, max_extent_cells=3.0)
    assert sorted(np.concatenate(pieces).tolist()) == [0, 1, 2, 3] and all(len(p) == 1 for p in pieces)


def test_regions_dropped_as_noise_are_proposed_once_a_run_would_stop():
    # a door the monocular map half-shuts leaves a frontier of 2-3 cells, below min_cells (5): classic stopped
    # with a quarter of procedural:1003 behind one (issue 54); min_cells_before_stop proposes such regions then
    from frontiernet.exploration.sources import MapSource
    from frontiernet.timing import Stopwatch

    free, occupied = np.zeros((20, 20), bool), np.zeros((20, 20), bool)
    free[:, :15], occupied[:, 15] = True, True
    occupied[8:11, 15], free[8:11, 15] = False, True  # the door's open part: 3 free cells, unknown beyond
    frame = SimpleNamespace(rgb=np.zeros((8, 8, 3), np.uint8), K=np.array([[8.0, 0, 4], [0, 8, 4], [0, 0, 1]]),
                            T_world_cam=pose_from_heading(1.0, 1.0, Z, 0.0), depth=np.ones((8, 8), np.float32))

    def proposed(source) -> list:
        return source(frame, frame.depth, Stopwatch())[0]

    source = MapSource("uniform", stub_map(free, occupied), OmegaConf.create(conf()))
    assert proposed(source) == []  # a run would stop here
    assert source.widen() and not source.widen()  # once
    (door,) = proposed(source)
    assert door.num_pixels == 3 and door.position[0] == pytest.approx(0.95) and door.direction[1] == 1.0
    free[0, 2:9] = False  # unknown cells along x = 0 too: a region of 9 frontier cells beside them, which the
    # tracker may drop as seen (the stop came with regions the robot had looked at): the door's is proposed too
    assert sorted(f.num_pixels for f in proposed(source)) == [3, 9]
    off = MapSource("uniform", stub_map(free, occupied), OmegaConf.create(conf(min_cells_before_stop=None)))
    assert not off.widen()  # as before the key: the run stops

"""Frontier bookkeeping (docs/design.md item 5): merge, map-based gain reduction, drops, stable ids."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from conftest import box_scene, explore_section, room_boxes
from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.frontiers import FrontierTracker
from frontiernet.geometry import pose_from_heading
from frontiernet.mapping import FREE, OCCUPIED, OccupancyMap
from frontiernet.simulator.camera import PinholeCamera, Renderer

# a closed room, interior [0, 4] x [0, 3] x [0, 2.5] m; the map's voxel faces lie half a voxel off the walls
ROOM = (4.0, 3.0, 2.5)
BOUNDS = np.array([[-0.45, -0.45, -0.45], [4.45, 3.45, 2.95]])
SMALL = PinholeCamera(120, 120, 75.0, 75.0, 59.5, 59.5, 3.5)  # the paper's field of view, 120 px
CAMERA_Z = 1.2


def tracking_conf(**changes) -> dict:
    return explore_section("tracking", **changes)


def observation(xyz, yaw_deg: float = 0.0, gain: float = 10.0):
    """A FrontierObservation-like record with a level view direction at heading `yaw_deg`."""
    yaw = np.radians(yaw_deg)
    return SimpleNamespace(position=np.asarray(xyz, float), direction=np.array([np.cos(yaw), np.sin(yaw), 0.0]),
                           gain_m3=float(gain))


def level_pose(x: float, y: float, yaw_deg: float, z: float = CAMERA_Z) -> np.ndarray:
    return pose_from_heading(x, y, z, np.radians(yaw_deg))


@pytest.fixture(scope="module")
def mapped_room():
    """The room's occupancy map after one level frame from (0.8, 1.5, 1.2) looking along +x
    (the wall x = 4 is 3.2 m away, within range)."""
    return room_map(0.0)


# -- merging and ids --------------------------------------------------------------------------------


def test_close_similar_observation_merges_into_a_running_mean():
    tracker = FrontierTracker(tracking_conf())
    assert tracker.add([observation((1.0, 1.0, 1.2), 0.0, gain=6.0)], parent_pose=0, step=0) == [0]
    # 0.3 m away (< merge_distance_m 0.6), direction 30 degrees off (< merge_angle_deg 45)
    assert tracker.add([observation((1.3, 1.0, 1.2), 30.0, gain=2.0)], parent_pose=4, step=7) == [0]
    assert len(tracker) == 1
    frontier = tracker.get(0)
    np.testing.assert_allclose(frontier.position, [1.15, 1.0, 1.2])
    assert frontier.predicted_gain_m3 == pytest.approx(4.0) and frontier.gain_m3 == pytest.approx(4.0)
    assert np.degrees(frontier.yaw) == pytest.approx(15.0)  # the mean of the two directions
    assert np.linalg.norm(frontier.direction) == pytest.approx(1.0)
    assert frontier.observations == 2
    assert frontier.parent_pose == 4  # the latest viewer is the parent in the frontier tree
    assert (frontier.first_step, frontier.last_step) == (0, 7)
    # a third observation weighs one third
    tracker.add([observation((1.45, 1.0, 1.2), 15.0, gain=7.0)], parent_pose=5, step=8)
    np.testing.assert_allclose(tracker.get(0).position, [(1.0 + 1.3 + 1.45) / 3, 1.0, 1.2])
    assert tracker.get(0).predicted_gain_m3 == pytest.approx(5.0)


@pytest.mark.parametrize("xyz, yaw_deg, why", [
    ((1.7, 1.0, 1.2), 0.0, "0.7 m away"),
    ((1.0, 1.0, 1.2), 180.0, "same place, opposite direction"),
    ((1.2, 1.0, 1.2), 50.0, "direction 50 degrees off"),
])
def test_far_or_differently_directed_observation_is_a_new_frontier(xyz, yaw_deg, why):
    tracker = FrontierTracker(tracking_conf())
    tracker.add([observation((1.0, 1.0, 1.2), 0.0)], 0, 0)
    assert tracker.add([observation(xyz, yaw_deg)], 1, 1) == [1], why
    assert len(tracker) == 2
    np.testing.assert_allclose(tracker.get(0).position, [1.0, 1.0, 1.2])  # the old one is untouched
    assert tracker.get(0).observations == 1


def test_an_observation_merges_into_the_closest_matching_frontier():
    tracker = FrontierTracker(tracking_conf())
    tracker.add([observation((1.0, 1.0, 1.2)), observation((2.0, 1.0, 1.2))], 0, 0)
    assert tracker.add([observation((1.6, 1.0, 1.2))], 1, 1) == [1]  # 0.4 m from #1, 0.6 m from #0
    assert tracker.get(0).observations == 1 and tracker.get(1).observations == 2


def test_cluster_merge_joins_chains_by_the_public_codes_distance_and_keeps_the_oldest_id():
    """merge: clusters (cvg/FrontierNet merge_frontiers): d = L1 position + 2 (1 - cos), eps 1.8,
    single linkage. #0 and #1 1.0 m apart, same direction (d = 1.0); #2 1.5 m from #1 along y and
    60 degrees off (d = 1.5 + 2 * 0.5 = 2.5: apart); #3 1.5 m beyond #1 along x (d = 1.5: chained
    to #0 through #1, 2.5 m from it); #4 far away."""
    tracker = FrontierTracker(tracking_conf(merge="clusters"))
    tracker.add([observation((1.0, 1.0, 1.2), 0.0, gain=6.0), observation((2.0, 1.0, 1.2), 0.0, gain=2.0),
                 observation((2.0, 2.5, 1.2), 60.0, gain=3.0), observation((3.5, 1.0, 1.2), 0.0, gain=4.0),
                 observation((9.0, 9.0, 1.2), 0.0, gain=5.0)], parent_pose=0, step=0)
    tracker.add([observation((3.5, 1.0, 1.2), 0.0, gain=4.0)], parent_pose=3, step=2)  # #3 seen again
    assert sorted(tracker.merge_clusters()) == [1, 3]
    assert sorted(f.id for f in tracker) == [0, 2, 4]
    merged = tracker.get(0)
    np.testing.assert_allclose(merged.position, [(6 * 1.0 + 2 * 2.0 + 4 * 3.5) / 12, 1.0, 1.2])  # gain-weighted
    assert merged.gain_m3 == pytest.approx(4.0) and merged.predicted_gain_m3 == pytest.approx(4.0)  # plain means
    assert merged.observations == 4 and merged.parent_pose == 3 and (merged.first_step, merged.last_step) == (0, 2)
    assert tracker.removed["merged"] == 2 and tracker.get(2).observations == 1
    assert tracker.merge_clusters() == []  # nothing left to merge
    # the default (nearest) merges nothing here; a misspelt rule is refused
    default = FrontierTracker(tracking_conf())
    default.add([observation((1.0, 1.0, 1.2)), observation((2.0, 1.0, 1.2))], 0, 0)
    assert default.merge_clusters() == [] and len(default) == 2
    with pytest.raises(InputError, match="tracking.merge must be nearest or clusters, got 'dbscan'"):
        FrontierTracker(tracking_conf(merge="dbscan")).merge_clusters()


def test_ids_are_never_reused_after_removal():
    tracker = FrontierTracker(tracking_conf())
    assert tracker.add([observation((x, 1.0, 1.2)) for x in (0.0, 2.0, 4.0)], 0, 0) == [0, 1, 2]
    tracker.remove(2, "visited")
    tracker.remove(1, "blacklisted")
    assert tracker.removed["visited"] == 1 and tracker.removed["blacklisted"] == 1
    # a new observation where #2 was gets a fresh id
    assert tracker.add([observation((4.0, 1.0, 1.2))], 1, 1) == [3]
    assert sorted(f.id for f in tracker) == [0, 3]
    tracker.remove(3, "visited")
    tracker.remove(3, "visited")  # removing twice counts once
    assert tracker.removed["visited"] == 2


def test_frontier_camera_pose_looks_along_its_direction():
    tracker = FrontierTracker(tracking_conf())
    tracker.add([observation((1.0, 2.0, 1.2), 90.0)], 0, 0)
    T = tracker.get(0).camera_pose()
    np.testing.assert_allclose(T[:3, 3], [1.0, 2.0, 1.2])
    np.testing.assert_allclose(T[:3, 2], [0.0, 1.0, 0.0], atol=1e-12)  # optical axis (camera z) along +y
    np.testing.assert_allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-12)
    record = tracker.as_list()[0]
    assert record["id"] == 0 and record["position"] == [1.0, 2.0, 1.2]


# -- gain reduction against the map --------------------------------------------------------------


def room_map(*yaws_deg: float) -> OccupancyMap:
    """The room's map after level frames from (0.8, 1.5, 1.2) at these headings, in order."""
    lower, upper = room_boxes(*ROOM, wall=0.25)
    renderer = Renderer(box_scene(lower, upper, "tracking-room"), SMALL, (0, 0, 0))
    occupancy = OccupancyMap.from_bounds(BOUNDS, load_config("explore").map)
    for yaw in yaws_deg:
        T = level_pose(0.8, 1.5, yaw)
        frame = renderer.render(T)
        occupancy.integrate(frame.depth, frame.K, T)
    return occupancy


def visible_known(occupancy: OccupancyMap, frontier) -> float:
    view = tracking_conf()["gain_view"]
    return float(occupancy.visible_known_volume(frontier.camera_pose(), int(view["width_px"]),
                                                float(view["focal_px"]), float(view["max_depth_m"]))[0])


def test_gain_is_reduced_by_what_the_map_knows_beyond_the_predicting_frame():
    ahead_xyz = (1.0, 1.5, 1.2)  # looks along +x into the room
    no_cap = {"unknown_cap_yaw_offsets_deg": []}
    # the frame that predicted it saw part of its view: the prediction already left that part out
    tracker = FrontierTracker(tracking_conf(**no_cap))
    ahead = tracker.add([observation(ahead_xyz, 0.0, gain=20.0)], 0, 0)[0]
    seen_by_it = room_map(50.0)
    tracker.update_gains(seen_by_it)
    assert visible_known(seen_by_it, tracker.get(ahead)) > 2.0  # some of the room in front of it ...
    assert tracker.get(ahead).gain_m3 == pytest.approx(20.0)   # ... none of which counts twice

    # a later frame maps more of its view: that part is subtracted
    later = room_map(50.0, 0.0)
    tracker.update_gains(later)
    extra = visible_known(later, tracker.get(ahead)) - visible_known(seen_by_it, tracker.get(ahead))
    assert extra > 0.5
    assert tracker.get(ahead).gain_m3 == pytest.approx(20.0 - extra)
    assert tracker.get(ahead).predicted_gain_m3 == 20.0  # the prediction itself is kept

    # predicted by a frame that looked elsewhere, over a map that knows the room from before: reduced at birth
    born_late = FrontierTracker(tracking_conf(**no_cap))
    late = born_late.add([observation(ahead_xyz, 0.0, gain=20.0)], 0, 0)[0]
    map_then = room_map(0.0, -90.0)  # the latest frame looks at the wall y = 0
    born_late.update_gains(map_then)
    assert born_late.get(late).gain_m3 < 20.0 - 6.0

    # a re-observation is a fresh prediction relative to its own frame
    again = tracker.add([observation(ahead_xyz, 0.0, gain=5.0)], 1, 1)[0]
    assert again == ahead  # merged: predicted (20 + 5) / 2 = 12.5
    tracker.update_gains(later)  # its frame: the latest of `later`
    latest_only = later.visible_known_volume(tracker.get(ahead).camera_pose(), *(
        lambda v: (int(v["width_px"]), float(v["focal_px"]), float(v["max_depth_m"])))(tracking_conf()["gain_view"]),
        latest_frame_only=True)[0]
    assert tracker.get(ahead).gain_m3 == pytest.approx(max(0.0, 12.5 - (visible_known(later, tracker.get(ahead)) - latest_only)))


def min_gain() -> float:
    return float(tracking_conf()["min_gain_m3"])


def test_gain_is_capped_by_the_unknown_volume_the_frontier_can_still_see():
    conf = tracking_conf(gain_reduction="none")  # the cap alone
    at_xyz = (2.0, 1.5, 1.2)
    half_seen = FrontierTracker(conf)
    half_seen.add([observation(at_xyz, 0.0, gain=30.0)], 0, 0)
    half_seen.update_gains(room_map(0.0))  # one frame: most of the room around it is still unknown
    assert half_seen.get(0).gain_m3 > 5.0
    mapped = room_map(*range(0, 360, 45))  # a full turn: the closed room is mapped
    everywhere = FrontierTracker(conf)
    everywhere.add([observation(at_xyz, 0.0, gain=30.0)], 0, 0)
    everywhere.update_gains(mapped)
    assert everywhere.get(0).gain_m3 < min_gain() < half_seen.get(0).gain_m3  # below g_min: it will be dropped
    assert everywhere.get(0).predicted_gain_m3 == 30.0
    # the cap is the best of the headings: a frontier facing a mapped wall still sees the unknown beside it
    facing_wall = FrontierTracker(conf)
    facing_wall.add([observation((1.0, 0.5, 1.2), -90.0, gain=30.0)], 0, 0)
    facing_wall.update_gains(room_map(0.0))
    alone = FrontierTracker(tracking_conf(gain_reduction="none", unknown_cap_yaw_offsets_deg=[0.0]))
    alone.add([observation((1.0, 0.5, 1.2), -90.0, gain=30.0)], 0, 0)
    alone.update_gains(room_map(0.0))
    assert facing_wall.get(0).gain_m3 >= alone.get(0).gain_m3


def test_the_cap_is_the_minimum_of_gain_and_the_best_heading_over_every_heading():
    """The cap stops viewing a frontier once one heading sees its gain: same gains as viewing all."""
    conf = tracking_conf(gain_reduction="none")
    tracker = FrontierTracker(conf, view_z=CAMERA_Z)
    spots = [((2.0, 1.5, 1.2), 0.0, 30.0), ((1.0, 0.5, 1.0), -90.0, 30.0), ((3.0, 2.5, 1.2), 135.0, 4.0),
             ((0.6, 2.6, 1.4), 90.0, 0.5), ((2.0, 0.5, 1.2), 180.0, 4.0), ((3.2, 1.0, 1.2), -45.0, 30.0)]
    tracker.add([observation(xyz, yaw, gain) for xyz, yaw, gain in spots], 0, 0)
    assert len(tracker) == len(spots)  # far enough apart: none merged
    occupancy = room_map(0.0, 45.0)
    tracker.update_gains(occupancy)
    view = conf["gain_view"]
    settings = (int(view["width_px"]), float(view["focal_px"]), float(view["max_depth_m"]))
    capped = 0
    for frontier in tracker:
        poses = []
        for turn in np.radians(conf["unknown_cap_yaw_offsets_deg"]):
            T = frontier.camera_pose(yaw_offset=turn)
            T[2, 3] = CAMERA_Z
            poses.append(T)
        best = float(occupancy.visible_unknown_volume(np.stack(poses), *settings).max())
        assert frontier.gain_m3 == pytest.approx(min(frontier.predicted_gain_m3, best), rel=1e-9, abs=1e-9)
        capped += best < frontier.predicted_gain_m3
    assert 0 < capped < len(tracker)  # both cases are exercised


def test_unknown_gain_reduction_mode_is_an_input_error(mapped_room):
    tracker = FrontierTracker(tracking_conf(gain_reduction="since_forever"))
    tracker.add([observation((1.0, 1.5, 1.2))], 0, 0)
    with pytest.raises(InputError, match="beyond_frame, absolute or none"):
        tracker.update_gains(mapped_room)


def test_absolute_gain_reduction_drops_a_frontier_whose_view_is_mapped(mapped_room):
    tracker = FrontierTracker(tracking_conf(gain_reduction="absolute"))
    ahead, aside = tracker.add([observation((1.0, 1.5, 1.2), 0.0, gain=5.0),
                                observation((1.0, 1.5, 1.2), -90.0, gain=20.0)], 0, 0)
    tracker.update_gains(mapped_room)  # the public code's rule: everything visible and known counts
    assert tracker.get(ahead).gain_m3 == 0.0  # not negative
    assert tracker.prune(np.zeros((0, 4, 4))) == [ahead]
    assert tracker.removed["low_gain"] == 1 and tracker.get(aside) is not None


def test_gain_reduction_can_be_switched_off(mapped_room):
    tracker = FrontierTracker(tracking_conf(gain_reduction="none", unknown_cap_yaw_offsets_deg=[]))
    tracker.add([observation((1.0, 1.5, 1.2), 0.0, gain=20.0)], 0, 0)
    tracker.update_gains(mapped_room)
    assert tracker.get(0).gain_m3 == 20.0


def test_frontiers_below_g_min_are_dropped():
    tracker = FrontierTracker(tracking_conf(min_gain_m3=1.0))
    low, high = tracker.add([observation((0.0, 0.0, 1.2), gain=0.9), observation((3.0, 0.0, 1.2), gain=1.1)], 0, 0)
    assert tracker.prune(np.zeros((0, 4, 4))) == [low]
    assert [f.id for f in tracker] == [high] and tracker.removed["low_gain"] == 1


def test_view_z_puts_the_gain_view_and_the_occupied_check_at_the_robot_height(mapped_room):
    # a frontier anchored on the floor at the end of the sensor's range (z = 0 lies in the floor's voxels)
    floor_xyz = (2.5, 1.5, 0.0)
    assert mapped_room.state_at(np.array([floor_xyz]))[0] == OCCUPIED
    assert mapped_room.state_at(np.array([[2.5, 1.5, CAMERA_Z]]))[0] == FREE
    view = tracking_conf()["gain_view"]

    conf = tracking_conf(height_window_m=None, gain_reduction="absolute", relocate_m=0.0,  # where the checks are made
                         unknown_cap_yaw_offsets_deg=[])
    at_floor = FrontierTracker(conf)
    at_floor.add([observation(floor_xyz, 0.0, gain=30.0)], 0, 0)
    at_floor.update_gains(mapped_room)
    assert at_floor.prune(np.zeros((0, 4, 4)), mapped_room) == [0]
    assert at_floor.removed["occupied"] == 1

    at_robot = FrontierTracker(conf, view_z=CAMERA_Z)
    at_robot.add([observation(floor_xyz, 0.0, gain=30.0)], 0, 0)
    at_robot.update_gains(mapped_room)
    T = at_robot.get(0).camera_pose()
    T[2, 3] = CAMERA_Z
    known = mapped_room.visible_known_volume(T, int(view["width_px"]), float(view["focal_px"]),
                                             float(view["max_depth_m"]))[0]
    assert known > 0.5
    assert at_robot.get(0).gain_m3 == pytest.approx(30.0 - known)
    assert at_robot.prune(np.zeros((0, 4, 4)), mapped_room) == []
    assert at_robot.get(0).position[2] == 0.0  # the frontier itself is not moved


def test_with_view_z_only_frontiers_in_the_height_window_are_kept():
    low, high = tracking_conf()["height_window_m"]
    tracker = FrontierTracker(tracking_conf(), view_z=CAMERA_Z)
    heights = [CAMERA_Z + low - 0.05, CAMERA_Z + low + 0.05, CAMERA_Z, CAMERA_Z + high - 0.05, CAMERA_Z + high + 0.05]
    ids = tracker.add([observation((2.0 * i, 0.0, z)) for i, z in enumerate(heights)], 0, 0)
    assert ids == [None, 0, 1, 2, None]  # e.g. the tops of walls against the sky are not frontiers
    # without view_z the frontier's own height is all there is: no window
    assert FrontierTracker(tracking_conf()).add([observation((0.0, 0.0, CAMERA_Z + high + 1.0))], 0, 0) == [0]


def test_floor_frontiers_are_kept_only_at_the_end_of_the_sensor_range():
    """A large room's far part shows up as frontiers on the floor where the depth range (3.5 m)
    ends: they are kept although below the height window; floor frontiers nearer the camera
    (behind a sofa) are not."""
    conf = tracking_conf()
    low = conf["height_window_m"][0]
    camera = level_pose(0.0, 0.0, 0.0)
    floor_z = CAMERA_Z + low - 0.3
    far = SimpleNamespace(**vars(observation((3.3, 0.0, floor_z))), T_world_cam=camera)
    near = SimpleNamespace(**vars(observation((1.5, 0.5, floor_z))), T_world_cam=camera)
    assert np.linalg.norm(far.position - camera[:3, 3]) >= conf["floor_range_end_m"]
    assert FrontierTracker(conf, view_z=CAMERA_Z).add([far, near], 0, 0) == [0, None]
    assert FrontierTracker(tracking_conf(floor_range_end_m=None), view_z=CAMERA_Z).add([far], 0, 0) == [None]
    # above the window (the ceiling where the range ends, wall tops against the sky) nothing is kept
    high = SimpleNamespace(**vars(observation((3.3, 0.0, CAMERA_Z + conf["height_window_m"][1] + 1.0))),
                           T_world_cam=camera)
    assert FrontierTracker(conf, view_z=CAMERA_Z).add([high], 0, 0) == [None]


def test_a_blacklisted_frontier_leaves_a_tombstone_that_discards_its_reobservations():
    tracker = FrontierTracker(tracking_conf())
    given_up, dropped = tracker.add([observation((1.0, 1.0, 1.2), 0.0), observation((4.0, 1.0, 1.2), 0.0)], 0, 0)
    tracker.remove(given_up, "blacklisted")
    tracker.remove(dropped, "visited")
    again = tracker.add([observation((1.2, 1.0, 1.2), 10.0),    # the blacklisted one, seen again
                         observation((1.0, 1.0, 1.2), 180.0),   # same place, looking the other way
                         observation((4.0, 1.0, 1.2), 0.0)], 1, 1)  # a visited one may come back
    assert again == [None, 2, 3]
    assert tracker.removed["blacklisted"] == 1 and len(tracker) == 2


def test_a_visited_frontier_of_a_fresh_set_buries_its_place_whatever_the_direction_of_its_return():
    # a map frontier of a pocket the camera cannot see from where the robot stood is proposed again every
    # frame, its direction following the robot: with bury_visited its place stays given up on until forgiven
    at = level_pose(1.3, 1.0, 0.0)  # 0.3 m from the frontier, looking along its direction
    for bury, expected in ((False, [2, 3, 4]), (True, [None, None, 2])):
        tracker = FrontierTracker(tracking_conf())
        pocket, far = tracker.add([observation((1.0, 1.0, 1.2), 0.0), observation((3.5, 1.0, 1.2), 0.0)], 0, 0)
        assert tracker.prune(at[None], bury_visited=bury) == [pocket]
        assert tracker.get(far) is not None  # no pose stood there: kept, and buries nothing
        again = tracker.add([observation((1.0, 1.0, 1.2), 0.0), observation((1.4, 1.2, 1.2), 135.0),  # back, turned
                             observation((1.0, 2.0, 1.2), 0.0)], 1, 1)  # 1 m away (merge distance 0.6 m)
        assert again == expected
        assert tracker.removed["visited"] == 1
    tracker.forgive()  # (planner.forgive_before_stop, before a stop): proposed again
    assert not tracker.buried_visits and tracker.add([observation((1.0, 1.0, 1.2), 90.0)], 2, 2) == [3]


def test_frontier_in_occupied_space_is_dropped(mapped_room):
    tracker = FrontierTracker(tracking_conf(gain_reduction="none", relocate_m=0.0))
    wall, free = tracker.add([observation((4.0, 1.5, 1.2), 180.0), observation((2.0, 1.5, 1.2), 90.0)], 0, 0)
    assert tracker.prune(np.zeros((0, 4, 4)), mapped_room) == [wall]
    assert tracker.removed["occupied"] == 1 and tracker.get(free) is not None
    # without a map (map-free mode) nothing is checked against occupancy
    tracker.add([observation((4.0, 1.5, 1.2), 180.0)], 1, 1)
    assert tracker.prune(np.zeros((0, 4, 4))) == []


def test_frontier_just_inside_a_wall_moves_out_to_the_nearest_unoccupied_voxel(mapped_room):
    # the wall x = 4 is mapped occupied; x = 4.0 lies one voxel deep, 4.3 behind the wall's mapped layer
    assert mapped_room.state_at(np.array([[4.0, 1.5, 1.2]]))[0] == OCCUPIED
    tracker = FrontierTracker(tracking_conf(gain_reduction="none", relocate_m=0.3))
    beside, deep = tracker.add([observation((4.0, 1.5, 1.2), 90.0), observation((1.0, 1.5, 1.2), 90.0)], 0, 0)
    assert tracker.prune(np.zeros((0, 4, 4)), mapped_room) == []
    moved = tracker.get(beside).position
    assert mapped_room.state_at(moved[None])[0] != OCCUPIED
    assert 0.0 < np.linalg.norm(moved[:2] - [4.0, 1.5]) <= 0.3 and moved[2] == 1.2
    assert tracker.get(deep).position.tolist() == [1.0, 1.5, 1.2]  # free: not moved
    # nothing unoccupied within reach: dropped
    buried = FrontierTracker(tracking_conf(gain_reduction="none", relocate_m=0.05))
    buried.add([observation((4.0, 1.5, 1.2), 90.0)], 0, 0)
    assert buried.prune(np.zeros((0, 4, 4)), mapped_room) == [0]


# -- visited poses ---------------------------------------------------------------------------------


@pytest.mark.parametrize("pose_xy, pose_yaw_deg, dropped", [
    ((1.3, 1.0), 0.0, True),     # 0.3 m away, same heading
    ((1.0, 1.3), 20.0, True),    # 0.3 m away, 0.35 rad off (< 0.4 rad)
    ((1.0, 1.0), 180.0, False),  # on the spot, looking the other way
    ((1.0, 1.0), 30.0, False),   # on the spot, 0.52 rad off
    ((1.6, 1.0), 0.0, False),    # 0.6 m away (> 0.5 m), same heading
])
def test_a_visited_pose_drops_the_frontier_it_looked_at(pose_xy, pose_yaw_deg, dropped):
    tracker = FrontierTracker(tracking_conf())
    tracker.add([observation((1.0, 1.0, 1.2), 0.0, gain=5.0)], 0, 0)
    far_away = level_pose(-5.0, -5.0, 0.0)
    poses = np.stack([far_away, level_pose(*pose_xy, pose_yaw_deg)])
    assert tracker.prune(poses) == ([0] if dropped else [])
    assert tracker.removed["visited"] == int(dropped)


def test_visited_uses_the_horizontal_heading_of_a_tilted_camera():
    tracker = FrontierTracker(tracking_conf())
    tracker.add([observation((1.0, 1.0, 1.2), 90.0, gain=5.0)], 0, 0)
    tilted = pose_from_heading(1.0, 1.2, 1.2, np.radians(90.0), np.radians(-30.0))  # looks down and along +y
    assert tracker.prune(tilted[None]) == [0]


def test_max_frontiers_keeps_the_highest_gains():
    tracker = FrontierTracker(tracking_conf(max_frontiers=3))
    gains = [2.0, 9.0, 5.0, 1.5, 7.0]
    ids = tracker.add([observation((2.0 * i, 0.0, 1.2), gain=g) for i, g in enumerate(gains)], 0, 0)
    tracker.prune(np.zeros((0, 4, 4)))
    assert sorted(f.id for f in tracker) == sorted([ids[1], ids[4], ids[2]])
    assert tracker.removed["low_gain"] == 2

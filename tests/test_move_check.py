"""The explorer's move check (issue 5): a move may not bring the body next to a wall end that the
camera never saw. Such a wall end is unknown in the map, not occupied: the check has the camera
look at it first."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import box_scene, room_boxes
from frontiernet.config import load_config
from frontiernet.depth import make_depth_source
from frontiernet.exploration.explorer import Explorer
from frontiernet.exploration.methods import MethodContext, make_method
from frontiernet.geometry import pose_from_heading
from frontiernet.mapping import FREE, UNKNOWN, OccupancyMap
from frontiernet.simulator.camera import PinholeCamera, Renderer
from frontiernet.simulator.voxels import voxelize_scene

ROBOT = (2.0, 1.5, 1.2)
PILLAR = ((1.65, 1.3, 0.0), (1.85, 1.6, 2.5))  # 0.15 m west of the robot (body 0.1 m), from floor to ceiling
SMALL = PinholeCamera(120, 120, 75.0, 75.0, 59.5, 59.5, 3.5)  # the paper's field of view, 120 px


def room_scene(pillar: bool):
    lower, upper = room_boxes(4.0, 3.0, 2.5)
    if pillar:
        lower, upper = [*lower, PILLAR[0]], [*upper, PILLAR[1]]
    return box_scene(lower, upper, f"move-check-{pillar}")


def explorer_facing_away_from_the_west(pillar: bool) -> Explorer:
    """A classic explorer at ROBOT that has looked north, east and south, never west."""
    scene = room_scene(pillar)
    conf, sim = load_config("explore"), load_config("sim")
    voxels = voxelize_scene(scene, sim.voxels)
    context = MethodContext(conf, sim, scene=scene, voxels=voxels)
    explorer = Explorer(context, Renderer(scene, SMALL, (0, 0, 0)), make_method("classic", context),
                        make_depth_source("ground_truth", load_config("depth")), pose_from_heading(*ROBOT, yaw=np.pi / 2))
    for yaw_deg in (90, 45, 0, -45, -90):
        turn(explorer, np.radians(yaw_deg))
    return explorer


def turn(explorer: Explorer, yaw: float) -> None:
    result = explorer.agent.move_to(pose_from_heading(*explorer.agent.position, yaw=yaw))
    assert not result.collided
    explorer.sense()


def north_west_target(explorer: Explorer) -> np.ndarray:
    """One increment (0.1 m) towards the north-west, the direction the KTH robot turned into."""
    x, y, z = explorer.agent.position
    step = 0.1 / np.sqrt(2.0)
    return pose_from_heading(x - step, y + step, z, yaw=np.radians(135))


@pytest.mark.parametrize("pillar", [True, False])
def test_an_unseen_wall_end_beside_a_move_is_looked_at_before_the_move(pillar):
    explorer = explorer_facing_away_from_the_west(pillar)
    T, target = explorer.agent.pose, north_west_target(explorer)
    # the target itself is mapped free and no occupied voxel is near: the old check let it pass
    assert explorer.map.state_at(target[None, :3, 3])[0] == FREE
    assert not explorer.map.cylinder_touches_occupied(target[:2, 3], explorer.body_radius, *explorer.move_check.band)
    verdict, look_xy = explorer.move_check(T, target)
    assert verdict == "look"
    assert look_xy[0] < ROBOT[0] - 0.1  # the unknown voxel to face lies to the west, where the pillar may be
    turn(explorer, float(np.arctan2(look_xy[1] - ROBOT[1], look_xy[0] - ROBOT[0])))
    verdict, _ = explorer.move_check(explorer.agent.pose, target)
    # once seen: the pillar blocks the move; without it the move is allowed
    assert verdict == ("fail" if pillar else "ok")
    if pillar:  # and the move would have collided in the simulator
        assert explorer.agent._clearance(target[None, :3, 3])[0] < explorer.agent.radius


def test_an_unknown_voxel_still_unknown_once_faced_is_passed_not_failed(monkeypatch):
    explorer = explorer_facing_away_from_the_west(False)
    T, target = explorer.agent.pose, north_west_target(explorer)
    verdict, look_xy = explorer.move_check(T, target)
    assert verdict == "look"
    # the camera faces the voxel, yet the map learns nothing (as between rays, or hidden)
    monkeypatch.setattr("frontiernet.exploration.move_check.looked_at", lambda T, xy: True)
    verdict, _ = explorer.move_check(T, target)
    assert verdict == "ok"  # the move check of the published run failed the route here
    assert any(np.allclose(xy, look_xy) for xy in explorer.move_check.faced_unknown)
    assert explorer.map.state_at(np.array([[*look_xy, ROBOT[2]]]))[0] == UNKNOWN


def test_a_held_look_ends_once_the_voxel_is_mapped():
    from frontiernet.planning.planner import Route

    explorer = explorer_facing_away_from_the_west(False)
    turn(explorer, np.pi / 2)  # north again; the west is still unseen
    x, y, _ = explorer.agent.position
    waypoint = np.array([x - 0.25, y + 0.45])  # 30 deg off the heading: a move that turns a little
    explorer.route = Route(0, waypoint[None], 1, 0.5, 1.0)
    first = explorer.next_pose()
    assert np.allclose(first[:2, 3], [x, y]) and explorer.look_xy is not None  # a look, held
    # the voxel gets mapped before the camera faces it (another frame saw it)
    T_west = pose_from_heading(x, y, ROBOT[2], yaw=np.pi)
    frame = explorer.renderer.render(T_west)
    explorer.map.integrate(frame.depth, frame.K, T_west)
    assert not explorer.move_check.unknown(explorer.look_xy)
    second = explorer.next_pose()
    assert not np.allclose(second[:2, 3], [x, y])  # the route goes on: no turning to a mapped voxel


def test_nearest_unknown_in_disk_is_the_nearest_unobserved_cell_of_the_layer():
    occupancy = OccupancyMap.from_bounds(np.array([[-0.45] * 3, [4.45, 3.45, 2.95]]), load_config("explore").map)
    scene = room_scene(False)
    renderer = Renderer(scene, SMALL, (0, 0, 0))
    T = pose_from_heading(1.0, 1.5, 1.2, yaw=0.0)  # looks along +x: everything behind x = 1 is unknown
    frame = renderer.render(T)
    occupancy.integrate(frame.depth, frame.K, T)
    assert occupancy.nearest_unknown_in_disk([2.5, 1.5], 0.22, 1.2) is None  # in the middle of the view
    centre = occupancy.nearest_unknown_in_disk([1.2, 1.5], 0.22, 1.2)  # the disk reaches behind the camera
    assert centre is not None
    assert occupancy.state_at(np.array([[*centre, 1.2]]))[0] == UNKNOWN
    gap = np.maximum(np.abs(centre - [1.2, 1.5]) - 0.05, 0.0)
    nearest = float(np.hypot(*gap))
    assert nearest < 0.22
    # no unknown point of the layer's cells inside the disk is nearer than the cell returned
    xs, ys = np.meshgrid(np.arange(0.9, 1.5, 0.01), np.arange(1.2, 1.8, 0.01), indexing="ij")
    points = np.stack([xs.ravel(), ys.ravel(), np.full(xs.size, 1.2)], 1)
    distance = np.hypot(points[:, 0] - 1.2, points[:, 1] - 1.5)
    unknown = occupancy.state_at(points) == UNKNOWN
    assert distance[unknown].min() >= nearest - 1e-9
    # excluded cells do not count: the next nearest comes out, and none once all are excluded
    second = occupancy.nearest_unknown_in_disk([1.2, 1.5], 0.22, 1.2, exclude=centre[None])
    assert second is not None and not np.allclose(second, centre)
    assert np.hypot(*np.maximum(np.abs(second - [1.2, 1.5]) - 0.05, 0.0)) >= nearest - 1e-9
    excluded = [centre]
    while (found := occupancy.nearest_unknown_in_disk([1.2, 1.5], 0.22, 1.2, exclude=np.array(excluded))) is not None:
        excluded.append(found)
        assert len(excluded) < 100
    # a disk of radius 0 around a free point holds nothing unknown
    assert occupancy.state_at(np.array([[1.2, 1.5, 1.2]]))[0] == FREE
    assert occupancy.nearest_unknown_in_disk([1.2, 1.5], 0.0, 1.2) is None
    # a second frame looking back maps what lay behind the first camera
    T_back = pose_from_heading(3.0, 1.5, 1.2, yaw=np.pi)
    frame = renderer.render(T_back)
    occupancy.integrate(frame.depth, frame.K, T_back)
    assert occupancy.nearest_unknown_in_disk([1.2, 1.5], 0.22, 1.2) is None


def _longest_turn_back_and_forth(trajectory: list) -> int:
    """The most consecutive increments that turn on the spot, each the other way from the one before."""
    T = np.asarray(trajectory, np.float64)
    still = np.linalg.norm(np.diff(T[:, :2, 3], axis=0), axis=1) < 1e-6
    turns = np.diff(np.unwrap(np.arctan2(T[:, 1, 2], T[:, 0, 2])))
    longest = run = 0
    for i in range(1, len(turns)):
        run = run + 1 if still[i] and still[i - 1] and turns[i] * turns[i - 1] < 0 else 0
        longest = max(longest, run)
    return longest


def _explore(tmp_path, scene: str, method: str, start: str | None, steps: int, seed: int = 0) -> dict:
    import json

    from frontiernet.exploration.run import load_run_config, main

    conf = load_run_config(overrides=["motion.start_turn_deg=0"])  # no turn first: the check meets unknown at once
    main(conf, scene, tmp_path / "run", method=method, max_steps=steps, start=start, seed=seed, video=False,
         progress=False)
    return json.loads((tmp_path / "run" / "trajectory.json").read_text())


@pytest.mark.slow
def test_a_look_the_move_check_asks_for_is_held_until_faced(tmp_path):
    # the check turned the robot one increment towards an unknown cell, the route turned it one back
    # towards its waypoint, and so on: six increments of this from this start (seed 2) before the
    # look was held over the next increments
    trajectory = _explore(tmp_path, "procedural:3", "classic", None, 60, seed=2)
    assert _longest_turn_back_and_forth(trajectory["T_world_cam"]) <= 2


@pytest.mark.slow
def test_the_oracle_leaves_its_start_without_a_start_turn(tmp_path, shared_data):
    # the livelock at its worst: from this start in the shared house the oracle turned back and forth
    # for all 300 steps of its budget (282 increments), path 0 m, Vox@100 11.9 % (classic: 62.0 %)
    trajectory = _explore(tmp_path, str(shared_data / "scenes" / "aws_small_house.glb"), "oracle",
                          "-0.45,2.95,1.1986,-105.3378", 40)
    assert _longest_turn_back_and_forth(trajectory["T_world_cam"]) <= 2
    positions = np.asarray(trajectory["T_world_cam"])[:, :2, 3]
    assert np.linalg.norm(positions[-1] - positions[0]) > 1.0


def map_free_explorer(frames: int) -> Explorer:
    """A map-free classic explorer at ROBOT that has looked west, at the pillar 0.15 m away."""
    return explorer_facing_the_pillar(mode="map_free", obstacle_memory_frames=frames)


@pytest.mark.parametrize("frames", [0, 10])
def test_map_free_moves_stop_short_of_obstacles_the_robot_has_seen_only_with_a_memory(frames):
    explorer = map_free_explorer(frames)
    x, y, z = explorer.agent.position
    towards_pillar = pose_from_heading(x - 0.11, y, z, yaw=np.pi)  # 0.04 m from its face: inside the body
    away = pose_from_heading(x + 0.11, y, z, yaw=np.pi)
    assert explorer.move_check(explorer.agent.pose, towards_pillar)[0] == ("fail" if frames else "ok")
    assert explorer.move_check(explorer.agent.pose, away)[0] == "ok"


def test_the_map_free_memory_forgets_after_its_frames():
    explorer = map_free_explorer(2)
    x, y, z = explorer.agent.position
    towards_pillar = pose_from_heading(x - 0.11, y, z, yaw=np.pi)
    for yaw_deg in (90, 0):  # two frames that do not see the pillar push the one that did out
        turn(explorer, np.radians(yaw_deg))
    assert explorer.move_check(explorer.agent.pose, towards_pillar)[0] == "ok"


def explorer_facing_the_pillar(depth: str = "ground_truth", **planner) -> Explorer:
    """A classic explorer at ROBOT that has looked west, at the pillar 0.15 m away, with `planner` keys
    set and the `depth` source."""
    from omegaconf import OmegaConf

    scene = room_scene(True)
    conf = OmegaConf.merge(load_config("explore"), {"planner": planner})
    sim = load_config("sim")
    voxels = voxelize_scene(scene, sim.voxels)
    context = MethodContext(conf, sim, scene=scene, voxels=voxels)
    explorer = Explorer(context, Renderer(scene, SMALL, (0, 0, 0)), make_method("classic", context),
                        make_depth_source(depth, load_config("depth")), pose_from_heading(*ROBOT, yaw=np.pi))
    explorer.sense()
    return explorer


def test_a_move_into_a_cell_the_robot_has_passed_through_passes_whatever_the_map_says():
    """``planner.traversed_is_free``: where the robot has been is open to the move check, as to the
    planner. Here the mapped pillar plays a doorway a noisy depth source has sealed behind the robot."""
    assert explorer_facing_the_pillar(traversed_is_free=False).traversed is None
    # on by default, ground truth too: a door narrower in the map than the planner's clearance shut the
    # robot in the room behind it (KTH 50010535_PLAN1, docs/results/2026-12-06-kth-stop.md)
    assert explorer_facing_the_pillar().traversed is not None
    assert explorer_facing_the_pillar(mode="map_free", traversed_is_free=True).traversed is None  # map mode only
    explorer = explorer_facing_the_pillar(traversed_is_free=True)
    x, y, z = explorer.agent.position
    assert explorer.traversed.contains((x, y)) and explorer.traversed.mask.sum() == 1
    towards_pillar = pose_from_heading(x - 0.11, y, z, yaw=np.pi)  # 0.04 m from its face: inside the body
    pillar_xy = np.array([1.82, 1.5])  # in the voxel layer of its face (x = 1.85), the target's cell
    assert explorer.move_check(explorer.agent.pose, towards_pillar)[0] == "fail"
    assert explorer.move_check.blocked(pillar_xy)
    explorer.traversed.add(pillar_xy)  # as if the robot had walked through it (the pillar a mapping error)
    assert explorer.move_check(explorer.agent.pose, towards_pillar) == ("ok", None)
    assert not explorer.move_check.blocked(pillar_xy)
    # the explorer adds each pose it senses from
    turn(explorer, 0.0)
    assert explorer.traversed.contains((x, y))


def test_monocular_traversed_is_free_keeps_the_way_back_open_for_monocular_depth_only():
    """``planner.monocular_traversed_is_free``: only a depth source with flying pixels (whose map smears
    walls into the doorways the robot came through) gets the record."""
    explorer = explorer_facing_the_pillar(monocular_traversed_is_free=True, traversed_is_free=False)
    assert explorer.traversed is None  # ground truth: the map alone
    explorer = explorer_facing_the_pillar("emulated", monocular_traversed_is_free=True, traversed_is_free=False)
    assert explorer.traversed is not None and explorer.traversed.contains(explorer.agent.position[:2])
    assert explorer_facing_the_pillar("emulated", monocular_traversed_is_free=False, traversed_is_free=False).traversed is None

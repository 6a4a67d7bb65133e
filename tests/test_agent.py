"""Pose sampling, pose checks, collision-checked motion and the paper's step count."""

from __future__ import annotations

import numpy as np
import pytest

from frontiernet.errors import InputError
from frontiernet.geometry import pose_from_heading, rotation_angle
from frontiernet.simulator.agent import Agent, StepCounter
from frontiernet.simulator.poses import check_pose, height_above_surface, sample_poses, sample_poses_detailed
from frontiernet.simulator.raycast import distance_to_surface

from conftest import box_scene, room_boxes, sim_section

AGENT = sim_section("agent")


def _poses_conf(**changes):
    return sim_section("poses", **changes)


# ----------------------------------------------------------------------------- poses


def test_sampled_poses_respect_height_clearance_and_free_space(two_room_scene, two_room_voxels):
    conf = _poses_conf(height_range_m=[0.6, 1.5], pitch_range_deg=[-10, 5], min_clearance_m=0.35)
    sampled = sample_poses_detailed(two_room_scene, two_room_voxels, 60, 7, conf)
    T = sampled.T_world_cam
    assert T.shape == (60, 4, 4) and T.dtype == np.float64
    assert np.allclose(T[:, 3], [0, 0, 0, 1])
    assert np.allclose(np.einsum("nji,njk->nik", T[:, :3, :3], T[:, :3, :3]), np.eye(3), atol=1e-9)
    positions = T[:, :3, 3]
    heights = height_above_surface(two_room_scene, positions)
    assert np.all((heights >= 0.6 - 1e-5) & (heights <= 1.5 + 1e-5))
    assert np.allclose(heights, sampled.heights, atol=1e-4)
    assert np.all(distance_to_surface(two_room_scene, positions) >= 0.35 - 1e-5)
    assert two_room_voxels.is_explorable(positions).all()
    assert np.all((sampled.pitches >= np.deg2rad(-10) - 1e-12) & (sampled.pitches <= np.deg2rad(5) + 1e-12))
    assert np.allclose(np.arcsin(T[:, 2, 2]), sampled.pitches)  # optical axis z component
    assert np.abs(T[:, 2, 0]).max() < 1e-12  # no roll: the camera's x axis is horizontal
    assert (positions[:, 0] < 2.9).any() and (positions[:, 0] > 3.1).any()  # both rooms


def test_pose_sampling_is_deterministic_per_seed(two_room_scene, two_room_voxels):
    a = sample_poses(two_room_scene, two_room_voxels, 20, 3, _poses_conf())
    b = sample_poses(two_room_scene, two_room_voxels, 20, np.random.default_rng(3), _poses_conf())
    c = sample_poses(two_room_scene, two_room_voxels, 20, 4, _poses_conf())
    assert np.array_equal(a, b)
    assert not np.allclose(a, c)
    assert sample_poses(two_room_scene, two_room_voxels, 0, 3, _poses_conf()).shape == (0, 4, 4)


def test_impossible_pose_sampling_is_an_input_error(two_room_scene, two_room_voxels):
    conf = _poses_conf(height_range_m=[5.0, 6.0], max_candidates=3000)
    with pytest.raises(InputError, match="found only 0 of 5 valid camera poses"):
        sample_poses(two_room_scene, two_room_voxels, 5, 0, conf)
    with pytest.raises(InputError, match="seed"):
        sample_poses(two_room_scene, two_room_voxels, 5, "x", _poses_conf())
    with pytest.raises(InputError, match="height_range_m"):
        sample_poses(two_room_scene, two_room_voxels, 5, 0, _poses_conf(height_range_m=[2.0, 1.0]))


def test_check_pose_accepts_free_space_and_names_bad_poses(two_room_scene, two_room_voxels):
    good = pose_from_heading(1.0, 1.0, 1.2, 0.3)
    assert np.allclose(check_pose(two_room_scene, two_room_voxels, good, _poses_conf()), [1.0, 1.0, 1.2])
    assert np.allclose(check_pose(two_room_scene, two_room_voxels, np.array([5.0, 3.0, 1.0]), _poses_conf()), [5.0, 3.0, 1.0])
    with pytest.raises(InputError, match=r"pose outside the scene.*\(20\.000, 1\.000, 1\.200\)"):
        check_pose(two_room_scene, two_room_voxels, pose_from_heading(20.0, 1.0, 1.2, 0.0), _poses_conf())
    with pytest.raises(InputError, match=r"pose inside an obstacle.*\(3\.000, 0\.500, 1\.000\)"):
        check_pose(two_room_scene, two_room_voxels, np.array([3.0, 0.5, 1.0]), _poses_conf())  # in the partition
    with pytest.raises(InputError, match=r"pose inside an obstacle.*0\.010 m from the mesh"):
        check_pose(two_room_scene, two_room_voxels, np.array([0.01, 2.0, 1.0]), _poses_conf())  # touching a wall
    with pytest.raises(InputError, match="rigid"):
        check_pose(two_room_scene, two_room_voxels, np.eye(4) * 2, _poses_conf())


def test_check_pose_outside_the_building_within_bounds():
    lower, upper = room_boxes(4.0, 4.0, 2.5)
    lower.append((-8, -8, -0.3))
    upper.append((12, 12, -0.2))
    scene = box_scene(lower, upper, "room-on-ground")
    from frontiernet.simulator.voxels import voxelize_scene

    voxels = voxelize_scene(scene, sim_section("voxels"))
    with pytest.raises(InputError, match=r"pose outside the scene.*outside the building"):
        check_pose(scene, voxels, np.array([8.0, 8.0, 1.0]), _poses_conf())


# ----------------------------------------------------------------------------- steps


def test_step_counter_translation_rule():
    counter = StepCounter(0.1, np.deg2rad(10), T_start=pose_from_heading(0, 0, 1, 0))
    counted = [counter.update(pose_from_heading(0.05 * i, 0, 1, 0)) for i in range(1, 10)]
    assert counted == [False, False, True] * 3  # 0.10 m is not > 0.1 m, 0.15 m is
    assert counter.count == 3


def test_step_counter_rotation_rule_and_geodesic_angle():
    counter = StepCounter(0.1, np.deg2rad(10), T_start=pose_from_heading(0, 0, 1, 0))
    turns = [counter.update(pose_from_heading(0, 0, 1, np.deg2rad(5 * i))) for i in range(1, 10)]
    assert turns == [False, False, True] * 3
    counter.reset(pose_from_heading(0, 0, 1, 0))
    assert counter.update(pose_from_heading(0, 0, 1, 0, np.deg2rad(11)))  # pitch counts too
    assert not counter.update(pose_from_heading(0.06, 0.06, 1, 0, np.deg2rad(11)))  # 0.085 m
    assert counter.count_path([pose_from_heading(0.3 * i, 0, 1, 0) for i in range(5)]) == 5
    counter = StepCounter(0.1, np.deg2rad(10))  # no start pose: the first update only sets the reference
    assert not counter.update(pose_from_heading(5, 5, 1, 1))
    with pytest.raises(InputError, match="positive"):
        StepCounter(0.0, np.deg2rad(10))


# ----------------------------------------------------------------------------- agent


def test_free_move_reaches_target_and_counts_a_step(two_room_scene, two_room_voxels):
    agent = Agent(two_room_scene, pose_from_heading(1.0, 1.0, 1.2, 0.0), AGENT, voxels=two_room_voxels)
    target = pose_from_heading(2.0, 3.0, 1.4, np.pi / 2, 0.1)
    result = agent.move_to(target)
    assert result.reached and not result.collided and not result.left_free_space and result.contact_point is None
    assert np.allclose(result.T_world_cam, target) and np.allclose(agent.pose, target)
    assert result.distance_m == pytest.approx(np.sqrt(1 + 4 + 0.04))
    assert result.steps_added == 1 and agent.steps == 1
    assert agent.trajectory.shape == (2, 4, 4)
    # through the door into the other room
    results = agent.follow([pose_from_heading(2.0, 1.95, 1.0, 0.0), pose_from_heading(4.0, 1.95, 1.0, 0.0)])
    assert [r.reached for r in results] == [True, True] and agent.steps == 3


def test_move_into_a_wall_stops_before_it(two_room_scene):
    radius = float(AGENT.radius_m)
    agent = Agent(two_room_scene, pose_from_heading(1.5, 0.5, 1.2, 0.0), AGENT)
    target = pose_from_heading(4.5, 0.5, 1.2, np.pi)  # through the partition at x = 2.9
    result = agent.move_to(target)
    assert result.collided and not result.reached
    final = result.T_world_cam[:3, 3]
    assert final[0] < 2.9 - radius + 1e-9 and final[0] > 2.9 - radius - 0.05  # stopped right before it
    assert distance_to_surface(two_room_scene, final[None])[0] >= radius - 1e-5
    assert result.clearance_m >= radius - 1e-5
    assert result.blocked_at is not None and result.blocked_at[0] <= 2.9
    # the bump sensor's report: the point of the partition's face the sphere touched
    assert np.allclose(result.contact_point, [2.9, 0.5, 1.2], atol=0.01)
    assert result.distance_m == pytest.approx(final[0] - 1.5)
    # orientation interpolated part of the way (slerp), not snapped to the target
    angle = rotation_angle(pose_from_heading(0, 0, 0, 0.0)[:3, :3], result.T_world_cam[:3, :3])
    assert 0 < angle < np.pi
    assert agent.collisions == 1
    # a move that starts blocked does not move at all
    again = agent.move_to(target)
    assert again.collided and again.distance_m < 0.05 and again.steps_added == 0


def test_long_move_never_passes_through_a_thin_wall():
    lower, upper = room_boxes(8.0, 4.0, 2.5)
    lower.append((4.0, 0.0, 0.0))
    upper.append((4.01, 4.0, 2.5))  # a 1 cm sheet across the room
    scene = box_scene(lower, upper, "thin-sheet")
    agent = Agent(scene, pose_from_heading(1.0, 2.0, 1.2, 0.0), AGENT)
    result = agent.move_to(pose_from_heading(7.0, 2.0, 1.2, 0.0))
    assert result.collided and result.T_world_cam[0, 3] < 4.0
    samples = np.linspace(1.0, result.T_world_cam[0, 3], 400)
    path = np.stack([samples, np.full(400, 2.0), np.full(400, 1.2)], axis=1)
    assert distance_to_surface(scene, path).min() >= float(AGENT.radius_m) - 1e-5


def test_agent_leaving_free_space_is_stopped():
    lower, upper = room_boxes(3.0, 3.0, 2.5, ceiling=False)
    scene = box_scene(lower, upper, "open-top")
    from frontiernet.simulator.voxels import voxelize_scene

    voxels = voxelize_scene(scene, sim_section("voxels"))
    agent = Agent(scene, pose_from_heading(1.5, 1.5, 1.2, 0.0), AGENT, voxels=voxels)
    result = agent.move_to(pose_from_heading(1.5, 1.5, 6.0, 0.0))  # straight up out of the room
    assert result.left_free_space and not result.collided and not result.reached
    assert voxels.is_explorable(result.T_world_cam[None, :3, 3]).all()


def test_agent_steps_follow_the_paper_rule(two_room_scene):
    agent = Agent(two_room_scene, pose_from_heading(1.0, 2.0, 1.2, 0.0), AGENT)
    moves = [agent.move_to(pose_from_heading(1.0 + 0.05 * i, 2.0, 1.2, 0.0)) for i in range(1, 10)]
    assert [m.steps_added for m in moves] == [0, 0, 1] * 3
    turns = [agent.move_to(pose_from_heading(1.45, 2.0, 1.2, np.deg2rad(5 * i))) for i in range(1, 7)]
    assert [m.steps_added for m in turns] == [0, 0, 1] * 2 and agent.steps == 5
    assert agent.move_to(agent.pose).steps_added == 0  # staying put adds nothing


def test_bad_agent_inputs_are_input_errors(two_room_scene):
    with pytest.raises(InputError, match=r"start pose inside an obstacle.*\[0\.05, 2\.0, 1\.2\]"):
        Agent(two_room_scene, pose_from_heading(0.05, 2.0, 1.2, 0.0), AGENT)
    agent = Agent(two_room_scene, pose_from_heading(1.0, 2.0, 1.2, 0.0), AGENT)
    with pytest.raises(InputError, match="target pose"):
        agent.move_to(np.eye(3))
    with pytest.raises(InputError, match="radius_m.*-1"):
        Agent(two_room_scene, pose_from_heading(1.0, 2.0, 1.2, 0.0), sim_section("agent", radius_m=-1))


def test_check_pose_accepts_a_camera_close_to_a_wall(two_room_scene, two_room_voxels):
    # 4 cm from the wall: in an occupied voxel, but on the free side of the surface
    for position in ([0.04, 2.0, 1.0], [2.86, 0.5, 1.0], [3.14, 0.5, 1.0], [1.0, 1.0, 2.46]):
        assert np.allclose(check_pose(two_room_scene, two_room_voxels, np.array(position), _poses_conf()), position)

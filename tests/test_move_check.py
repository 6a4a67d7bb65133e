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
PILLAR = ((1.55, 1.3, 0.0), (1.75, 1.6, 2.5))  # 0.25 m west of the robot, from floor to ceiling
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
    assert not explorer.map.cylinder_touches_occupied(target[:2, 3], explorer.body_radius, *explorer._band())
    verdict, look_xy = explorer._check_move(T, target)
    assert verdict == "look"
    assert look_xy[0] < ROBOT[0] - 0.1  # the unknown voxel to face lies to the west, where the pillar may be
    turn(explorer, float(np.arctan2(look_xy[1] - ROBOT[1], look_xy[0] - ROBOT[0])))
    verdict, _ = explorer._check_move(explorer.agent.pose, target)
    # once seen: the pillar blocks the move; without it the move is allowed
    assert verdict == ("fail" if pillar else "ok")
    if pillar:  # and the move would have collided in the simulator
        assert explorer.agent._clearance(target[None, :3, 3])[0] < explorer.agent.radius


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
    # a disk of radius 0 around a free point holds nothing unknown
    assert occupancy.state_at(np.array([[1.2, 1.5, 1.2]]))[0] == FREE
    assert occupancy.nearest_unknown_in_disk([1.2, 1.5], 0.0, 1.2) is None
    # a second frame looking back maps what lay behind the first camera
    T_back = pose_from_heading(3.0, 1.5, 1.2, yaw=np.pi)
    frame = renderer.render(T_back)
    occupancy.integrate(frame.depth, frame.K, T_back)
    assert occupancy.nearest_unknown_in_disk([1.2, 1.5], 0.22, 1.2) is None

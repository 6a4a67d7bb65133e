"""Voxelisation: surfaces, explorable interior, outside; house and KTH plans when present."""

from __future__ import annotations

import json

import numpy as np
import open3d as o3d
import pytest
from omegaconf import OmegaConf

from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.scenes import load_scene
from frontiernet.scenes.builder import MeshBuilder
from frontiernet.scenes.floorplan import plan_pixel_to_world
from frontiernet.scenes.explorable import enclosed_free
from frontiernet.scenes.scene import Material, SceneMetadata
from frontiernet.simulator.voxels import VoxelGrid, surface_voxels, voxelize_scene

from conftest import TWO_ROOM_FREE_VOLUME, box_scene, room_boxes, scenes_config


def _conf(**changes):
    return OmegaConf.merge(load_config("sim").voxels, changes)


def test_two_room_box_volume_close_to_analytic(two_room_voxels):
    grid = two_room_voxels
    assert isinstance(grid, VoxelGrid)
    assert grid.occupied.dtype == bool and grid.explorable.shape == grid.occupied.shape
    assert not (grid.occupied & grid.explorable).any()
    assert grid.explorable_volume_m3 == pytest.approx(TWO_ROOM_FREE_VOLUME, rel=0.10)
    # both rooms, the door, not the partition, not outside, nothing above the ceiling
    inside = [(1.0, 1.0, 1.2), (5.0, 3.0, 0.5), (3.0, 2.0, 1.0), (0.15, 3.85, 2.35)]
    assert grid.is_explorable(np.array(inside)).all()
    outside = [(3.0, 0.5, 1.0), (3.0, 2.0, 2.3), (-0.3, 2.0, 1.0), (3.0, 2.0, 2.6), (50.0, 0.0, 0.0)]
    assert not grid.is_explorable(np.array(outside)).any()
    # the grid's z range is the scene bounds
    assert grid.bounds[0, 2] == pytest.approx(-0.2)
    assert grid.bounds[1, 2] < 2.7 + grid.voxel_size + 1e-9


def test_index_world_round_trip(two_room_voxels):
    grid = two_room_voxels
    index = np.array([[0, 0, 0], [3, 7, 2], [grid.shape[0] - 1, 1, 5]])
    centres = grid.index_to_world(index)
    assert np.array_equal(grid.world_to_index(centres), index)
    assert np.allclose(centres[0], grid.origin + grid.voxel_size / 2)
    assert np.array_equal(grid.in_grid(np.array([[-1, 0, 0], [0, 0, 0]])), [False, True])


def test_surface_voxels_match_open3d_and_close_thin_slanted_walls():
    rng = np.random.default_rng(0)
    vertices = rng.uniform(0, 2.0, (30, 3))
    triangles = rng.integers(0, 30, (40, 3))
    triangles = triangles[(triangles[:, 0] != triangles[:, 1]) & (triangles[:, 1] != triangles[:, 2])
                          & (triangles[:, 0] != triangles[:, 2])]
    origin, size, shape = np.zeros(3), 0.1, (21, 21, 21)
    ours = surface_voxels(vertices, triangles, origin, size, shape, chunk=5000)  # many batches
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(vertices), o3d.utility.Vector3iVector(triangles))
    grid = o3d.geometry.VoxelGrid.create_from_triangle_mesh_within_bounds(mesh, size, origin, origin + 2.1)
    theirs = np.zeros(shape, bool)
    idx = np.array([v.grid_index for v in grid.get_voxels()])
    theirs[tuple(idx.T)] = True
    assert (theirs & ~ours).sum() == 0  # every voxel Open3D finds
    assert (ours & ~theirs).sum() <= 0.01 * theirs.sum()  # extras only where a triangle touches a box

    # a closed room of 2 cm walls rotated by 30 degrees: no holes, so the inside stays sealed
    builder = MeshBuilder()
    mid = builder.material(Material("grey"))
    centre, yaw = np.array([3.0, 3.0]), np.deg2rad(30)
    R = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
    for offset, size_xy in [((2, 0), (0.02, 4)), ((-2, 0), (0.02, 4)), ((0, 2), (4, 0.02)), ((0, -2), (4, 0.02))]:
        c = centre + R @ np.array(offset, float)
        builder.add_oriented_box((c[0], c[1], 1.0), (*size_xy, 2.0), yaw, mid)
    builder.add_box((0, 0, -0.02), (6, 6, 0), mid)
    scene = builder.build(SceneMetadata("slanted", "procedural", "test:slanted"))
    voxels = voxelize_scene(scene, _conf(gap_closing_m=0.3))
    assert voxels.is_explorable(np.array([[3.0, 3.0, 1.0], [3.0, 4.5, 1.5]])).all()
    assert not voxels.is_explorable(np.array([[0.3, 0.3, 1.0], [5.7, 0.3, 1.0]])).any()
    assert voxels.explorable_volume_m3 == pytest.approx(4 * 4 * 2, rel=0.15)


def test_open_door_to_outside_ground_keeps_inside_only():
    lower, upper = room_boxes(4.0, 4.0, 2.5, door=(1.5, 2.4))
    lower.append((-8, -8, -0.3))  # ground plane around the house
    upper.append((12, 12, -0.2))
    grid = voxelize_scene(box_scene(lower, upper, "door-to-outside"), _conf())
    assert grid.is_explorable(np.array([[2.0, 2.0, 1.0], [3.8, 1.9, 1.0], [0.2, 0.2, 2.3]])).all()
    outside = np.array([[6.0, 2.0, 1.0], [4.6, 1.9, 1.0], [-5.0, -5.0, 0.5], [10.0, 10.0, 2.5]])
    assert not grid.is_explorable(outside).any()
    assert grid.explorable_volume_m3 == pytest.approx(4 * 4 * 2.5, rel=0.12)


def test_room_without_ceiling_still_has_an_interior():
    lower, upper = room_boxes(3.0, 3.0, 2.5, ceiling=False)
    grid = voxelize_scene(box_scene(lower, upper, "no-ceiling"), _conf())
    assert grid.is_explorable(np.array([[1.5, 1.5, 2.0]])).all()
    assert grid.explorable_volume_m3 == pytest.approx(3 * 3 * 2.5, rel=0.15)


def test_enclosed_free_2d_seals_narrow_openings():
    free = np.ones((60, 60), bool)
    free[10, 10:50] = free[49, 10:50] = free[10:50, 10] = free[10:50, 49] = False
    free[10, 30:34] = True  # a 4-cell opening, narrower than 10 cells
    inside = enclosed_free(free, 0.1, 1.0)
    assert inside[30, 30] and inside[11, 31] and not inside[5, 5] and not inside[10, 10]
    free[10, 20:40] = True  # a 20-cell opening lets the outside in
    assert not enclosed_free(free, 0.1, 1.0)[30, 30]


@pytest.mark.parametrize("value", [0, -0.1, "big"])
def test_bad_voxel_size_is_an_input_error(two_room_scene, value):
    with pytest.raises(InputError, match=rf"voxel_size.*{value}"):
        voxelize_scene(two_room_scene, _conf(voxel_size=value))


def test_scene_without_interior_is_an_input_error():
    plane = box_scene([(0, 0, -0.1)], [(5, 5, 0)], "ground-only")
    with pytest.raises(InputError, match="no explorable free space"):
        voxelize_scene(plane, _conf())


def test_too_many_voxels_is_an_input_error(two_room_scene):
    with pytest.raises(InputError, match="max_voxels"):
        voxelize_scene(two_room_scene, _conf(voxel_size=0.01, max_voxels=1000))


def test_house_without_ceiling_has_a_plausible_interior(shared_data):
    scene = load_scene(str(shared_data / "scenes" / "aws_small_house.glb"), scenes_config())
    grid = voxelize_scene(scene, _conf())
    # 19 x 11.4 m x 3 m = 650 m^3 footprint box, minus walls, furniture and the outside notches
    assert 380 < grid.explorable_volume_m3 < 620
    living = np.array([[-4.5, -0.5, 1.2], [-4.5, -0.5, 0.5], [0.0, 0.0, 2.5], [5.0, 0.0, 1.2]])
    assert grid.is_explorable(living).all()
    outside = np.array([[-8.0, 5.0, 1.2], [-9.65, 0.0, 1.2], [0.0, 0.0, 3.5], [15.0, 0.0, 1.0]])
    assert not grid.is_explorable(outside).any()


def test_kth_plan_interior_is_explorable(shared_data):
    folder = shared_data / "floorplans" / "kth" / "50052750"
    scene = load_scene(f"floorplan:{folder}", scenes_config())
    grid = voxelize_scene(scene, _conf())
    plan_shape = tuple(scene.metadata.extra["plan_shape"])
    starts = json.loads((folder / "start_poses.json").read_text())["start_poses"]
    rows, cols = np.array([s["raw_pixel_row_col"] for s in starts]).T
    xy = plan_pixel_to_world(rows, cols, plan_shape, 0.05)
    points = np.concatenate([xy, np.full((len(xy), 1), 1.2)], axis=1)
    assert grid.is_explorable(points).all()
    # the building (42.8 x 32.6 m, ~79% valid space, 2.6 m storeys) minus walls
    assert 1500 < grid.explorable_volume_m3 < 42.8 * 32.6 * 2.6 * 0.85
    assert not grid.is_explorable(np.array([[1.0, 1.0, 1.2], [-0.1, 10.0, 1.2]])).any()  # outside corner

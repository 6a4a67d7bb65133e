"""The ray-cast camera: depth, RGB, normals and hit mask."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from conftest import scenes_config
from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.geometry import pose_from_heading, poses_from_headings
from frontiernet.scenes import Material, SceneMetadata
from frontiernet.scenes.builder import MeshBuilder
from frontiernet.simulator.camera import PinholeCamera, Renderer
from frontiernet.simulator.raycast import ray_caster


def _corridor(length=10.0):
    """A closed 2 m wide, 2.5 m high corridor along +x from x=0 to `length` (coloured faces)."""
    builder = MeshBuilder()
    wall = builder.material(Material("wall", (200, 50, 50)))
    floor = builder.material(Material("floor", (50, 200, 50)))
    builder.add_box((-0.1, -1.1, -0.1), (length + 0.1, -1.0, 2.6), wall)
    builder.add_box((-0.1, 1.0, -0.1), (length + 0.1, 1.1, 2.6), wall)
    builder.add_box((-0.1, -1.1, -0.1), (length + 0.1, 1.1, 0.0), floor)
    builder.add_box((-0.1, -1.1, 2.5), (length + 0.1, 1.1, 2.6), wall)
    builder.add_box((length, -1.1, -0.1), (length + 0.1, 1.1, 2.6), wall)
    return builder.build(SceneMetadata("corridor", "test", "corridor"))


def test_default_camera_is_the_papers():
    camera = PinholeCamera.from_config(load_config("sim").camera)  # the shipped camera
    assert (camera.width, camera.height, camera.max_depth) == (480, 480, 3.5)
    assert camera.horizontal_fov_deg == pytest.approx(77.32, abs=0.01)


def test_house_living_room_depth_matches_a_direct_open3d_cast(shared_data):
    from frontiernet.scenes import load_scene

    scene = load_scene(str(shared_data / "scenes" / "aws_small_house.glb"), scenes_config())
    camera = PinholeCamera.from_config(load_config("sim").camera)
    T = pose_from_heading(-4.5, -0.5, 1.2, 0.0)  # looking along +x into the living room
    frame = Renderer(scene, camera, (0, 0, 0)).render(T)
    # Open3D samples pixel (u, v) at u + 0.5: shift the principal point to match our centres.
    K_open3d = camera.K.copy()
    K_open3d[:2, 2] += 0.5
    rays = o3d.t.geometry.RaycastingScene.create_rays_pinhole(
        o3d.core.Tensor(K_open3d), o3d.core.Tensor(np.linalg.inv(T)), camera.width, camera.height)
    direct = ray_caster(scene, "open3d").scene.cast_rays(rays)["t_hit"].numpy()  # z-depth: directions have z = 1
    direct = np.where(direct <= camera.max_depth, direct, np.nan)
    assert np.array_equal(np.isnan(frame.depth), np.isnan(direct))
    assert np.nanmax(np.abs(frame.depth - direct)) < 1e-3
    valid = np.isfinite(frame.depth)
    assert 0.3 < valid.mean() < 0.95  # floor and near furniture in range, far walls beyond 3.5 m
    assert frame.hit_mask.mean() > 0.8  # no ceiling: only the sky above misses
    # the wooden floor fills the bottom rows and is textured (not one flat colour)
    bottom = frame.rgb[-40:].reshape(-1, 3).astype(int)
    assert bottom.std(axis=0).max() > 5


def test_depth_is_z_depth_and_invalid_beyond_range_but_rgb_still_seen():
    scene = _corridor()
    camera = PinholeCamera(64, 48, 40.0, 40.0, 31.5, 23.5, 3.5)
    renderer = Renderer(scene, camera, (0, 0, 0))
    frame = renderer.render(pose_from_heading(1.0, 0.0, 1.25, 0.0))
    # end wall at x = 10 is 9 m away: beyond range -> NaN depth, but hit and coloured
    centre = (23, 31)
    assert np.isnan(frame.depth[centre]) and frame.hit_mask[centre]
    assert tuple(frame.rgb[centre]) == (200, 50, 50)
    # hit_depth has no range: what a monocular model sees (the emulated depth source's input)
    assert frame.hit_depth[centre] == pytest.approx(9.0, abs=1e-4)
    in_range = np.isfinite(frame.depth)
    assert np.array_equal(frame.hit_depth[in_range], frame.depth[in_range])
    assert np.array_equal(np.isfinite(frame.hit_depth), frame.hit_mask)
    far = PinholeCamera(64, 48, 40.0, 40.0, 31.5, 23.5, 20.0)
    frame = Renderer(scene, far, (0, 0, 0)).render(pose_from_heading(1.0, 0.0, 1.25, 0.0))
    assert frame.depth[centre] == pytest.approx(9.0, abs=1e-4)
    # z-depth, not range: a side-wall pixel's depth equals its x distance
    row, col = 23, 0
    direction = np.array([(col - 31.5) / 40.0, (row - 23.5) / 40.0, 1.0])
    assert frame.depth[row, col] == pytest.approx(1.0 / abs(direction[0]), rel=1e-4)


def test_normals_are_unit_and_face_the_camera():
    scene = _corridor()
    frame = Renderer(scene, PinholeCamera(32, 32, 20.0, 20.0, 15.5, 15.5, 10.0), (0, 0, 0)).render(
        pose_from_heading(2.0, 0.3, 1.0, 0.4, 0.2))
    normals = frame.normals[frame.hit_mask]
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-5)
    rays = Renderer(scene, PinholeCamera(32, 32, 20.0, 20.0, 15.5, 15.5, 10.0), (0, 0, 0)).rays(frame.T_world_cam[None])[0]
    assert (np.einsum("ij,ij->i", normals, rays[..., 3:][frame.hit_mask]) < 0).all()
    assert np.allclose(frame.normals[~frame.hit_mask], 0)


def test_batched_render_equals_single_renders():
    scene = _corridor()
    renderer = Renderer(scene, PinholeCamera(40, 30, 25.0, 25.0, 19.5, 14.5, 3.5), (0, 0, 0))
    poses = poses_from_headings(np.array([[1, 0, 1], [3, 0.5, 1.5], [6, -0.5, 0.5]]), np.array([0.0, 2.0, -1.0]))
    batch = renderer.render_batch(poses)
    assert batch.rgb.shape == (3, 30, 40, 3) and batch.depth.dtype == np.float32
    for i, pose in enumerate(poses):
        single = renderer.render(pose)
        assert np.array_equal(single.rgb, batch.rgb[i])
        assert np.array_equal(single.depth, batch.depth[i], equal_nan=True)
        assert np.array_equal(single.normals, batch[i].normals)
        assert np.array_equal(single.hit_depth, batch[i].hit_depth, equal_nan=True)


@pytest.mark.parametrize("kwargs", [dict(width=0), dict(fx=-1.0), dict(max_depth=0.0)])
def test_bad_intrinsics_are_refused(kwargs):
    good = dict(width=8, height=8, fx=5.0, fy=5.0, cx=3.5, cy=3.5, max_depth=3.5)
    PinholeCamera(**good)
    with pytest.raises(InputError):
        PinholeCamera(**{**good, **kwargs})


def test_non_finite_pose_is_refused():
    renderer = Renderer(_corridor(), PinholeCamera(8, 8, 5.0, 5.0, 3.5, 3.5, 3.5), (0, 0, 0))
    pose = np.eye(4)
    pose[0, 3] = np.nan
    with pytest.raises(InputError, match="NaN"):
        renderer.render(pose)

"""Ray casting: the Embree engine answers as Open3D's does (rays, depth, hit mask on the shared
house), its point-to-mesh distance is exact, and the engine is chosen by sim.yaml's raycast.backend."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from frontiernet.cli.main import main
from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.scenes import load_scene
from frontiernet.simulator.camera import PinholeCamera, Renderer
from frontiernet.simulator.closest_point import build_triangle_tree, distance_to_triangles
from frontiernet.simulator.poses import sample_poses
from frontiernet.simulator.raycast import (INVALID_ID, active_backend, cast_rays, distance_to_surface,
                                           resolve_backend, select_backend)
from frontiernet.simulator.voxels import voxelize_scene

from conftest import box_scene, scenes_config

needs_open3d = pytest.mark.skipif(importlib.util.find_spec("open3d") is None,
                                  reason="open3d is not installed (the reference engine)")


@pytest.fixture
def engine():
    """Selects this process's ray-cast engine for a test; the previous one is restored after."""
    previous = active_backend()
    yield select_backend
    select_backend(previous)


def rays_from_free_space(scene, n: int, seed: int) -> np.ndarray:
    """(n, 6) float32 rays from explorable voxel centres in random directions of length 0.5-2 m,
    and a quarter from above the roof looking up (they hit nothing)."""
    voxels = voxelize_scene(scene, load_config("sim").voxels)
    rng = np.random.default_rng(seed)
    cells = rng.choice(np.flatnonzero(voxels.explorable), n)
    origins = voxels.index_to_world(np.stack(np.unravel_index(cells, voxels.shape), axis=1))
    directions = rng.normal(size=(n, 3))
    directions *= rng.uniform(0.5, 2.0, (n, 1)) / np.linalg.norm(directions, axis=1, keepdims=True)
    sky = slice(0, n // 4)
    origins[sky, 2] = scene.vertices[:, 2].max() + 1.0
    directions[sky, 2] = np.abs(directions[sky, 2]) + 0.1
    return np.concatenate([origins, directions], 1).astype(np.float32)


@needs_open3d
def test_embree_answers_every_ray_as_open3d_does():
    scene = load_scene("procedural:2003", scenes_config())
    rays = rays_from_free_space(scene, 4000, 0).reshape(4, 1000, 6)  # any leading shape
    reference, answer = cast_rays(scene, rays, "open3d"), cast_rays(scene, rays, "embree")
    assert {key: value.shape for key, value in answer.items()} == {
        "t_hit": (4, 1000), "primitive_ids": (4, 1000), "primitive_uvs": (4, 1000, 2),
        "primitive_normals": (4, 1000, 3)}
    assert answer["primitive_ids"].dtype == np.uint32 and answer["t_hit"].dtype == np.float32
    hit = reference["primitive_ids"] != INVALID_ID
    assert np.array_equal(answer["primitive_ids"] != INVALID_ID, hit)
    assert 0.5 < hit.mean() < 0.8  # the sky rays miss, the rest hit
    assert np.isinf(answer["t_hit"][~hit]).all()
    assert np.abs(answer["t_hit"][hit] - reference["t_hit"][hit]).max() < 1e-5
    same = answer["primitive_ids"] == reference["primitive_ids"]
    for key in ("primitive_uvs", "primitive_normals"):
        assert np.abs(answer[key][same & hit] - reference[key][same & hit]).max() < 1e-5, key
        assert not answer[key][~hit].any(), key
    # another triangle only where two lie in one plane (a furniture face on a wall: z-fighting,
    # either answer is right): the hit point lies on both. Which one wins varies with the engines'
    # versions and the machine: 4, 7 or none of the 3,000 hits seen (4 on 2026-12-02's machine with
    # embreex 4.4.0.post1 and open3d 0.19.0, none on CI's on 2026-12-01), so none at all is an answer too
    other = ~same & hit
    assert other.sum() <= 0.01 * hit.sum()
    points = rays[..., :3][other] + reference["t_hit"][other][:, None] * rays[..., 3:][other]
    for ids in (answer["primitive_ids"][other], reference["primitive_ids"][other]):
        corners = scene.vertices[scene.triangles[ids]]
        normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        assert np.abs(np.einsum("ij,ij->i", points - corners[:, 0], normals)).max(initial=0) < 1e-4


@needs_open3d
def test_embree_depth_and_hit_mask_match_open3d_on_the_house(shared_data, engine):
    scene = load_scene(str(shared_data / "scenes" / "aws_small_house.glb"), scenes_config())
    sim = load_config("sim")
    poses = sample_poses(scene, voxelize_scene(scene, sim.voxels), 4, 0, sim.poses)
    renderer = Renderer(scene, PinholeCamera.from_config(sim.camera), tuple(sim.camera.background))
    engine("open3d")
    reference = renderer.render_batch(poses)
    engine("embree")
    frames = renderer.render_batch(poses)
    assert reference.hit_mask.mean() > 0.5
    assert np.array_equal(frames.hit_mask, reference.hit_mask)  # 921,600 rays, thin walls and edges included
    assert np.array_equal(np.isnan(frames.depth), np.isnan(reference.depth))
    assert np.nanmax(np.abs(frames.depth - reference.depth)) < 1e-3  # metres
    assert np.abs(frames.normals - reference.normals).max() < 1e-4


def box_distance(points, lower, upper) -> np.ndarray:
    """Exact distance from points to the surface of the box [lower, upper]."""
    outside = np.linalg.norm(np.maximum(np.maximum(lower - points, points - upper), 0.0), axis=1)
    inside = np.minimum(points - lower, upper - points).min(1)
    return np.where(outside > 0, outside, inside)


def test_distance_to_surface_is_exact_on_a_box(engine):
    lower, upper = np.array([0.0, 0.0, 0.0]), np.array([3.0, 1.0, 2.0])
    scene = box_scene([lower], [upper], "one-box")
    points = np.random.default_rng(0).uniform(-2.0, 5.0, (3000, 3))
    distance = distance_to_surface(scene, points, "embree")
    assert distance.shape == (3000,) and distance.dtype == np.float32
    assert np.abs(distance - box_distance(points, lower, upper)).max() < 1e-6
    engine("embree")  # through the active engine, as pose sampling and the agent ask
    assert np.allclose(distance_to_surface(scene, points[:5]), distance[:5])


@needs_open3d
def test_distance_to_surface_matches_open3d_on_a_triangle_soup():
    rng = np.random.default_rng(1)
    vertices = rng.uniform(0.0, 4.0, (300, 3))
    triangles = rng.integers(0, 300, (400, 3))
    triangles = triangles[(triangles[:, 0] != triangles[:, 1]) & (triangles[:, 1] != triangles[:, 2])
                          & (triangles[:, 0] != triangles[:, 2])]
    points = rng.uniform(-1.0, 5.0, (2000, 3))
    ours = distance_to_triangles(build_triangle_tree(vertices, triangles), points)
    import open3d as o3d

    reference = o3d.t.geometry.RaycastingScene()
    reference.add_triangles(o3d.core.Tensor(vertices.astype(np.float32)), o3d.core.Tensor(triangles.astype(np.uint32)))
    theirs = reference.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy()
    assert np.abs(ours - theirs).max() < 1e-5  # Open3D answers in float32


def segment_distance(points, a, b) -> np.ndarray:
    """(N, M) distances from N points to M segments a-b."""
    ab = b - a
    t = np.clip(np.einsum("nmk,mk->nm", points[:, None] - a, ab) / np.maximum((ab * ab).sum(1), 1e-300), 0, 1)
    return np.linalg.norm(points[:, None] - (a + t[..., None] * ab), axis=2)


def test_degenerate_triangles_are_measured_as_their_edges():
    """A triangle with a repeated corner, or three corners on a line, is a segment (Open3D's
    answer for those is wrong: farther than the segment)."""
    rng = np.random.default_rng(2)
    a, b = rng.uniform(0, 4, (30, 3)), rng.uniform(0, 4, (30, 3))
    middle = a + rng.uniform(0.1, 0.9, (30, 1)) * (b - a)
    vertices = np.concatenate([a, b, middle])
    # triangles 0-14 repeat corner a; 15-29 have their third corner between a and b
    triangles = np.stack([np.arange(30), np.arange(30, 60), np.r_[np.arange(15), np.arange(75, 90)]], 1)
    points = rng.uniform(-1, 5, (500, 3))
    ours = distance_to_triangles(build_triangle_tree(vertices, triangles), points)
    assert np.abs(ours - segment_distance(points, a, b).min(1)).max() < 1e-9


@needs_open3d
def test_house_distances_match_open3d(shared_data):
    scene = load_scene(str(shared_data / "scenes" / "aws_small_house.glb"), scenes_config())
    points = rays_from_free_space(scene, 2000, 2)[:, :3]
    assert np.abs(distance_to_surface(scene, points, "embree") - distance_to_surface(scene, points, "open3d")).max() < 1e-5


def test_engine_comes_from_the_config_and_a_bad_one_is_one_line(tmp_path, capsys, one_line_error):
    assert load_config("sim").raycast.backend == "auto"
    assert resolve_backend("auto") in ("open3d", "embree")
    assert resolve_backend("embree") == "embree"
    with pytest.raises(InputError, match="raycast.backend 'optix' is unknown"):
        resolve_backend("optix")
    out = tmp_path / "data"
    assert main(["datagen", "--scenes", "procedural:1", "--views-per-scene", "1", "--out", str(out),
                 "--set", "raycast.backend=optix", "--no-progress"]) == 2
    assert "raycast.backend must be one of auto, open3d, embree, got 'optix'" in one_line_error()
    assert not out.exists()

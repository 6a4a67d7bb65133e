"""procedural:<seed> scenes: determinism, structure, enclosure, passability, options."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from omegaconf import OmegaConf
from scipy import ndimage

from conftest import scenes_config
from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.scenes import load_scene
from frontiernet.scenes.procedural import generate_layout
from frontiernet.simulator.raycast import INVALID_ID, cast_rays, distance_to_surface

SEEDS = (0, 1, 2, 5, 7)


@functools.lru_cache(maxsize=None)
def scene(spec: str):
    return load_scene(spec, scenes_config())


@functools.lru_cache(maxsize=None)
def layout(seed: int, **options):
    conf = OmegaConf.merge(load_config("scenes").procedural, options)
    return generate_layout(seed, conf)


def free_points(lay, floor_index: int, count: int, rng, height: float) -> np.ndarray:
    """(count, 3) world points above free floor (no furniture, stairs or walls) of one storey."""
    floor = lay.floors[floor_index]
    free = floor.interior & ~floor.furniture & ~floor.reserved & ~floor.clearance
    free = ndimage.binary_erosion(free, iterations=3)
    rows, cols = np.nonzero(free)
    pick = rng.choice(len(rows), count, replace=False)
    s, H = lay.params.resolution, free.shape[0]
    x, y = (cols[pick] + 0.5) * s, (H - rows[pick] - 0.5) * s
    return np.stack([x, y, np.full(count, floor.z0 + height)], 1)


def vertical_hits(sc, points: np.ndarray, direction: float) -> np.ndarray:
    rays = np.concatenate([points, np.tile([0.0, 0.0, direction], (len(points), 1))], 1).astype(np.float32)
    answer = cast_rays(sc, rays)
    return np.where(answer["primitive_ids"] != INVALID_ID, points[:, 2] + direction * answer["t_hit"], np.nan)


def test_same_seed_gives_identical_scene():
    a, b = load_scene("procedural:4", scenes_config()), load_scene("procedural:4", scenes_config())
    assert np.array_equal(a.vertices, b.vertices)
    assert np.array_equal(a.triangles, b.triangles)
    assert np.array_equal(a.triangle_material, b.triangle_material)
    assert np.array_equal(a.triangle_uvs, b.triangle_uvs)
    assert [m.name for m in a.materials] == [m.name for m in b.materials]
    assert all(np.array_equal(m.texture, n.texture) for m, n in zip(a.materials, b.materials) if m.texture is not None)


def test_different_seeds_give_different_buildings():
    plans = [layout(seed).floors[0].walls for seed in SEEDS]
    for i in range(len(plans)):
        for j in range(i + 1, len(plans)):
            assert plans[i].shape != plans[j].shape or (plans[i] != plans[j]).mean() > 0.01
    shapes = {layout(seed).skeleton.shape_kind for seed in range(8)}
    assert len(shapes) >= 2  # rectangles, L and U footprints all occur


@pytest.mark.parametrize("seed", SEEDS)
def test_scene_is_a_plausible_building(seed):
    sc = scene(f"procedural:{seed}")
    extra = sc.metadata.extra
    assert sc.metadata.name == f"procedural-{seed}" and sc.metadata.source == "procedural"
    assert extra["rooms"] >= 4 and extra["seed"] == seed
    assert sc.num_triangles < 100_000
    width, depth = extra["footprint_m"]
    assert 8.0 <= max(width, depth) <= 35.0
    assert 2.5 <= extra["wall_height"] <= 3.0 and extra["door_height"] < extra["wall_height"]
    lay = layout(seed)
    rng = np.random.default_rng(seed)
    points = free_points(lay, 0, 60, rng, 1.0)
    floor_z = vertical_hits(sc, points, -1.0)
    assert np.allclose(floor_z, 0.0, atol=0.02), "free floor is at z = 0 (rugs at most 1.2 cm)"
    ceiling_z = vertical_hits(sc, points, 1.0)
    assert np.all(ceiling_z > lay.wall_height - 0.05) and np.all(ceiling_z < lay.wall_height + 0.01)


def test_building_is_enclosed_sideways():
    sc, lay = scene("procedural:2"), layout(2)
    points = free_points(lay, 0, 40, np.random.default_rng(0), 1.2)
    angles = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    dirs = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], 1)
    rays = np.concatenate([np.repeat(points, len(dirs), 0), np.tile(dirs, (len(points), 1))], 1).astype(np.float32)
    assert (cast_rays(sc, rays)["primitive_ids"] != INVALID_ID).all()


def test_ceiling_can_be_dropped():
    sc, lay = scene("procedural:1?ceiling=false"), layout(1, ceiling=False)
    points = free_points(lay, 0, 60, np.random.default_rng(1), 1.0)
    assert np.isnan(vertical_hits(sc, points, 1.0)).all()
    assert sc.metadata.extra["ceiling"] is False


def _robot_free_space(floor, radius_px: int) -> np.ndarray:
    free = (floor.interior | floor.openings_mask) & ~floor.furniture & ~floor.solid
    yy, xx = np.mgrid[-radius_px:radius_px + 1, -radius_px:radius_px + 1]
    return ndimage.binary_erosion(free, yy ** 2 + xx ** 2 <= radius_px ** 2)


@pytest.mark.parametrize("seed", SEEDS)
def test_every_room_is_reachable_through_doors_by_a_robot(seed):
    lay = layout(seed)
    radius_px = int(round(0.2 / lay.params.resolution))
    for floor in lay.floors:
        labels, _ = ndimage.label(_robot_free_space(floor, radius_px))
        main = np.argmax(np.bincount(labels.ravel())[1:]) + 1
        for room in floor.rooms:
            I = room.interior
            assert (labels[I[0]:I[2], I[1]:I[3]] == main).any(), \
                f"a 0.2 m-radius robot cannot drive into the {room.kind} from the rest of the floor"
        pockets = np.bincount(labels.ravel())[1:] * lay.params.resolution ** 2
        assert np.sort(pockets)[-2:-1].sum() < 1.5, "only small nooks behind furniture are cut off"
    for index, floor in enumerate(lay.floors):  # no furniture in front of a doorway (open door leaves aside)
        items = np.zeros(floor.walls.shape, bool)
        for p in lay.placed:
            if p.floor == index and p.blocking and p.name != "door":
                items[p.footprint[0]:p.footprint[2], p.footprint[1]:p.footprint[3]] = True
        for o in floor.openings:
            for z in o.clearance:
                assert not items[z[0]:z[2], z[1]:z[3]].any()


@pytest.mark.parametrize("seed", SEEDS)
def test_furniture_stays_out_of_walls_and_apart(seed):
    lay = layout(seed)
    s = lay.params.resolution
    lower, upper, _ = lay.furniture
    assert len(lower) > 50
    H = lay.floors[0].walls.shape[0]
    c0 = np.floor(lower[:, 0] / s + 1e-6).astype(int)
    c1 = np.ceil(upper[:, 0] / s - 1e-6).astype(int)
    r0 = H - np.ceil(upper[:, 1] / s - 1e-6).astype(int)
    r1 = H - np.floor(lower[:, 1] / s + 1e-6).astype(int)
    storey = np.searchsorted([f.z0 for f in lay.floors], lower[:, 2] + 1e-6) - 1  # floor each box stands on
    for a, b, c, d, k in zip(r0, c0, r1, c1, storey):
        assert not lay.floors[k].walls[a:c, b:d].any(), "a furniture box cuts into a wall"
    footprints = [p for p in lay.placed if p.blocking]
    for floor_index in range(len(lay.floors)):
        canvas = np.zeros(lay.floors[0].walls.shape, np.int32)
        for p in footprints:
            if p.floor == floor_index:
                f = p.footprint
                canvas[f[0]:f[2], f[1]:f[3]] += 1
        assert canvas.max() <= 1, "two pieces of furniture overlap"


def test_furniture_does_not_float():
    lay = layout(7)
    lower, upper, _ = lay.furniture
    floors_z = np.array([f.z0 for f in lay.floors])
    eps = 1e-3
    on_floor = np.isclose(lower[:, 2][:, None], floors_z[None], atol=eps).any(1)
    overlap_xy = (lower[:, None, :2] <= upper[None, :, :2] + eps).all(-1) & (upper[:, None, :2] >= lower[None, :, :2] - eps).all(-1)
    resting = overlap_xy & (lower[None, :, 2] < lower[:, None, 2]) & (upper[None, :, 2] >= lower[:, None, 2] - eps)
    on_something = resting.any(1)
    s, H = lay.params.resolution, lay.floors[0].walls.shape[0]
    near_wall = np.zeros(len(lower), bool)
    for floor in lay.floors:
        for room in floor.rooms:
            I = room.interior
            x0, x1, y0, y1 = I[1] * s, I[3] * s, (H - I[2]) * s, (H - I[0]) * s
            inside = (lower[:, 0] >= x0 - eps) & (upper[:, 0] <= x1 + eps) & (lower[:, 1] >= y0 - eps) & (upper[:, 1] <= y1 + eps)
            gap = np.minimum.reduce([lower[:, 0] - x0, x1 - upper[:, 0], lower[:, 1] - y0, y1 - upper[:, 1]])
            near_wall |= inside & (gap < 0.03)
    ceiling = np.isclose(upper[:, 2][:, None], floors_z[None] + lay.wall_height, atol=eps).any(1)
    assert (on_floor | on_something | near_wall | ceiling).all()


def test_two_floors_are_connected_by_stairs():
    sc, lay = scene("procedural:3?floors=2"), layout(3, floors=2)
    assert sc.metadata.extra["floors"] == 2 and len(lay.floors) == 2 and lay.stair is not None
    storey = lay.floors[1].z0
    assert storey == pytest.approx(lay.wall_height + lay.params.slab_thickness)
    # free space (farther than 0.2 m from any surface) on a 0.15 m grid, flooded from the ground floor
    lo, hi = sc.bounds
    step = 0.15
    axes = [np.arange(lo[i] + step / 2, hi[i], step) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
    free = (distance_to_surface(sc, grid.reshape(-1, 3)) > 0.2).reshape(grid.shape[:3])
    labels, _ = ndimage.label(free)
    rng = np.random.default_rng(3)
    ground = free_points(lay, 0, 5, rng, 1.2)
    upper = free_points(lay, 1, 5, rng, 1.2)
    index = lambda p: tuple(np.clip(((p - lo) / step).astype(int), 0, np.array(free.shape) - 1))  # noqa: E731
    ground_ids = {labels[index(p)] for p in ground}
    upper_ids = {labels[index(p)] for p in upper}
    assert len(ground_ids) == 1 and 0 not in ground_ids
    assert ground_ids == upper_ids, "free space of the ground floor reaches the upper floor"
    outside = labels[0, 0, grid.shape[2] // 2]
    assert outside not in ground_ids, "the building is closed: inside free space does not leak outside"


@pytest.mark.parametrize("option, value", [("floors", 5), ("room_min", -1), ("wall_height_min", 3.5),
                                           ("second_floor_probability", 1.5), ("ceiling", "maybe"),
                                           ("door_width_max", 0)])
def test_bad_options_raise_input_error_naming_the_option(option, value):
    with pytest.raises(InputError) as error:
        load_scene(f"procedural:0?{option}={value}", scenes_config())
    message = str(error.value)
    assert option in message and "\n" not in message


def test_unknown_option_is_rejected():
    with pytest.raises(InputError, match="unknown procedural option 'rooms'; did you mean rooms_min, rooms_max"):
        load_scene("procedural:0?rooms=3", scenes_config())

"""The explorable space of thin-floor and multi-level buildings (issue 55 item 1).

A building model of one storey has its floor as a thin surface at z = 0 (no slab, nothing under
it) and a stairwell going down to the storey below, which the model leaves out: the voxel grid
then reaches down to z = -3 and the void under the floor is covered by the floor, so it lies
inside the building's envelope. The ``reachable`` rule (frontiernet/scenes/explorable.py) must
seed on the floor the robot stands on and count its storey only: not the void under the building,
not the stairwell going down (the robot keeps its camera height and takes no stair), not another
storey.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import scenes_config

from omegaconf import OmegaConf

from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.exploration.region import camera_z
from frontiernet.scenes import load_scene
from frontiernet.simulator.poses import check_pose
from frontiernet.simulator.voxels import voxelize_scene

trimesh = pytest.importorskip("trimesh")

X, Y, H = 10.0, 8.0, 3.0  # the storey's interior, metres: its own volume is X * Y * H
W = 0.2  # wall thickness
HOLE = (5.0, 5.0, 9.5, 7.5)  # the stairwell's opening in the floor: xmin, ymin, xmax, ymax
FLIGHT_Y = 6.2  # the flight runs down east along the opening's south side (y 5 to 6.2); its eye north of it


def box(lower, upper):
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    return trimesh.creation.box(extents=upper - lower,
                                transform=trimesh.transformations.translation_matrix((lower + upper) / 2))


def plane(x0, y0, x1, y1, z):
    """A horizontal rectangle at height z (two triangles, no thickness)."""
    return trimesh.Trimesh([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], [[0, 1, 2], [0, 2, 3]],
                           process=False)


def floor_with_hole(z, hole):
    """A thin floor over [0, X] x [0, Y] at height z with a rectangular `hole` (xmin, ymin, xmax, ymax)."""
    x0, y0, x1, y1 = hole
    return [plane(0, 0, X, y0, z), plane(0, y1, X, Y, z), plane(0, y0, x0, y1, z), plane(x1, y0, X, y1, z)]


def stairwell():
    """Shaft walls under the opening down to z = -3 with a door at their foot (to the storey below,
    which is not modelled) and an open flight of ten 0.3 m steps (0.05 m treads, nothing under them)."""
    x0, y0, x1, y1 = HOLE
    parts = [box((x0 - W, y0 - W, -H), (8.3, y0, 0)), box((9.3, y0 - W, -H), (x1 + W, y0, 0)),
             box((8.3, y0 - W, -0.9), (9.3, y0, 0)),  # the south wall, its door x 8.3-9.3 below z = -0.9
             box((x0 - W, y1, -H), (x1 + W, y1 + W, 0)), box((x0 - W, y0, -H), (x0, y1, 0)),
             box((x1, y0, -H), (x1 + W, y1, 0))]
    for i in range(10):
        top = -0.3 * (i + 1)
        parts.append(box((x0 + 0.4 * i, y0, top - 0.05), (x0 + 0.4 * (i + 1), FLIGHT_Y, top)))
    return parts


def walls(z0, z1):
    return [box((-W, -W, z0), (X + W, 0, z1)), box((-W, Y, z0), (X + W, Y + W, z1)),
            box((-W, 0, z0), (0, Y, z1)), box((X, 0, z0), (X + W, Y, z1))]


def building(path, storeys: int = 1):
    """The thin-floor building as a .ply mesh file at `path`: `storeys` storeys of height H over the
    stairwell; an upper storey's thin floor has a 2 x 2 m opening over the floor below."""
    parts = floor_with_hole(0.0, HOLE) + stairwell() + walls(0.0, storeys * H)
    for k in range(1, storeys):
        parts += floor_with_hole(k * H, (1.0, 1.0, 3.0, 3.0))
    parts.append(plane(-W, -W, X + W, Y + W, storeys * H))  # the ceiling
    trimesh.util.concatenate(parts).export(path)
    return path


@pytest.fixture(scope="module")
def one_storey(tmp_path_factory):
    return building(tmp_path_factory.mktemp("thin") / "storey.ply")


def voxels(spec):
    return voxelize_scene(load_scene(str(spec), scenes_config()), load_config("sim").voxels)


IN_ROOM = [[2.0, 2.0, 1.5], [7.0, 7.0, 1.0], [9.0, 1.0, 2.9]]  # the room, over the stairwell's eye too
OVER_FLIGHT = [[8.0, 5.6, -1.0], [5.5, 5.6, -0.2]]  # over a tread: a pose stands on the stairs
VOID = [[2.0, 2.0, -1.5], [5.5, 3.0, -2.9], [8.8, 4.0, -2.0]]  # under the floor, out of the shaft's door
SHAFT = [[8.0, 5.6, -2.9], [7.0, 7.0, -1.5]]  # under the flight, down the eye: nothing to stand on


def test_thin_floor_over_a_stairwell_counts_the_storey_not_the_void_under_it(one_storey):
    """Before the rule, the seed could lie on the grid's bottom layer under the floor and the void
    below the building joined the storey through the shaft's door: 410 m^3 for a 240 m^3 storey."""
    grid = voxels(one_storey)
    assert 0.9 * X * Y * H <= grid.explorable_volume_m3 <= X * Y * H  # at most the storey's own volume
    seed = grid.index_to_world(grid.seed)
    assert 0.0 < seed[2] < 0.2  # on the floor, not under it
    assert grid.is_explorable(np.array(IN_ROOM)).all()
    assert not grid.is_explorable(np.array(VOID + SHAFT + OVER_FLIGHT)).any()  # the way down is another storey's


def test_without_the_storey_keys_the_rule_before_them_keeps_the_flight(one_storey):
    """Benchmark plans made before the storey keys read them as null (frontiernet/benchmark/changes.py):
    then only the void under the building is cut, and the space over the flight still counts."""
    conf = OmegaConf.merge(load_config("sim").voxels, {"storey_floor_share": None, "storey_slab_share": None})
    grid = voxelize_scene(load_scene(str(one_storey), scenes_config()), conf)
    assert grid.is_explorable(np.array(IN_ROOM + OVER_FLIGHT)).all()
    assert not grid.is_explorable(np.array(VOID + SHAFT)).any()


def test_a_seed_without_z_takes_the_floor_not_the_void(one_storey):
    """`?seed=x,y` takes the lowest floor at that point: the storey's floor, not the grid's bottom
    layer under it (there the seed used to be, at z = -3)."""
    automatic = voxels(one_storey)
    grid = voxels(f"{one_storey}?seed=2,2")
    assert 0.0 < grid.index_to_world(grid.seed)[2] < 0.2
    assert np.array_equal(grid.explorable, automatic.explorable)
    with pytest.raises(InputError, match="has no navigable floor"):  # no floor at or below z = -1
        voxels(f"{one_storey}?seed=2,2,-1")


def test_a_camera_under_the_floor_is_outside_the_building(one_storey):
    scene = load_scene(str(one_storey), scenes_config())
    grid = voxelize_scene(scene, load_config("sim").voxels)
    poses = load_config("sim").poses
    check_pose(scene, grid, np.array([2.0, 2.0, 1.2]), poses)
    with pytest.raises(InputError, match="outside the building"):
        check_pose(scene, grid, np.array(VOID[0]), poses)


def test_each_storey_of_a_two_storey_building_counts_on_its_own(tmp_path):
    """The automatic seed is on the ground storey (the lowest large floor, not the largest: here the
    upper one, whose opening is smaller) and only that storey counts, up to the upper floor;
    ``?seed=x,y,z`` upstairs counts the upper storey, and the robot's camera stands over its floor."""
    path = building(tmp_path / "two.ply", storeys=2)
    upper = [[6.0, 2.0, 4.5], [8.0, 6.0, 5.5], [9.0, 1.0, 5.9]]  # upstairs, not over its floor's opening
    ground = voxels(path)
    assert 0.85 * X * Y * H <= ground.explorable_volume_m3 <= X * Y * H
    assert 0.0 < ground.index_to_world(ground.seed)[2] < 0.2
    assert ground.is_explorable(np.array(IN_ROOM)).all()
    assert not ground.is_explorable(np.array(upper + OVER_FLIGHT + VOID + SHAFT)).any()
    up = voxels(f"{path}?seed=6,2,4")
    assert H < up.index_to_world(up.seed)[2] < H + 0.2
    assert 0.85 * X * Y * H <= up.explorable_volume_m3 <= X * Y * H
    assert up.is_explorable(np.array(upper)).all()
    assert not up.is_explorable(np.array(IN_ROOM + OVER_FLIGHT)).any()
    explore = load_config("explore")
    scene = load_scene(str(path), scenes_config())
    height = explore.motion.camera_height_m  # over the storey's floor, not over the shaft's bottom at z = -3
    assert camera_z(scene, ground, explore) == pytest.approx(height, abs=0.05)
    assert camera_z(scene, up, explore) == pytest.approx(H + height, abs=0.05)


def side_cut(grid, y: float, scale: int = 4) -> np.ndarray:
    """(Z * scale, X * scale, 3) uint8 picture of the vertical cut of `grid` at world `y` (metres),
    up at the top: structure dark grey, explorable voxels green, other free voxels white, the
    seed's voxel (projected onto the cut) red."""
    j = int(np.clip((y - grid.origin[1]) / grid.voxel_size, 0, grid.shape[1] - 1))
    image = np.full((grid.shape[2], grid.shape[0], 3), 255, np.uint8)  # rows are layers
    image[grid.occupied[:, j, :].T] = (70, 70, 70)
    image[grid.explorable[:, j, :].T] = (90, 190, 90)
    if grid.seed is not None:
        image[grid.seed[2], grid.seed[0]] = (220, 0, 0)
    return np.kron(image[::-1], np.ones((scale, scale, 1), np.uint8))


if __name__ == "__main__":  # the docs picture: .venv/bin/python tests/test_explorable_floors.py OUT.png
    import sys
    import tempfile
    from pathlib import Path

    from PIL import Image, ImageDraw

    before_keys = {"storey_floor_share": None, "storey_slab_share": None}  # the void rule alone (before the storey)
    with tempfile.TemporaryDirectory() as folder:
        scene = load_scene(str(building(Path(folder) / "storey.ply")), scenes_config())
        grids = [voxelize_scene(scene, OmegaConf.merge(load_config("sim").voxels, keys)) for keys in (before_keys, {})]
    titles = ("the void rule alone", "one storey (the robot takes no stair)")
    cuts = [side_cut(grid, 5.6) for grid in grids]
    canvas = Image.new("RGB", (sum(c.shape[1] for c in cuts) + 20, cuts[0].shape[0] + 18), "white")
    draw, x = ImageDraw.Draw(canvas), 0
    for cut, grid, title in zip(cuts, grids, titles):
        canvas.paste(Image.fromarray(cut), (x, 18))
        draw.text((x + 4, 3), f"{title}: {grid.explorable_volume_m3:.1f} m^3", fill="black")
        x += cut.shape[1] + 20
    canvas.save(sys.argv[1])
    print(f"wrote {sys.argv[1]}: explorable {', '.join(f'{g.explorable_volume_m3:.1f}' for g in grids)} m^3 "
          f"of a {X * Y * H:.0f} m^3 storey")

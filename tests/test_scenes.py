"""Scene loading: mesh files, HM3D layout, floor plans, specs, and bad input."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from PIL import Image

from conftest import scenes_config
from frontiernet.errors import InputError
from frontiernet.geometry import pose_from_heading
from frontiernet.scenes import load_scene, parse_spec
from frontiernet.simulator.camera import PinholeCamera, Renderer
from frontiernet.simulator.raycast import cast_rays

LOOK_DOWN = -np.pi / 2 + 1e-6  # pitch that looks straight down


def _box_scene_yup() -> trimesh.Scene:
    """A 4 m (x) by 3 m (y-up, height) by 2 m (z) box, Y-up as glTF expects."""
    return trimesh.Scene(trimesh.creation.box(extents=(4.0, 3.0, 2.0)))


def test_glb_y_up_is_converted_to_z_up(tmp_path):
    path = tmp_path / "room.glb"
    _box_scene_yup().export(path)
    as_stored = load_scene(str(path), scenes_config())
    converted = load_scene(f"mesh:{path}?up=y", scenes_config())
    assert np.allclose(as_stored.bounds[1] - as_stored.bounds[0], [4, 3, 2], atol=1e-5)
    assert np.allclose(converted.bounds[1] - converted.bounds[0], [4, 2, 3], atol=1e-5)
    assert converted.metadata.up_axis_conversion == "y-up to z-up"


def test_obj_texture_is_sampled_with_barycentric_uvs(tmp_path):
    # A 2 x 2 m floor quad at z = 0 whose texture has four coloured quadrants.
    texture = np.zeros((8, 8, 3), np.uint8)
    texture[:4, :4] = (255, 0, 0)    # top-left of the image = v high, u low
    texture[:4, 4:] = (0, 255, 0)
    texture[4:, :4] = (0, 0, 255)
    texture[4:, 4:] = (255, 255, 0)
    Image.fromarray(texture).save(tmp_path / "quad.png")
    (tmp_path / "quad.mtl").write_text("newmtl mat\nKd 1 1 1\nmap_Kd quad.png\n")
    (tmp_path / "quad.obj").write_text(
        "mtllib quad.mtl\n"
        "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n"
        "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
        "usemtl mat\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")
    scene = load_scene(str(tmp_path / "quad.obj"), scenes_config())
    assert scene.triangle_uvs is not None and scene.materials[0].texture is not None
    camera = PinholeCamera(64, 64, 40.0, 40.0, 31.5, 31.5, 5.0)
    frame = Renderer(scene, camera, (0, 0, 0)).render(pose_from_heading(0, 0, 1.0, np.pi / 2, LOOK_DOWN))
    # Looking down with yaw +90 deg: image right = world +x, image up = world +y.
    assert tuple(frame.rgb[20, 20]) == (255, 0, 0)      # world (-x, +y): u low, v high
    assert tuple(frame.rgb[20, 43]) == (0, 255, 0)      # world (+x, +y)
    assert tuple(frame.rgb[43, 20]) == (0, 0, 255)      # world (-x, -y)
    assert tuple(frame.rgb[43, 43]) == (255, 255, 0)    # world (+x, -y)
    assert np.nanmax(np.abs(frame.depth[frame.hit_mask] - 1.0)) < 1e-5


def test_ply_vertex_colours_are_interpolated(tmp_path):
    mesh = trimesh.Trimesh([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], [[0, 1, 2], [0, 2, 3]], process=False)
    mesh.visual.vertex_colors = np.tile([200, 100, 50, 255], (4, 1))
    mesh.export(tmp_path / "colored.ply")
    scene = load_scene(str(tmp_path / "colored.ply"), scenes_config())
    assert scene.vertex_colors is not None and scene.materials[0].use_vertex_colors
    camera = PinholeCamera(32, 32, 20.0, 20.0, 15.5, 15.5, 5.0)
    frame = Renderer(scene, camera, (0, 0, 0)).render(pose_from_heading(0, 0, 1.0, 0.0, LOOK_DOWN))
    assert np.abs(frame.rgb[16, 16].astype(int) - [200, 100, 50]).max() <= 1


def test_hm3d_layout_is_found_and_converted(tmp_path):
    folder = tmp_path / "hm3d" / "minival" / "00800-TEEsavR23oF"
    folder.mkdir(parents=True)
    _box_scene_yup().export(folder / "TEEsavR23oF.glb")
    _box_scene_yup().export(folder / "TEEsavR23oF.semantic.glb")  # must not be picked
    scene = load_scene(f"hm3d:{folder}", scenes_config())
    assert scene.metadata.source == "hm3d"
    assert scene.metadata.name == "TEEsavR23oF"
    assert np.allclose(scene.bounds[1] - scene.bounds[0], [4, 2, 3], atol=1e-5)  # Y-up -> Z-up


def test_hm3d_basis_glb_is_refused_or_loaded_geometry_only(tmp_path, caplog):
    folder = tmp_path / "train" / "00001-abcdefghijk"
    folder.mkdir(parents=True)
    _box_scene_yup().export(folder / "abcdefghijk.basis.glb")
    with pytest.raises(InputError, match=r"plain '\.glb' release"):
        load_scene(f"hm3d:{folder}", scenes_config())
    scene = load_scene(f"hm3d:{folder}?geometry_only=true", scenes_config())
    assert scene.metadata.extra["geometry_only"] is True
    assert all(material.texture is None for material in scene.materials)
    assert "geometry only" in caplog.text


def test_a_folder_of_several_unrelated_meshes_is_no_hm3d_scene(tmp_path, one_line_error):
    # eighth probe (E13): `scene info ./` read the first .glb by name (room.glb of room.glb, room_bitflip.glb)
    from frontiernet.cli.main import main

    folder = tmp_path / "meshes"
    folder.mkdir()
    for name in ("room.glb", "room_copy.glb"):
        _box_scene_yup().export(folder / name)
    assert main(["scene", "info", str(folder)]) == 2
    assert one_line_error() == (f"frontiernet scene: error: {folder}: several .glb files (room.glb, room_copy.glb) "
                                "and none named meshes.glb, an HM3D scene folder's own; give the scene's file")


def test_floorplan_image_is_extruded_with_walls_floor_and_ceiling(tmp_path):
    plan = np.full((60, 80), 254, np.uint8)
    plan[10:50, 10:13] = plan[10:50, 67:70] = 0
    plan[10:13, 10:70] = plan[47:50, 10:70] = 0
    plan[30:33, 10:70] = 0
    plan[30:33, 35:50] = 254  # a 0.75 m door between the two rooms
    Image.fromarray(plan).save(tmp_path / "plan.png")
    scene = load_scene(f"floorplan:{tmp_path / 'plan.png'}?resolution=0.05&wall_height=2.5", scenes_config())
    assert scene.metadata.source == "floorplan"
    assert np.isclose(scene.bounds[1, 2], 2.5, atol=1e-6)
    no_ceiling = load_scene(f"floorplan:{tmp_path / 'plan.png'}?resolution=0.05&ceiling=false", scenes_config())
    # plan pixel (20, 40) is inside the upper room: x = 2.025, y = (60 - 20 - 0.5) * 0.05 = 1.975
    up, down, door = [[2.025, 1.975, 1.0, 0, 0, 1]], [[2.025, 1.975, 1.0, 0, 0, -1]], [[2.125, 2.2, 1.0, 0, -1, 0]]
    assert np.isclose(cast_rays(scene, up)["t_hit"][0], 1.5, atol=1e-4)       # ceiling at 2.5 m
    assert np.isinf(cast_rays(no_ceiling, up)["t_hit"][0])                     # open to the sky
    assert np.isclose(cast_rays(scene, down)["t_hit"][0], 1.0, atol=1e-4)     # floor at 0 m
    # walking from the upper room through the door (cols 35-49) to the lower one meets no wall
    assert np.isclose(cast_rays(scene, door)["t_hit"][0], 2.2 - 0.65, atol=1e-4)  # far wall, not the door wall


def _slice_occupancy(scene, z: float, shape, resolution: float) -> np.ndarray:
    """Rasterise the mesh's cross-section at height z onto plan pixels (scanline parity fill)."""
    segments = trimesh.intersections.mesh_plane(scene.to_trimesh(), [0, 0, 1], [0, 0, z])[:, :, :2]
    H, W = shape
    occupied = np.zeros(shape, bool)
    x0, y0, x1, y1 = segments[:, 0, 0], segments[:, 0, 1], segments[:, 1, 0], segments[:, 1, 1]
    centres_x = (np.arange(W) + 0.5) * resolution
    for row in range(H):
        y = (H - row - 0.5) * resolution
        crossing = (y0 - y) * (y1 - y) < 0
        xs = np.sort(x0[crossing] + (y - y0[crossing]) * (x1[crossing] - x0[crossing]) / (y1[crossing] - y0[crossing]))
        for enter, leave in zip(xs[0::2], xs[1::2]):
            occupied[row] |= (centres_x > enter) & (centres_x < leave)
    return occupied


def test_kth_floorplan_slice_matches_plan_occupancy(shared_data):
    folder = shared_data / "floorplans" / "kth" / "50052750"
    scene = load_scene(f"floorplan:{folder}", scenes_config())
    occupied = np.load(folder / "occ_map.npy") == 0
    sliced = _slice_occupancy(scene, 1.0, occupied.shape, 0.05)
    iou = (sliced & occupied).sum() / (sliced | occupied).sum()
    assert iou > 0.9, f"slice IoU {iou:.3f}"


@pytest.mark.parametrize("spec, message", [
    ("missing.glb", "file not found"),
    ("scene.fbx", "unsupported scene format"),
    ("procedural:abc", "seed must be an integer"),
    ("procedural:1?nonsense=3", "unknown procedural option 'nonsense'; valid: floors, "),
    ("floorplan:plan.png", "needs its resolution"),
    ("floorplan:plan.png?resolution=-0.1", r"floorplan option resolution must be a number > 0 \(or null\), got -0.1"),
    ("floorplan:plan.png?resolution=0", r"resolution must be a number > 0 \(or null\), got 0"),
    ("floorplan:plan.png?resolution=0.05&wall_height=.nan", "wall_height must be a number > 0, got nan"),
    ("floorplan:empty.png?resolution=0.05", "no free space"),
    ("corrupt.glb", "cannot read mesh"),
    ("nan.obj", "NaN or infinite"),
    ("empty.obj", "empty"),
    ("", "empty scene spec"),
])
def test_bad_scene_input_gives_a_clear_error(tmp_path, monkeypatch, spec, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "scene.fbx").write_bytes(b"fbx")
    Image.fromarray(np.full((20, 20), 254, np.uint8)).save(tmp_path / "plan.png")
    Image.fromarray(np.zeros((20, 20), np.uint8)).save(tmp_path / "empty.png")
    (tmp_path / "corrupt.glb").write_bytes(b"glTF\x02\x00\x00\x00" + np.random.default_rng(0).bytes(200))
    (tmp_path / "nan.obj").write_text("v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n")
    (tmp_path / "empty.obj").write_text("# nothing\nv 0 0 0\n")
    with pytest.raises(InputError, match=message) as error:
        load_scene(spec, scenes_config())
    assert "\n" not in str(error.value)


def test_spec_parsing_reads_typed_options():
    spec = parse_spec("procedural:7?floors=2&ceiling=false&wall_height=2.8")
    assert (spec.source, spec.argument) == ("procedural", "7")
    assert spec.options == {"floors": 2, "ceiling": False, "wall_height": 2.8}
    assert parse_spec("default").text == "procedural:0"


def test_kth_layout_door_gaps_get_lintels_but_wall_strips_do_not(tmp_path):
    # KTH/MapEx layout: occ_map.npy (0 occupied, 254 free) and valid_space.npy (room ids).
    occ = np.full((60, 100), 254, np.uint8)
    occ[10:50, 10:13] = occ[10:50, 87:90] = occ[10:13, 10:90] = occ[47:50, 10:90] = 0
    occ[10:50, 48:52] = 0
    occ[25:35, 48:52] = 254                  # a 0.5 m door gap in the middle wall
    valid = np.zeros_like(occ)
    valid[13:47, 13:48] = 1
    valid[13:47, 52:87] = 2
    valid[13:47, 13:15] = 0                  # an unlabelled free strip along room 1's west wall
    np.save(tmp_path / "occ_map.npy", occ)
    np.save(tmp_path / "valid_space.npy", valid)
    scene = load_scene(f"floorplan:{tmp_path}?door_height=2.0&wall_height=2.6", scenes_config())
    H, s = occ.shape[0], 0.05

    def up_hit(row, col):
        x, y = (col + 0.5) * s, (H - row - 0.5) * s
        return cast_rays(scene, [[x, y, 1.0, 0, 0, 1]])["t_hit"][0] + 1.0

    assert up_hit(30, 50) == pytest.approx(2.0, abs=1e-4)   # lintel above the door gap
    assert up_hit(30, 13) == pytest.approx(2.6, abs=1e-4)   # ceiling above the strip: no lintel
    assert up_hit(30, 30) == pytest.approx(2.6, abs=1e-4)   # ceiling in the room
    assert scene.metadata.extra["door_pixels"] == 10 * 4

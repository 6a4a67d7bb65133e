"""build_world: the one scene -> voxels -> renderer assembly, from one config (sim and scenes)."""

from __future__ import annotations

import numpy as np
import pytest
from omegaconf import OmegaConf

from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.geometry import pose_from_heading
from frontiernet.simulator import raycast
from frontiernet.simulator.world import build_world


def _sim(**changes):
    return OmegaConf.merge(load_config("sim"), changes)


@pytest.fixture
def restore_backend():
    selected = list(raycast._SELECTED)
    yield
    raycast._SELECTED[:] = selected


def test_the_world_renders_with_the_configs_camera_and_background(two_room_scene, restore_backend):
    sim = _sim(camera={"width": 64, "height": 48, "focal_px": 40.0, "background": [10, 20, 30]})
    world = build_world(two_room_scene, sim)
    assert world.scene is two_room_scene and set(world.seconds) == {"voxelize", "renderer"}
    assert world.voxels.num_explorable > 0
    camera = world.renderer.camera
    assert (camera.width, camera.height, camera.fx) == (64, 48, 40.0)
    outside = world.renderer.render(pose_from_heading(8.0, 2.0, 1.2, 0.0))  # beyond the +x wall, looking away
    assert not outside.hit_mask.any()
    assert np.all(outside.rgb == np.array([10, 20, 30], np.uint8))
    inside = world.renderer.render(pose_from_heading(1.0, 2.0, 1.2, 0.0))
    assert inside.hit_mask.all()


def test_the_world_selects_the_configs_ray_cast_engine(two_room_scene, restore_backend):
    importable = []
    for name in raycast.BACKENDS:
        try:
            importable.append(raycast.resolve_backend(name))
        except InputError:
            continue
    for name in importable:
        world = build_world(two_room_scene, _sim(raycast={"backend": name}), voxels=False, renderer=False)
        assert world.raycast_backend == name == raycast.active_backend()
        assert world.voxels is None and world.renderer is None and world.seconds == {}


def test_a_bad_engine_is_named_before_the_scene_is_read(tmp_path, restore_backend):
    with pytest.raises(InputError, match="raycast.backend 'nope'"):
        build_world(str(tmp_path / "missing.glb"), _sim(raycast={"backend": "nope"}), load_config("scenes"))


def test_the_scene_sources_options_are_the_given_scenes_configs(plan_spec, restore_backend):
    """A spec is loaded with the command's scenes section (here a floor plan's wall height), not
    the shipped scenes.yaml."""
    shipped = load_config("scenes")
    low = OmegaConf.merge(shipped, {"floorplan": {"wall_height": 2.0}})
    top = [build_world(plan_spec, _sim(), scenes, voxels=False, renderer=False).scene.bounds[1, 2]
           for scenes in (shipped, low)]
    assert top[1] == pytest.approx(2.0) and top[0] == pytest.approx(2.6)

"""The oracle's attribution hybrids (issue 27, step 3; datagen/oracle.py): each takes its frontier
pixels ("where") from one source and its gain classes ("how much") from another."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from datagen.oracle import OraclePerception
from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.exploration.ablations import GainFrom
from frontiernet.exploration.methods import ImageSource, MethodContext, ModelPerception, make_method, method_names
from frontiernet.geometry import pose_from_heading
from frontiernet.model import FrontierNet, NetworkConfig, open_runtime, resize_and_crop, save_model
from frontiernet.simulator.camera import PinholeCamera, Renderer

SIZE = 96  # the frame's size (pixels); the tiny model works at 64 px


@pytest.fixture(scope="module")
def tiny_model(tmp_path_factory):
    torch.manual_seed(0)
    net = FrontierNet(NetworkConfig(decoder_channels=(32, 16, 16, 8, 8), head_channels=8)).eval()
    conf = OmegaConf.to_container(load_config("model"), resolve=True)
    conf["inference"]["size"] = 64
    return save_model(tmp_path_factory.mktemp("model") / "tiny.safetensors", net, conf)


@pytest.fixture(scope="module")
def small_sim():
    return load_config("sim", overrides=[f"camera.width={SIZE}", f"camera.height={SIZE}", "camera.focal_px=60"])


@pytest.fixture(scope="module")
def door_frame(two_room_scene, small_sim):
    """A view from the first room through the door into the second (a frontier with gain)."""
    camera = PinholeCamera.from_config(small_sim.camera)
    return Renderer(two_room_scene, camera, (0, 0, 0)).render(pose_from_heading(1.0, 1.95, 1.2, 0.0))


def method_of(name, model, scene, voxels, sim, conf=None):
    """The method `name` built for a run of `scene` with the sim config `sim` and the run config `conf`
    (None: the shipped explore.yaml)."""
    conf = conf if conf is not None else load_config("explore")
    return make_method(name, MethodContext(conf, sim, model, scene, voxels))


def hybrid(name, model, scene, voxels, sim, conf=None):
    method = method_of(name, model, scene, voxels, sim, conf)
    assert method.name == name and isinstance(method.source, ImageSource) and method.goal == "utility"
    assert method.source.perception.name == name
    assert method.uses_model == (name == "frontiernet-oracle-gain")  # the run records the model file
    return method.source.perception


def test_the_hybrids_are_listed_and_an_unknown_name_lists_them(small_sim):
    assert {"oracle", "oracle-uniform", "frontiernet-oracle-gain"} <= set(method_names())
    with pytest.raises(InputError, match="valid: .*frontiernet-oracle-gain.*oracle-uniform"):
        make_method("oracle-unifrom", MethodContext(load_config("explore"), small_sim))


def test_oracle_uniform_has_the_ground_truth_frontiers_and_the_uniform_gain(two_room_scene, two_room_voxels,
                                                                            small_sim, door_frame):
    conf = load_config("explore", overrides=["ablations.uniform_gain_class=4"])
    seen = hybrid("oracle-uniform", None, two_room_scene, two_room_voxels, small_sim, conf)(door_frame,
                                                                                           door_frame.depth)
    truth = OraclePerception(two_room_scene, two_room_voxels, small_sim)(door_frame, door_frame.depth)
    frontier = truth.distance_field < truth.labels["frontier_threshold_px"]
    assert frontier.any() and (truth.gain_class[frontier] > 0).any()  # the view has a frontier with gain
    np.testing.assert_array_equal(seen.distance_field, truth.distance_field)  # where: the ground truth's
    assert seen.labels == truth.labels
    assert seen.gain_class.shape == (SIZE, SIZE) and (seen.gain_class == 4).all()  # how much: uniform


def test_frontiernet_oracle_gain_has_the_models_frontiers_and_the_ground_truth_gain(
        tiny_model, two_room_scene, two_room_voxels, small_sim, door_frame):
    seen = hybrid("frontiernet-oracle-gain", tiny_model, two_room_scene, two_room_voxels, small_sim)(
        door_frame, door_frame.depth)
    model = ModelPerception(open_runtime(tiny_model))(door_frame, door_frame.depth)
    truth = OraclePerception(two_room_scene, two_room_voxels, small_sim)(door_frame, door_frame.depth)
    assert model.gain_logits.shape == (11, 64, 64) and truth.gain_logits is None
    assert seen.gain_logits is None  # the model's logits are not the classes' any more (expected decoding)
    np.testing.assert_array_equal(seen.distance_field, model.distance_field)  # where: the model's (64 px)
    np.testing.assert_array_equal(seen.depth, model.depth)
    np.testing.assert_array_equal(seen.K, model.K)
    # how much: the ground truth's classes, brought to the model's 64 px as its input is (nearest)
    _, expected, _ = resize_and_crop(None, truth.gain_class.astype(np.float32), None, 64)
    assert seen.gain_class.shape == (64, 64) and seen.gain_class.dtype == np.uint8
    np.testing.assert_array_equal(seen.gain_class, expected.astype(np.uint8))
    assert (seen.gain_class > 0).any()
    assert seen.labels["bin_edges"] == truth.labels["bin_edges"]
    assert seen.labels["frontier_threshold_px"] == model.labels["frontier_threshold_px"]


def test_gain_from_keeps_a_same_size_gain_as_it_is(door_frame, two_room_scene, two_room_voxels, small_sim):
    truth = OraclePerception(two_room_scene, two_room_voxels, small_sim)
    seen = GainFrom(truth, OraclePerception(two_room_scene, two_room_voxels, small_sim))(door_frame, door_frame.depth)
    again = OraclePerception(two_room_scene, two_room_voxels, small_sim)(door_frame, door_frame.depth)
    np.testing.assert_array_equal(seen.gain_class, again.gain_class)
    np.testing.assert_array_equal(seen.distance_field, again.distance_field)


def test_the_oracles_ground_truth_follows_the_run_config(two_room_scene, two_room_voxels, small_sim, door_frame):
    from frontiernet.exploration.run import load_run_config

    conf = load_run_config(overrides=["ground_truth.gain.volume=occluded", "ground_truth.gain.spread=region"])
    oracle = hybrid("oracle", None, two_room_scene, two_room_voxels, small_sim, conf)
    assert (oracle.generator.gain_volume, oracle.generator.gain_spread) == ("occluded", "region")
    uniform = hybrid("oracle-uniform", None, two_room_scene, two_room_voxels, small_sim, conf)
    assert uniform.base.generator.gain_spread == "region"
    shipped = hybrid("oracle", None, two_room_scene, two_room_voxels, small_sim, load_run_config())
    assert (shipped.generator.gain_volume, shipped.generator.gain_spread) == ("unobserved", "blend")
    with pytest.raises(InputError, match="ground_truth.gain.volume"):
        method_of("oracle", None, two_room_scene, two_room_voxels, small_sim,
                  load_run_config(overrides=["ground_truth.gain.volume=behind"]))

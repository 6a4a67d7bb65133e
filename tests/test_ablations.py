"""The paper's Fig. 9 ablation perceptions (frontiernet/exploration/ablations.py): uniform gain,
depth-discontinuity frontiers F_d, and the methods built of them (exploration/methods.py)."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.exploration.ablations import (
    DISCONTINUITY_THRESHOLD_PX,
    DiscontinuityFrontiers,
    DiscontinuitySettings,
    UniformGain,
    model_labels,
)
from frontiernet.exploration.methods import METHODS, MethodContext, ModelPerception, make_method
from frontiernet.exploration.perception import Perception, PerceptionResult
from frontiernet.frontiers.discontinuity import discontinuity_mask, distance_field
from frontiernet.model import FrontierNet, NetworkConfig, save_model

SIZE = 48  # working size of the model-free tests (pixels)
LABELS = model_labels()
SETTINGS = DiscontinuitySettings.from_config(load_config("explore").ablations.discontinuity)  # the shipped F_d
SIM = load_config("sim")


def frame_with(depth: np.ndarray) -> SimpleNamespace:
    """A Frame-like object: grey rgb, a pinhole K, the given (H, W) depth in metres."""
    h, w = depth.shape
    K = np.array([[30.0, 0, (w - 1) / 2], [0, 30.0, (h - 1) / 2], [0, 0, 1]])
    return SimpleNamespace(rgb=np.full((h, w, 3), 128, np.uint8), depth=depth, K=K, T_world_cam=np.eye(4))


def step_depth(size: int = SIZE, near: float = 1.0, far: float = 3.0) -> np.ndarray:
    """(size, size) float32: left half a wall at `near` metres, right half at `far`."""
    depth = np.full((size, size), near, np.float32)
    depth[:, size // 2:] = far
    return depth


class StubPerception(Perception):
    """A 'model' with frontier pixels on column 5 and gain class 3 there (class 0 elsewhere)."""

    def __call__(self, frame, depth):
        mask = np.zeros(depth.shape, bool)
        mask[:, 5] = True
        classes = np.where(mask, 3, 0).astype(np.uint8)
        logits = np.eye(len(LABELS["bin_edges"]), dtype=np.float32)[classes].transpose(2, 0, 1) * 10  # (K, H, W)
        return PerceptionResult(frame.rgb, np.asarray(depth, np.float32), frame.K,
                                distance_field(mask, LABELS["truncation_px"]), classes, dict(LABELS), logits)


def test_uniform_gain_is_constant_and_the_configured_class_on_the_base_frontiers():
    depth = step_depth()
    base = StubPerception()(frame_with(depth), depth)
    seen = UniformGain(StubPerception(), 7)(frame_with(depth), depth)
    assert seen.gain_class.dtype == np.uint8 and seen.gain_class.shape == depth.shape
    assert (seen.gain_class == 7).all()
    assert (seen.gain_class[base.distance_field < LABELS["frontier_threshold_px"]] == 7).all()
    assert base.gain_logits is not None and seen.gain_logits is None  # the base's logits are not class 7's
    np.testing.assert_array_equal(seen.distance_field, base.distance_field)  # frontiers untouched


@pytest.mark.parametrize("gain_class", [0, -1, 2.5, True])
def test_uniform_gain_refuses_no_gain_and_non_classes(gain_class):
    with pytest.raises(InputError, match="uniform_gain_class"):
        UniformGain(StubPerception(), gain_class)


def test_uniform_gain_beyond_the_models_classes_is_an_input_error():
    depth = step_depth()
    with pytest.raises(InputError, match="not a gain class"):
        UniformGain(StubPerception(), len(LABELS["bin_edges"]))(frame_with(depth), depth)


def test_discontinuities_give_zero_distance_on_a_depth_step_and_the_truncation_far_from_it():
    depth = step_depth()
    perception = DiscontinuityFrontiers(None, SETTINGS, size=SIZE)
    seen = perception(frame_with(depth), depth)
    r = int(LABELS["truncation_px"])
    assert seen.distance_field.shape == (SIZE, SIZE) and seen.distance_field.dtype == np.float32
    edge = seen.distance_field[:, SIZE // 2 - 1:SIZE // 2 + 1]
    assert (edge.min(axis=1) == 0).all()  # D = 0 on the edge, every row ...
    assert seen.labels["frontier_threshold_px"] == DISCONTINUITY_THRESHOLD_PX
    assert (edge.min(axis=1) < seen.labels["frontier_threshold_px"]).all()  # ... below anchoring's l
    assert (seen.distance_field[:, :SIZE // 2 - r - 2] == r).all()  # far from it: D = r
    assert (seen.distance_field[:, SIZE // 2 + r + 2:] == r).all()
    assert (seen.gain_class == 0).all()  # no model: no gain until UniformGain


def test_discontinuities_treat_invalid_depth_as_far():
    depth = np.full((SIZE, SIZE), 2.0, np.float32)
    depth[:, SIZE // 2:] = np.nan  # no return within the sensor's range on the right
    seen = DiscontinuityFrontiers(None, SETTINGS, size=SIZE)(frame_with(depth), depth)
    frontier = seen.distance_field < DISCONTINUITY_THRESHOLD_PX
    assert frontier[:, SIZE // 2 - 1:SIZE // 2 + 1].any(axis=1).all()  # where valid borders "far"
    assert not frontier[:, :SIZE // 2 - 2].any() and not frontier[:, SIZE // 2 + 1:].any()
    everything_invalid = np.full((SIZE, SIZE), np.nan, np.float32)
    seen = DiscontinuityFrontiers(None, SETTINGS, size=SIZE)(frame_with(everything_invalid), everything_invalid)
    assert (seen.distance_field == LABELS["truncation_px"]).all()  # no crash, no frontier


def test_discontinuities_keep_the_base_gain_and_resize_without_one():
    depth = step_depth(96)  # the frame is 96 px, the working size 48 px: resized and cropped
    seen = DiscontinuityFrontiers(None, SETTINGS, size=SIZE)(frame_with(depth), depth)
    assert seen.rgb.shape == (SIZE, SIZE, 3) and seen.depth.shape == (SIZE, SIZE)
    assert seen.K[0, 0] == pytest.approx(15.0)
    with_gain = DiscontinuityFrontiers(StubPerception(), SETTINGS)(frame_with(depth), depth)
    np.testing.assert_array_equal(with_gain.gain_class, StubPerception()(frame_with(depth), depth).gain_class)
    assert (with_gain.distance_field[:, 48 - 1:48 + 1].min(axis=1) == 0).all()


def test_the_window_is_datagens_scaled_to_the_working_size():
    settings = SETTINGS
    assert settings.window_at(480) == 3 and settings.window_at(320) == 2 and settings.window_at(48) == 2
    with pytest.raises(InputError, match="ablations.discontinuity"):
        replace(SETTINGS, window_px=1)


def test_the_ablation_config_matches_datagen_and_the_simulator():
    ablation = load_config("explore").ablations
    datagen = load_config("datagen").ground_truth.discontinuity
    for key in ("window_px", "relative_jump", "min_jump_m", "invalid_is_far"):
        assert ablation.discontinuity[key] == datagen[key], key
    assert ablation.discontinuity.source_size_px == load_config("sim").camera.width
    lower_bound = LABELS["bin_edges"][ablation.uniform_gain_class - 1] * LABELS["bin_unit_m3"]
    assert lower_bound == pytest.approx(10.0)  # a mid class, above tracking.min_gain_m3


@pytest.fixture(scope="module")
def tiny_model(tmp_path_factory):
    torch.manual_seed(0)
    net = FrontierNet(NetworkConfig(decoder_channels=(32, 16, 16, 8, 8), head_channels=8)).eval()
    conf = OmegaConf.to_container(load_config("model"), resolve=True)
    conf["inference"]["size"] = 64  # small and fast
    return save_model(tmp_path_factory.mktemp("model") / "tiny.safetensors", net, conf)


def ablation(method: str, model=None, conf=None) -> Perception:
    """The perception of image method `method` built for a run of config `conf` (None: the shipped explore.yaml)."""
    conf = conf if conf is not None else load_config("explore")
    built = make_method(method, MethodContext(conf, SIM, model=model))
    return built.source.perception


@pytest.mark.parametrize("method, model_runs", [("df-uniform", True), ("discontinuity-gain", True),
                                                ("discontinuity-uniform", False)])
def test_each_ablation_method_is_built_with_its_perception(tiny_model, method, model_runs):
    built = make_method(method, MethodContext(load_config("explore"), SIM, model=tiny_model))
    perception = built.source.perception
    assert built.name == perception.name == method and built.uses_model == model_runs
    chain, node = [], perception
    while node is not None:
        chain.append(node)
        node = getattr(node, "base", None)
    assert any(isinstance(p, ModelPerception) for p in chain) == model_runs
    depth = step_depth(96)
    seen = perception(frame_with(depth), depth)
    assert seen.distance_field.shape == seen.gain_class.shape == seen.depth.shape
    if method != "discontinuity-gain":
        assert (seen.gain_class == load_config("explore").ablations.uniform_gain_class).all()


def test_the_ablations_take_the_run_config():
    conf = load_config("explore", overrides=["ablations.uniform_gain_class=4"])
    depth = step_depth(96)
    seen = ablation("discontinuity-uniform", conf=conf)(frame_with(depth), depth)
    assert (seen.gain_class == 4).all() and seen.depth.shape == (320, 320)  # the model's inference.size
    with pytest.raises(InputError, match="ablations"):
        ablation("discontinuity-uniform", conf=OmegaConf.create({"run": {"seed": 0}, "anchoring": {}}))


def test_an_unknown_method_lists_every_valid_name():
    with pytest.raises(InputError) as error:
        make_method("no-such-method", MethodContext(load_config("explore"), SIM))
    for name in ("frontiernet", "df-uniform", "discontinuity-gain", "discontinuity-uniform", "oracle"):
        assert name in METHODS.names() and name in str(error.value)


def test_datagen_still_imports_the_moved_label_functions():
    from datagen import labels

    assert labels.discontinuity_mask is discontinuity_mask and labels.distance_field is distance_field

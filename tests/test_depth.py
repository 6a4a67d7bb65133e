"""Depth sources: ground truth, emulated monocular depth, Depth Anything V2, Metric3D v2.

The real models' weights cannot be downloaded here: the tests build tiny randomly
initialised models (a transformers DepthAnything, a local torch.hub repo) and load them
through the library's real loading and inference code.
"""

from __future__ import annotations

import textwrap

import numpy as np
import pytest
from omegaconf import OmegaConf

from frontiernet.config import load_config
from frontiernet.depth import SOURCES, make_depth_source
from frontiernet.errors import InputError

H, W = 48, 64
K = np.array([[50.0, 0.0, (W - 1) / 2], [0.0, 50.0, (H - 1) / 2], [0.0, 0.0, 1.0]])


def _rgb(h: int = H, w: int = W, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (h, w, 3), dtype=np.uint8)


def _step_depth() -> np.ndarray:
    """Left half a wall at 1 m, right half at 3 m: one vertical depth discontinuity."""
    depth = np.full((H, W), 1.0, np.float32)
    depth[:, W // 2 :] = 3.0
    return depth


def options(name: str, **changes) -> dict:
    """Section `name` of the shipped ``configs/depth.yaml`` as a dict, with `changes`."""
    return {**OmegaConf.to_container(load_config("depth")[name], resolve=True), **changes}


EMULATED = options("emulated")
QUIET = options("emulated", noise_sigma=0.0, noise_sigma_per_m=0.0, scale_sigma=0.0, blur_sigma_px=0.0)


# ---------------------------------------------------------------- factory, ground truth


def test_unknown_source_lists_valid_names():
    with pytest.raises(InputError) as info:
        make_depth_source("lidar")
    assert all(name in str(info.value) for name in SOURCES)


def test_whole_config_with_overrides_builds_named_source():
    conf = load_config("depth", overrides=["source=emulated", "emulated.scale_sigma=0.3"])
    source = make_depth_source(conf)
    assert source.name == "emulated" and source.scale_sigma == 0.3


def test_unknown_option_is_refused():
    with pytest.raises(InputError, match="unknown option 'scale_sigmaa'; did you mean scale_sigma"):
        make_depth_source("emulated", options("emulated", scale_sigmaa=0.1))
    with pytest.raises(InputError, match="missing option.*scale_sigma"):
        make_depth_source("emulated", {"seed": 0})


def test_each_source_takes_exactly_the_keys_of_its_shipped_section():
    shipped = load_config("depth")
    for name, source in SOURCES.items():  # every source has a shipped section, whose keys it takes
        assert source.options() == tuple(shipped[name]), name


def test_ground_truth_passes_depth_through_with_nan_invalid():
    gt = _step_depth()
    gt[0, 0], gt[1, 1] = np.nan, 0.0
    source = make_depth_source({"source": "ground_truth"})
    assert source.requires_ground_truth
    out = source.estimate(_rgb(), K, gt)
    assert out.dtype == np.float32 and out.shape == (H, W)
    assert np.isnan(out[0, 0]) and np.isnan(out[1, 1])  # 0 is never a valid depth
    np.testing.assert_array_equal(out[2:], gt[2:])
    with pytest.raises(InputError, match="gt_depth"):
        source.estimate(_rgb(), K, None)
    with pytest.raises(InputError, match="shape"):
        source.estimate(_rgb(), K, gt[:10])


# ---------------------------------------------------------------- emulated


def test_emulated_is_deterministic_per_seed_and_seeds_differ():
    gt = _step_depth()
    a, b = make_depth_source("emulated", EMULATED), make_depth_source("emulated", EMULATED)
    a.reset(7)
    b.reset(7)
    out_a, out_b = a.estimate(_rgb(), K, gt), b.estimate(_rgb(), K, gt)
    np.testing.assert_array_equal(out_a, out_b)
    b.reset(8)
    assert not np.allclose(out_a, b.estimate(_rgb(), K, gt))
    assert out_a.dtype == np.float32 and out_a.shape == (H, W) and np.all(out_a > 0)


def test_emulated_global_scale_shows_in_median_ratio():
    gt = np.random.default_rng(1).uniform(1.0, 3.0, (H, W)).astype(np.float32)
    conf = dict(QUIET, scale_sigma=0.2, edge_band_px=0, scale_per_frame=False)
    source = make_depth_source("emulated", conf)
    log_scales = []
    for seed in range(40):
        source.reset(seed)
        ratio = np.median(source.estimate(_rgb(), K, gt) / gt)
        assert ratio == pytest.approx(source.scale, rel=1e-5)
        log_scales.append(np.log(ratio))
    assert 0.12 < np.std(log_scales) < 0.3  # about scale_sigma = 0.2
    # one scale per episode: a second frame of the same episode keeps it
    source.reset(3)
    first = source.estimate(_rgb(), K, gt)
    np.testing.assert_array_equal(first, source.estimate(_rgb(), K, gt))


def test_emulated_bleeds_edges_and_leaves_flat_regions():
    gt = _step_depth()
    out = make_depth_source("emulated", dict(QUIET, edge_band_px=3, edge_sigma_px=2.0)).estimate(_rgb(), K, gt)
    change = np.abs(out - gt)
    next_to_edge = change[:, W // 2 - 1 : W // 2 + 1]
    assert np.all(next_to_edge > 0.3)  # fore/background mixed right at the step
    flat = np.concatenate([change[:, : W // 2 - 5], change[:, W // 2 + 5 :]], axis=1)
    assert flat.max() < 1e-5
    # intermediate depths appear between the two surfaces ("flying pixels")
    assert np.any((out > 1.2) & (out < 2.8))


def test_emulated_noise_grows_with_depth():
    near = np.full((H, W), 1.0, np.float32)
    far = np.full((H, W), 3.0, np.float32)
    conf = dict(QUIET, noise_sigma=0.02, noise_sigma_per_m=0.02, noise_smooth_px=0.0)
    source = make_depth_source("emulated", conf)
    rel_near = np.std(source.estimate(_rgb(), K, near) / near)
    rel_far = np.std(source.estimate(_rgb(), K, far) / far)
    assert rel_near == pytest.approx(0.04, rel=0.2)
    assert rel_far == pytest.approx(0.08, rel=0.2)


@pytest.mark.parametrize("mode", ["far", "nearest", "none"])
def test_emulated_invalid_pixels_filled_as_configured(mode):
    gt = _step_depth()
    gt[:10, :] = np.nan  # e.g. no hit
    out = make_depth_source("emulated", dict(QUIET, fill_invalid=mode, fill_depth=5.0)).estimate(_rgb(), K, gt)
    if mode == "none":
        assert np.all(np.isnan(out[:10])) and np.all(np.isfinite(out[10:]))
    else:
        assert np.all(np.isfinite(out)) and np.all(out > 0)
        expected = 5.0 if mode == "far" else 1.0
        assert out[0, 2] == pytest.approx(expected, rel=1e-4)


def test_emulated_per_frame_scale_changes_every_frame():
    gt = np.full((H, W), 2.0, np.float32)
    source = make_depth_source("emulated", dict(QUIET, scale_per_frame=True, scale_sigma=0.2))
    medians = {float(np.median(source.estimate(_rgb(), K, gt))) for _ in range(3)}
    assert len(medians) == 3


def _frame_scales(source, gt, frames):
    """(frames,) log of the scale each consecutive frame of an episode got (median ratio to `gt`)."""
    return np.array([np.log(np.median(source.estimate(_rgb(), K, gt) / gt)) for _ in range(frames)])


def test_emulated_per_frame_scale_drifts_slowly_and_keeps_its_spread():
    """Per-frame models' scale wanders with the view but barely moves between consecutive frames
    (frame_correlation): over many episodes the spread is still scale_sigma."""
    gt = np.full((H, W), 2.0, np.float32)
    conf = dict(QUIET, scale_per_frame=True, scale_sigma=0.1, edge_band_px=0)
    jumps = {}
    for rho in (0.0, 0.97):
        source = make_depth_source("emulated", dict(conf, frame_correlation=rho))
        episodes = []
        for seed in range(60):
            source.reset(seed)
            episodes.append(_frame_scales(source, gt, 30))
        episodes = np.array(episodes)
        assert np.std(episodes[:, -1]) == pytest.approx(0.1, rel=0.3)  # stationary: the spread stays
        jumps[rho] = np.mean(np.abs(np.diff(episodes, axis=1)))
    assert jumps[0.0] == pytest.approx(0.8 * np.sqrt(2) * 0.1, rel=0.2)  # independent frames
    assert jumps[0.97] == pytest.approx(0.8 * np.sqrt(2 * 0.03) * 0.1, rel=0.2)  # ~2 %: a TAE of per-frame models


def test_emulated_noise_of_consecutive_frames_is_correlated_as_configured():
    gt = np.full((H, W), 2.0, np.float32)
    conf = dict(QUIET, noise_sigma=0.05, noise_smooth_px=0.0, edge_band_px=0)
    for rho in (0.0, 0.9):
        source = make_depth_source("emulated", dict(conf, frame_correlation=rho))
        first, second = (source.estimate(_rgb(), K, gt).ravel() - 2.0 for _ in range(2))
        assert np.corrcoef(first, second)[0, 1] == pytest.approx(rho, abs=0.08)


def test_emulated_far_wall_is_far_and_leaves_no_phantom_wall_in_the_map():
    """A wall 9 m down a corridor, beyond the 3.5 m sensor range: the emulated source degrades its
    true far depth (the renderer's hit_depth), so the map carves free space to its range and marks
    no wall there; degrading the range-clipped depth with beyond-range pixels at 3.5 m (the old
    emulation) put a wall across the corridor at the range limit."""
    from conftest import box_scene, room_boxes

    from frontiernet.geometry import pose_from_heading
    from frontiernet.mapping import OccupancyMap
    from frontiernet.simulator.camera import PinholeCamera, Renderer

    scene = box_scene(*room_boxes(10.0, 2.0, 2.5), "corridor")
    camera = PinholeCamera(96, 72, 60.0, 60.0, 47.5, 35.5, 3.5)
    T = pose_from_heading(1.0, 1.0, 1.25, 0.0)
    frame = Renderer(scene, camera, (0, 0, 0)).render(T)
    centre = (35, 47)
    assert np.isnan(frame.depth[centre]) and frame.hit_depth[centre] == pytest.approx(9.0, abs=1e-3)
    source = make_depth_source("emulated", EMULATED)
    assert source.sees_past_range and source.flying_pixels  # the explorer's map skips its depth edges
    assert not make_depth_source("ground_truth", {}).flying_pixels
    source.reset(0)
    far = source.estimate(frame.rgb, frame.K, frame.hit_depth)
    assert far[centre] > 5.0  # far, wrong by the error model

    def phantom_voxels(depth) -> int:  # occupied voxels in the corridor's open middle, away from walls
        occupancy = OccupancyMap.from_bounds(np.array([[-0.5, -0.5, -0.5], [10.5, 2.5, 3.0]]), load_config("explore").map)
        occupancy.integrate(depth, frame.K, T)
        centres = occupancy.index_to_world(np.argwhere(occupancy.occupied_mask()))
        middle = (np.abs(centres[:, 1] - 1.0) < 0.6) & (centres[:, 2] > 0.5) & (centres[:, 2] < 2.0)
        return int(middle.sum())

    assert phantom_voxels(far) == 0
    old = make_depth_source("emulated", options("emulated", fill_depth=3.5, scale_per_frame=False, frame_correlation=0.0))
    old.reset(0)
    assert phantom_voxels(old.estimate(frame.rgb, frame.K, frame.depth)) > 20


def test_emulated_bad_config_value_names_key():
    with pytest.raises(InputError, match="fill_invalid"):
        make_depth_source("emulated", options("emulated", fill_invalid="zero"))
    with pytest.raises(InputError, match="scale_sigma"):
        make_depth_source("emulated", options("emulated", scale_sigma=-1))
    with pytest.raises(InputError, match=r"frame_correlation: must be in \[0, 1\)"):
        make_depth_source("emulated", options("emulated", frame_correlation=1.0))


# ---------------------------------------------------------------- Depth Anything V2


def test_depth_anything_loads_local_weights_and_predicts_input_size(tiny_depth_anything):
    source = make_depth_source("depth_anything_v2", options("depth_anything_v2", path=str(tiny_depth_anything), device="cpu"))
    assert not source.requires_ground_truth
    out = source.estimate(_rgb(37, 53), K)  # odd size: output must match it, not the 14 px grid
    assert out.shape == (37, 53) and out.dtype == np.float32
    assert np.all(np.isfinite(out)) and np.all(out > 0)


def test_depth_anything_missing_weights_says_where_and_which_files(tmp_path):
    pytest.importorskip("transformers")
    folder = tmp_path / "no_weights_here"
    with pytest.raises(InputError) as info:
        make_depth_source("depth_anything_v2", options("depth_anything_v2", path=str(folder), device="cpu"))
    message = str(info.value)
    assert str(folder) in message
    assert all(name in message for name in ("config.json", "model.safetensors", "preprocessor_config.json"))
    assert "huggingface-cli download" in message


def test_depth_anything_absent_from_hub_cache_names_cache(tmp_path, monkeypatch):
    pytest.importorskip("transformers")
    from huggingface_hub import constants

    monkeypatch.setattr(constants, "HF_HUB_CACHE", str(tmp_path))
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path))
    repo = "depth-anything/Depth-Anything-V2-Metric-Indoor-Small-hf"
    with pytest.raises(InputError) as info:
        make_depth_source("depth_anything_v2", options("depth_anything_v2", repo_id=repo, device="cpu"))
    assert str(tmp_path / "models--depth-anything--Depth-Anything-V2-Metric-Indoor-Small-hf") in str(info.value)


def test_depth_anything_refuses_relative_model_and_corrupt_weights(tiny_depth_anything, tmp_path):
    import json
    import shutil

    relative = tmp_path / "relative"
    shutil.copytree(tiny_depth_anything, relative)
    config = json.loads((relative / "config.json").read_text())
    config["depth_estimation_type"] = "relative"
    (relative / "config.json").write_text(json.dumps(config))
    with pytest.raises(InputError, match="relative"):
        make_depth_source("depth_anything_v2", options("depth_anything_v2", path=str(relative), device="cpu"))
    corrupt = tmp_path / "corrupt"
    shutil.copytree(tiny_depth_anything, corrupt)
    (corrupt / "model.safetensors").write_bytes(b"not a safetensors file")
    with pytest.raises(InputError, match="cannot load"):
        make_depth_source("depth_anything_v2", options("depth_anything_v2", path=str(corrupt), device="cpu"))


def test_depth_anything_without_transformers_says_what_to_install(monkeypatch, tmp_path):
    import sys

    monkeypatch.setitem(sys.modules, "transformers", None)  # import fails as if not installed
    with pytest.raises(InputError, match=r"pip install frontiernet\[depth\]"):
        make_depth_source("depth_anything_v2", options("depth_anything_v2", path=str(tmp_path), device="cpu"))


# ---------------------------------------------------------------- Metric3D v2

HUBCONF = textwrap.dedent(
    """
    dependencies = ["torch"]
    import torch

    class TinyMetric3D(torch.nn.Module):
        # Canonical depth = gain * (red channel in 0-255) / 255; gain is 0 until the
        # checkpoint sets it, so a correct load is visible in the output.
        def __init__(self):
            super().__init__()
            self.gain = torch.nn.Parameter(torch.zeros(()))

        def inference(self, data):
            x = data["input"]
            red = x[:, :1] * 58.395 + 123.675
            pred = self.gain * red / 255.0
            return pred, torch.ones_like(pred), {"prediction_normal": torch.zeros_like(x)}

    def metric3d_vit_small(pretrain=False, **kwargs):
        return TinyMetric3D()
    """
)


@pytest.fixture()
def tiny_metric3d(tmp_path):
    import torch

    repo = tmp_path / "Metric3D"
    repo.mkdir()
    (repo / "hubconf.py").write_text(HUBCONF)
    weights = tmp_path / "metric_depth_vit_small_800k.pth"
    torch.save({"model_state_dict": {"gain": torch.tensor(1.0)}}, weights)
    return options("metric3d_v2", repo_dir=str(repo), weights=str(weights), device="cpu")


def test_metric3d_decanonical_scale_and_unpadding(tiny_metric3d):
    source = make_depth_source("metric3d_v2", tiny_metric3d)
    rgb = np.full((30, 80, 3), 255, np.uint8)  # canonical depth 1.0 inside, ~0.49 in the padding
    out = source.estimate(rgb, K)
    scale = min(616 / 30, 1064 / 80)
    assert out.shape == (30, 80) and out.dtype == np.float32
    # every pixel, borders included: padding removed exactly, depth = fx_scaled / 1000
    np.testing.assert_allclose(out, K[0, 0] * scale / 1000.0, rtol=1e-5)
    # twice the focal length, twice the depth
    out2 = source.estimate(rgb, K * np.array([[2.0], [2.0], [1.0]]))
    np.testing.assert_allclose(out2, 2 * out, rtol=1e-5)


def test_metric3d_missing_weights_names_file(tiny_metric3d, tmp_path, monkeypatch):
    monkeypatch.setenv("TORCH_HOME", str(tmp_path / "torch_home"))
    conf = dict(tiny_metric3d, weights=None)
    with pytest.raises(InputError) as info:
        make_depth_source("metric3d_v2", conf)
    assert "metric_depth_vit_small_800k.pth" in str(info.value)
    assert str(tmp_path / "torch_home" / "hub" / "checkpoints") in str(info.value)


def test_metric3d_missing_dependency_is_named(tiny_metric3d, tmp_path):
    repo = tmp_path / "Metric3D_needs_mm"
    repo.mkdir()
    (repo / "hubconf.py").write_text("import mmengine_not_installed_here\n")
    with pytest.raises(InputError, match="mmengine_not_installed_here"):
        make_depth_source("metric3d_v2", dict(tiny_metric3d, repo_dir=str(repo)))


def test_metric3d_missing_repo_says_how_to_get_it(tmp_path):
    with pytest.raises(InputError) as info:
        make_depth_source("metric3d_v2", options("metric3d_v2", repo_dir=str(tmp_path / "nothing"), device="cpu"))
    assert "github.com/YvanYin/Metric3D" in str(info.value) and "hubconf.py" in str(info.value)


def test_gt_names_the_ground_truth_source_in_every_command():
    """``--depth gt`` means the ground-truth source wherever a depth source is named (explore,
    bench and evaluate share the one alias table)."""
    from frontiernet.config import load_config
    from frontiernet.depth import GroundTruthDepth, depth_source_name, make_depth_source

    assert depth_source_name("gt") == "ground_truth" and depth_source_name("emulated") == "emulated"
    assert isinstance(make_depth_source("gt", load_config("depth")), GroundTruthDepth)

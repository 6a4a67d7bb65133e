"""Export and runtimes: ONNX (onnxruntime), TorchScript and torch agree on real images; `frontiernet
predict` writes an overlay; bad images, depth maps and model files exit 2 with one line."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from deploy.export import export
from frontiernet.sequences import read_depth
from deploy.runtime import load_runtime
from frontiernet.cli.main import main
from frontiernet.config import load_config
from frontiernet.model import FrontierNet, NetworkConfig, default_model_path, resize_and_crop, save_model

MODEL_CONF = OmegaConf.to_container(load_config("model"), resolve=True)


@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    """The shipped model when the checkout has it, else a small random one."""
    if default_model_path().is_file():
        return default_model_path()
    torch.manual_seed(0)
    net = FrontierNet(NetworkConfig(decoder_channels=(32, 16, 16, 8, 8), head_channels=8)).eval()
    return save_model(tmp_path_factory.mktemp("model") / "small.safetensors", net, MODEL_CONF)


@pytest.fixture(scope="module")
def exported(model_file, tmp_path_factory):
    folder = tmp_path_factory.mktemp("exported")
    return {"torch": model_file, "onnx": export(model_file, "onnx", folder / "m.onnx"),
            "torchscript": export(model_file, "torchscript", folder / "m.pt")}


def real_frames(shared_data):
    """(rgb, depth metres) pairs: the TUM frame and a livingroom1 frame, at the model's 320 px."""
    frames = []
    tum_rgb = cv2.imread(str(shared_data / "images/rgbd_frames/TUM_color.png"))[..., ::-1]
    tum_depth = read_depth(shared_data / "images/rgbd_frames/TUM_depth.png", 5000.0)
    frames.append((tum_rgb, tum_depth))
    room = shared_data / "images/livingroom1"
    frames.append((cv2.imread(str(room / "color/00000.jpg"))[..., ::-1], read_depth(room / "depth/00000.png")))
    return [resize_and_crop(np.ascontiguousarray(rgb), depth, None, 320)[:2] for rgb, depth in frames]


def test_torch_onnx_and_torchscript_agree_on_real_images(exported, shared_data):
    runtimes = {name: load_runtime(path, threads=1) for name, path in exported.items()}
    for rgb, depth in real_frames(shared_data):
        reference = runtimes["torch"].predict(rgb, depth)
        probabilities = torch.softmax(torch.from_numpy(reference[1]), 0)
        for name in ("onnx", "torchscript"):
            distance, logits = runtimes[name].predict(rgb, depth)
            assert np.abs(distance - reference[0]).max() < 1e-4, name  # pixels
            assert (torch.softmax(torch.from_numpy(logits), 0) - probabilities).abs().max() < 1e-4, name
            # logits reach +-25: float32 rounding of a different kernel order is ~1e-6 of that
            assert np.allclose(logits, reference[1], rtol=1e-5, atol=1e-4), name


def test_exported_models_take_any_size(exported):
    rgb = np.random.default_rng(1).integers(0, 255, (75, 101, 3), dtype=np.uint8)
    depth = np.full((75, 101), 1.5, np.float32)
    reference = load_runtime(exported["torch"], threads=1).predict(rgb, depth)
    for name in ("onnx", "torchscript"):
        distance, logits = load_runtime(exported[name], threads=1).predict(rgb, depth)
        assert distance.shape == (75, 101) and logits.shape == (11, 75, 101)
        assert np.abs(logits - reference[1]).max() < 1e-4


@pytest.mark.parametrize("encoder", ["mobilenet_v3_large", "efficientnet_b0"])
def test_light_encoders_export_and_agree(encoder, tmp_path):
    """MobileNetV3 (hardswish, squeeze-excitation) and EfficientNet (SiLU) export to ONNX at the
    opset used and to TorchScript, record their encoder, and match torch at an odd size."""
    torch.manual_seed(0)
    net = FrontierNet(NetworkConfig(encoder=encoder, decoder_channels=(32, 16, 16, 8, 8), head_channels=8)).eval()
    model = save_model(tmp_path / "light.safetensors", net, MODEL_CONF)
    rgb = np.random.default_rng(2).integers(0, 255, (75, 101, 3), dtype=np.uint8)
    depth = np.full((75, 101), 1.5, np.float32)
    reference = load_runtime(model, threads=1).predict(rgb, depth)
    for fmt, suffix in (("onnx", "onnx"), ("torchscript", "pt")):
        runtime = load_runtime(export(model, fmt, tmp_path / f"light.{suffix}"), threads=1)
        assert runtime.conf["network"]["encoder"] == encoder
        distance, logits = runtime.predict(rgb, depth)
        assert np.abs(distance - reference[0]).max() < 1e-4, fmt
        assert np.abs(logits - reference[1]).max() < 1e-4, fmt


def test_onnx_runs_on_the_threads_torch_was_given_unless_told(exported):
    """A benchmark worker limits torch to its share of the cores; an ONNX model it opens keeps to it."""
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        assert load_runtime(exported["onnx"]).session.get_session_options().intra_op_num_threads == 1
        assert load_runtime(exported["onnx"], threads=2).session.get_session_options().intra_op_num_threads == 2
    finally:
        torch.set_num_threads(previous)


def test_predict_command_writes_overlay_and_arrays(model_file, tmp_path, capsys):
    rgb = np.zeros((120, 160, 3), np.uint8)
    rgb[:, 80:] = (200, 180, 160)
    cv2.imwrite(str(tmp_path / "rgb.png"), rgb[..., ::-1])
    depth = np.full((120, 160), 1000, np.uint16)
    depth[:, 80:] = 3000
    cv2.imwrite(str(tmp_path / "depth.png"), depth)
    out = tmp_path / "out"
    assert main(["predict", "--image", str(tmp_path / "rgb.png"), "--depth", str(tmp_path / "depth.png"),
                 "--model", str(model_file), "--out", str(out)]) == 0
    assert "frontier pixels" in capsys.readouterr().out
    overlay = cv2.imread(str(out / "overlay.png"))
    assert overlay.shape == (320, 320, 3)  # short side resized to the model's 320, centre-cropped
    arrays = np.load(out / "outputs.npz")
    assert arrays["distance_field"].shape == (320, 320) and arrays["gain_logits"].shape == (11, 320, 320)
    threshold = load_runtime(model_file).labels["frontier_threshold_px"]  # the model file's own l
    assert np.array_equal(arrays["frontier_mask"], arrays["distance_field"] < threshold)
    assert abs(float(arrays["depth"].max()) - 3.0) < 1e-6  # millimetres read as metres
    assert main(["predict", "--image", str(tmp_path / "rgb.png"), "--depth", str(tmp_path / "depth.png"),
                 "--model", str(model_file), "--out", str(tmp_path / "native"), "--size", "0"]) == 0
    assert cv2.imread(str(tmp_path / "native" / "overlay.png")).shape == (120, 160, 3)


def test_predict_estimates_the_depth_of_a_plain_photo_with_a_monocular_model(model_file, tiny_depth_anything,
                                                                            tmp_path, capsys):
    """`--depth depth_anything_v2`: the RGB + depth model runs on a photo alone, its depth channel the
    monocular model's estimate made invalid beyond the sensor's range, as the explorer hands it
    monocular depth (weights from a local folder set by an override)."""
    from frontiernet.depth import make_depth_source
    from frontiernet.model.predictor import beyond_range_invalid, invalid_to_zero

    rgb = np.random.default_rng(0).integers(0, 256, (90, 120, 3), dtype=np.uint8)
    cv2.imwrite(str(tmp_path / "photo.png"), rgb[..., ::-1])
    weights = [f"depth.depth_anything_v2.path={tiny_depth_anything}", "depth.depth_anything_v2.device=cpu"]
    out = tmp_path / "out"
    assert main(["predict", "--image", str(tmp_path / "photo.png"), "--depth", "depth_anything_v2", "--model",
                 str(model_file), "--out", str(out), "--intrinsics", "100,100,59.5,44.5", *weights]) == 0
    assert "frontier pixels" in capsys.readouterr().out
    options = OmegaConf.to_container(load_config("depth").depth_anything_v2, resolve=True)
    estimate = make_depth_source("depth_anything_v2", {**options, "path": str(tiny_depth_anything),
                                                       "device": "cpu"}).estimate(rgb, np.eye(3))
    runtime = load_runtime(model_file)
    _, expected, _ = resize_and_crop(rgb, beyond_range_invalid(estimate, runtime.conf["input"]["max_depth_m"]),
                                     None, 320)
    seen = np.load(out / "outputs.npz")["depth"]
    assert seen.shape == (320, 320) and np.allclose(seen, invalid_to_zero(expected), atol=1e-5)
    assert (seen > 0).all()  # the tiny model's estimate lies inside the range everywhere
    record = json.loads((out / "frontiers.json").read_text())
    assert record["depth"] == "depth_anything_v2" and isinstance(record["frontiers"], list)


def test_bad_predict_and_export_input_is_one_line_exit_2(model_file, tmp_path, capsys, one_line_error):
    grey = tmp_path / "grey.png"
    cv2.imwrite(str(grey), np.zeros((40, 50), np.uint8))
    rgb = tmp_path / "rgb.png"
    cv2.imwrite(str(rgb), np.zeros((40, 50, 3), np.uint8))
    depth_small = tmp_path / "small.npy"
    np.save(depth_small, np.ones((20, 25), np.float32))
    depth_negative = tmp_path / "negative.npy"  # (NaN is invalid depth, as render writes it: tests/test_bad_input.py)
    np.save(depth_negative, np.full((40, 50), -1.0, np.float32))
    good_depth = tmp_path / "good.npy"
    np.save(good_depth, np.ones((40, 50), np.float32))
    corrupt = tmp_path / "corrupt.onnx"
    corrupt.write_bytes(b"not a model")
    out = str(tmp_path / "out")
    cases = [
        (["predict", "--image", str(grey), "--depth", str(good_depth), "--model", str(model_file), "--out", out],
         "grey.png: image has 1 channel(s)"),
        (["predict", "--image", str(rgb), "--depth", str(depth_small), "--model", str(model_file), "--out", out],
         "depth map is 25 x 20 but the image is 50 x 40"),
        (["predict", "--image", str(rgb), "--depth", str(depth_negative), "--model", str(model_file), "--out", out],
         "negative.npy: no valid depth"),
        (["predict", "--image", str(rgb), "--model", str(model_file), "--out", out], "give --depth"),
        (["predict", "--image", str(rgb), "--depth", str(good_depth), "--model", str(corrupt), "--out", out],
         "corrupt.onnx: not a loadable ONNX model"),
        (["predict", "--image", str(rgb), "--depth", str(good_depth), "--model", str(tmp_path / "x.bin"),
          "--out", out], "x.bin: model file not found"),
        (["export", str(model_file), "--format", "onnx", "--out", str(tmp_path / "no" / "m.onnx")],
         "output folder does not exist"),
        (["predict", "--image", str(rgb), "--depth", "emulated", "--model", str(model_file), "--out", out],
         "--depth emulated: that source reads a sensor's depth (the simulator's), and predict has none"),
        (["predict", "--image", str(rgb), "--depth", "metric3d_v2", "--model", str(model_file), "--out", out],
         "--depth metric3d_v2: the model reads the camera's focal length; give --intrinsics"),
        (["predict", "--depth", "depth_anything_v2", "--model", str(model_file), "--out", out],
         "give --image"),
        (["predict", "--image", str(rgb), "--depth", "depth_anything_v2", "--model", str(model_file), "--out", out,
          f"depth.depth_anything_v2.path={tmp_path / 'no_weights'}"], "no_weights (missing config.json"),
        (["predict", "--image", str(rgb), "--depth", str(good_depth), "--model", str(model_file), "--out", out,
          "depth.depth_anything_v2.pth=x"], "depth_anything_v2.pth"),
    ]
    for argv, expected in cases:
        assert main(argv) == 2, argv
        assert expected in one_line_error()
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_exported_files_carry_the_model_config(exported):
    import onnx

    proto = onnx.load(str(exported["onnx"]), load_external_data=False)
    meta = {entry.key: entry.value for entry in proto.metadata_props}
    conf = json.loads(meta["frontiernet_model"])
    assert conf["labels"]["num_classes"] == 11 and conf["network"]["inputs"] == "rgbd"
    assert load_runtime(exported["torchscript"]).conf["input"] == MODEL_CONF["input"]


def test_export_sets_the_frontier_threshold_its_runtimes_use(model_file, tmp_path, capsys, one_line_error):
    """`export --frontier-threshold` (the best-F1 l of evaluate) travels in every format."""
    for fmt, name in (("safetensors", "m.safetensors"), ("onnx", "m.onnx")):
        assert main(["export", str(model_file), "--format", fmt, "--out", str(tmp_path / name),
                     "--frontier-threshold", "2.5"]) == 0
        assert load_runtime(tmp_path / name).conf["labels"]["frontier_threshold_px"] == 2.5
    # without the option the model's own threshold is kept
    kept = export(model_file, "safetensors", tmp_path / "kept.safetensors")
    assert load_runtime(kept).conf["labels"] == load_runtime(model_file).conf["labels"]
    capsys.readouterr()
    assert main(["export", str(model_file), "--format", "onnx", "--out", str(tmp_path / "bad.onnx"),
                 "--frontier-threshold", "0"]) == 2
    assert "--frontier-threshold must be a positive number of pixels" in one_line_error()
    assert not (tmp_path / "bad.onnx").exists()


def test_predict_picks_the_shipped_model_by_the_inputs_given(tmp_path, monkeypatch, capsys, one_line_error):
    """--image alone takes the shipped RGB-only model (the public demo's single-image inference),
    --image with --depth the RGB + depth one; a missing shipped file is one line naming it."""
    import frontiernet.model.files as model_files
    import frontiernet.model.network as network

    weights = tmp_path / "weights"
    weights.mkdir()
    torch.manual_seed(0)
    small = dict(decoder_channels=(32, 16, 16, 8, 8), head_channels=8)
    save_model(weights / network.SHIPPED_MODELS["rgbd"], FrontierNet(NetworkConfig(**small)).eval(), MODEL_CONF)

    files = model_files.resources.files

    class Files:  # importlib.resources.files("frontiernet") with the weights folder in tmp_path
        def __init__(self, package):
            self.package = package

        def joinpath(self, *parts):
            return weights.joinpath(*parts[1:]) if parts[0] == "weights" else files(self.package).joinpath(*parts)

    monkeypatch.setattr(model_files.resources, "files", Files)
    rgb = tmp_path / "photo.png"
    cv2.imwrite(str(rgb), np.full((60, 80, 3), 128, np.uint8))
    depth = tmp_path / "depth.npy"
    np.save(depth, np.full((60, 80), 2.0, np.float32))
    assert main(["predict", "--image", str(rgb), "--out", str(tmp_path / "a")]) == 2
    assert "frontiernet_rgb_resnet18.safetensors: no shipped model takes an RGB image alone" in one_line_error()
    assert main(["predict", "--image", str(rgb), "--depth", str(depth), "--out", str(tmp_path / "b")]) == 0
    save_model(weights / network.SHIPPED_MODELS["rgb"],
               FrontierNet(NetworkConfig(inputs="rgb", **small)).eval(), MODEL_CONF)
    capsys.readouterr()
    assert main(["predict", "--image", str(rgb), "--out", str(tmp_path / "c")]) == 0
    assert (tmp_path / "c" / "overlay.png").is_file() and "depth" not in np.load(tmp_path / "c" / "outputs.npz")


def test_bench_encoders_times_each_encoder_against_the_first():
    from deploy.bench import bench_encoders

    results = bench_encoders(["resnet18", "mobilenet_v3_small"], sizes=(40,), repeats=1, train_crop=32, train_batch=2)
    assert results["baseline"] == "resnet18" and results["parameters_m"]["mobilenet_v3_small"] < 2
    for rows in (results["sizes"]["40"], results["training"]["rows"]):
        assert set(rows) == {"resnet18", "mobilenet_v3_small"}
        assert all(value == 1.0 for key, value in rows["resnet18"].items() if key.startswith("speedup_"))
        assert "speedup_1_threads" in rows["mobilenet_v3_small"]


def test_running_an_exported_model_does_not_import_torchvision():
    """torchvision (~1.5 s to import: it pulls in torch._dynamo) builds networks; a process that
    runs an exported model and the exploration around it never needs it."""
    import subprocess
    import sys

    code = ("import sys, frontiernet.model, frontiernet.exploration.methods, deploy.runtime, deploy.predict; "
            "print('torchvision' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"

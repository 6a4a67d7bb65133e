"""Bad input of the fourteenth probe (/tmp/probe14/report.md) for ``predict`` and the model files it reads: P2 a
principal point that leaves the network's resized input (refused after the pictures were written, quoting the
rescaled numbers), P4 an ONNX model whose embedded config is not JSON (an internal error), P5 an embedded config
out of range (never checked: crashes, NaN results), P6 a 1 x 1 px image (upscaled and run), P7 a uint8 ``.npy``
depth (read as millimetres). Each refusal: one line naming the file or value, exit code 2, nothing written."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from frontiernet.cli.main import main
from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.model import FrontierNet, NetworkConfig, load_model, open_runtime, save_model

MODEL_CONF = OmegaConf.to_container(load_config("model"), resolve=True)


def tiny_model(path, labels: dict | None = None):
    """A small random RGB + depth model file whose embedded labels section has `labels` changed."""
    torch.manual_seed(0)
    net = FrontierNet(NetworkConfig.from_dict({"encoder": "mobilenet_v3_small", "inputs": "rgbd",
                                               "decoder_channels": [16, 16, 8, 8, 8], "head_channels": 8})).eval()
    conf = json.loads(json.dumps(MODEL_CONF))
    conf["labels"].update(labels or {})
    return save_model(path, net, conf)


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    return tiny_model(tmp_path_factory.mktemp("model") / "tiny.safetensors")


@pytest.fixture(scope="module")
def onnx_model(model, tmp_path_factory):
    from deploy.export import export

    return export(model, "onnx", tmp_path_factory.mktemp("onnx") / "tiny.onnx")


def frame(folder, width: int = 64, height: int = 64, name: str = "rgb.png"):
    """An image and a float depth map (metres) of `width` x `height` px in `folder`."""
    rgb = np.zeros((height, width, 3), np.uint8)
    rgb[:, width // 2:] = (200, 180, 160)
    cv2.imwrite(str(folder / name), rgb)
    depth = np.full((height, width), 1.5, np.float32)
    depth[:, width // 2:] = 3.0
    np.save(folder / (name.split(".")[0] + "_depth.npy"), depth)
    return folder / name, folder / (name.split(".")[0] + "_depth.npy")


def with_onnx_config(source, target, text: str):
    """A copy of ONNX model `source` at `target` whose embedded model config is `text`."""
    import onnx

    proto = onnx.load(str(source))
    for entry in proto.metadata_props:
        if entry.key == "frontiernet_model":
            entry.value = text
    onnx.save(proto, str(target))
    return target


# ----------------------------------------------------------------------------- P2

def test_a_principal_point_outside_the_resized_input_is_refused_before_any_picture(model, tmp_path, one_line_error):
    # was: overlay.png, distance.png, input.png, outputs.npz written, then "K's principal point (-0.25, 15.75) lies
    # outside the 32 x 32 depth image" (the rescaled numbers)
    rgb, depth = frame(tmp_path)
    out = tmp_path / "o"
    argv = ["predict", "--image", str(rgb), "--depth", str(depth), "--model", str(model), "--size", "32",
            "--intrinsics", "60,60,0,32"]
    assert main([*argv, "--out", str(out)]) == 2
    assert ("--intrinsics: the principal point (0, 32) lies outside the part of the 64 x 64 image the network sees "
            "at --size 32 (resized and centre-cropped: x 0.5 to 62.5, y 0.5 to 62.5 in the image's pixels)"
            in one_line_error())
    assert not out.exists()
    kept = tmp_path / "kept"  # --force over an earlier run: its files stay, nothing new is written
    kept.mkdir()
    (kept / "overlay.png").write_bytes(b"earlier")
    assert main([*argv, "--out", str(kept), "--force"]) == 2
    one_line_error()
    assert sorted(p.name for p in kept.iterdir()) == ["overlay.png"] and (kept / "overlay.png").read_bytes() == b"earlier"
    # a point in the part the network sees runs; --size 0 keeps the image's own pixels, where 0 is inside
    assert main([*argv[:-1], "60,60,1,32", "--out", str(tmp_path / "in")]) == 0
    assert (tmp_path / "in" / "frontiers.json").is_file()
    assert main([*argv[:-3], "0", "--intrinsics", "60,60,0,32", "--out", str(tmp_path / "own")]) == 0


def test_a_principal_point_in_the_cropped_off_part_is_refused(model, tmp_path, one_line_error):
    rgb, depth = frame(tmp_path, 128, 64)  # at --size 32: 64 x 32, the middle 32 x 32 kept: x 32.5 to 94.5
    assert main(["predict", "--image", str(rgb), "--depth", str(depth), "--model", str(model), "--size", "32",
                 "--intrinsics", "60,60,10,32", "--out", str(tmp_path / "o")]) == 2
    assert "the principal point (10, 32) lies outside the part of the 128 x 64 image" in one_line_error()
    assert not (tmp_path / "o").exists()


# ----------------------------------------------------------------------------- P4, P5

def test_an_onnx_model_whose_config_is_not_json_is_named(onnx_model, tmp_path, one_line_error):
    # was: internal error (JSONDecodeError: Unterminated string starting at: line 1 column 2 (char 1))
    bad = with_onnx_config(onnx_model, tmp_path / "badmeta.onnx", '{"broken')
    rgb, depth = frame(tmp_path)
    assert main(["predict", "--image", str(rgb), "--depth", str(depth), "--model", str(bad),
                 "--out", str(tmp_path / "o")]) == 2
    assert f"{bad}: its embedded model config is not valid JSON" in one_line_error()
    assert not (tmp_path / "o").exists()
    with pytest.raises(InputError, match="badmeta.onnx: its embedded model config is not valid JSON"):
        open_runtime(bad)  # explore --model's runtime
    not_object = with_onnx_config(onnx_model, tmp_path / "list.onnx", "[1, 2]")
    with pytest.raises(InputError, match="list.onnx: its embedded model config is not a JSON object"):
        open_runtime(not_object)


@pytest.mark.parametrize("labels, key", [({"num_classes": -3}, "labels.num_classes must be an integer in [2, 256], "
                                                                "got -3"),
                                         ({"truncation_px": float("nan")}, "labels.truncation_px must be a number > 0, "
                                                                           "got nan")])
def test_an_embedded_config_out_of_range_is_refused_wherever_the_file_is_read(labels, key, tmp_path, one_line_error):
    # was: predict an internal error (ValueError: Number of samples, -4, ...) or NaN pictures with numpy warnings,
    # export re-exported the file, evaluate printed "DF error nan"
    bad = tiny_model(tmp_path / "bad.safetensors", labels)
    message = f"{bad}: its embedded model config is out of range: {key}"
    rgb, depth = frame(tmp_path)
    assert main(["predict", "--image", str(rgb), "--depth", str(depth), "--model", str(bad),
                 "--out", str(tmp_path / "o")]) == 2
    assert message in one_line_error()
    assert not (tmp_path / "o").exists()
    assert main(["export", str(bad), "--format", "onnx", "--out", str(tmp_path / "e.onnx")]) == 2
    assert message in one_line_error()
    assert not (tmp_path / "e.onnx").exists()
    for read in (load_model, open_runtime):  # evaluate and export; predict and explore
        with pytest.raises(InputError) as error:
            read(bad)
        assert message in str(error.value)


def test_an_onnx_config_out_of_range_is_refused(onnx_model, tmp_path):
    conf = json.loads(json.dumps(open_runtime(onnx_model).conf))
    conf["labels"]["truncation_px"] = float("nan")
    bad = with_onnx_config(onnx_model, tmp_path / "nan.onnx", json.dumps(conf))
    with pytest.raises(InputError, match=r"nan.onnx: its embedded model config is out of range: "
                                         r"labels.truncation_px must be a number > 0, got nan"):
        open_runtime(bad)
    conf["labels"]["truncation_px"], conf["labels"]["frontier_threshold_px"] = 10.0, 20.0  # a relation broken
    other = with_onnx_config(onnx_model, tmp_path / "other.onnx", json.dumps(conf))
    with pytest.raises(InputError, match=r"other.onnx: its embedded model config is out of range: "
                                         r"labels.min_distance_px < labels.frontier_threshold_px < labels.truncation_px"):
        open_runtime(other)


# ----------------------------------------------------------------------------- P6

@pytest.mark.parametrize("width, height, size", [(1, 1, []), (480, 2, []), (1, 1, ["--size", "0"]),
                                                 (31, 64, ["--size", "0"])])
def test_an_image_under_the_minimum_size_is_refused_naming_it(width, height, size, model, tmp_path, one_line_error):
    # was: a 1 x 1 px image upscaled 320 times and run, exit 0 ("0 frontier pixels")
    rgb, depth = frame(tmp_path, width, height, "small.png")
    assert main(["predict", "--image", str(rgb), "--depth", str(depth), "--model", str(model), *size,
                 "--out", str(tmp_path / "o")]) == 2
    assert (f"{rgb}: an image of {width} x {height} pixels is too small: predict needs at least 32 px on each side"
            in one_line_error())
    assert not (tmp_path / "o").exists()


def test_an_image_of_the_minimum_size_runs(model, tmp_path):
    from deploy.predict import MIN_IMAGE_PX

    rgb, depth = frame(tmp_path, MIN_IMAGE_PX, MIN_IMAGE_PX)
    assert main(["predict", "--image", str(rgb), "--depth", str(depth), "--model", str(model), "--size", "32",
                 "--out", str(tmp_path / "o")]) == 0


# ----------------------------------------------------------------------------- P7

def test_an_8_bit_npy_depth_is_refused_as_an_8_bit_png_is(model, tmp_path, one_line_error):
    # was: read as millimetres (5 to 25 cm) and run, exit 0
    from frontiernet.sequences.images import read_depth

    rgb, _ = frame(tmp_path)
    for dtype in (np.uint8, np.int8):
        depth = tmp_path / f"d_{np.dtype(dtype).name}.npy"
        np.save(depth, np.full((64, 64), 100, dtype))
        assert main(["predict", "--image", str(rgb), "--depth", str(depth), "--model", str(model),
                     "--out", str(tmp_path / "o")]) == 2
        assert (f"{depth}: holds 8-bit integer ({np.dtype(dtype).name}) values; integer depth must be 16-bit or wider"
                in one_line_error())
        assert not (tmp_path / "o").exists()
    millimetres = tmp_path / "d_u16.npy"
    np.save(millimetres, np.full((64, 64), 1500, np.uint16))
    assert np.allclose(read_depth(millimetres), 1.5)  # 16-bit integer depth is read as before

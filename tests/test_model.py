"""The FrontierNet network and its model files: any input size, the three input kinds, safe and
strict loading (a malicious pickle is refused), ImageNet weights from a local file."""

from __future__ import annotations

import os
import pickle
import zipfile

import numpy as np
import pytest
import torch
import torchvision

from frontiernet.errors import InputError
from frontiernet.model import (FEATURE_ENCODERS, FrontierNet, NetworkConfig, Predictor, check_images, decode_distance,
                               encode_distance, load_imagenet_encoder, load_model, resize_and_crop, save_model)
from frontiernet.config import load_config
from omegaconf import OmegaConf

MODEL_CONF = OmegaConf.to_container(load_config("model"), resolve=True)


def small_net(inputs: str = "rgbd", encoder: str = "resnet18") -> FrontierNet:
    torch.manual_seed(0)
    return FrontierNet(NetworkConfig(encoder=encoder, inputs=inputs, decoder_channels=(32, 16, 16, 8, 8),
                                     head_channels=8)).eval()


@pytest.mark.parametrize("inputs,channels", [("rgbd", 4), ("rgb", 3), ("depth", 1)])
def test_any_input_size_gives_full_size_outputs(inputs, channels):
    net = small_net(inputs)
    with torch.no_grad():
        distance, logits = net(torch.randn(2, channels, 70, 93))
    assert distance.shape == (2, 1, 70, 93) and logits.shape == (2, 11, 70, 93)
    assert (distance >= 0).all()  # y = -log(D / r) >= 0 because D <= r


def test_padding_does_not_leak_into_the_image():
    """A 64 x 64 crop of a 70 x 93 input and the crop run alone differ only near the crop's
    padded border: the network does not resize, so pixel scale is kept."""
    net = small_net()
    image = torch.randn(1, 4, 64, 64)
    with torch.no_grad():
        alone = net(image)[0]
        padded = net(torch.nn.functional.pad(image, (0, 29, 0, 6)))[0][..., :64, :64]
    assert alone.shape == padded.shape == (1, 1, 64, 64)


@pytest.mark.parametrize("encoder", ["resnet34", "resnet50", *FEATURE_ENCODERS])
def test_other_encoders_build_and_run(encoder):
    net = small_net(encoder=encoder)
    with torch.no_grad():
        distance, logits = net(torch.randn(1, 4, 64, 64))
    assert distance.shape == (1, 1, 64, 64) and logits.shape == (1, 11, 64, 64)


@pytest.mark.parametrize("encoder", ["resnet18", *FEATURE_ENCODERS])
def test_encoder_skips_are_at_strides_2_to_32_with_the_listed_channels(encoder):
    net = small_net(encoder=encoder)
    with torch.no_grad():
        features = [net.stem(torch.randn(1, 4, 128, 96))]
        features.append(net.layers[0](net.pool(features[0])))
        for layer in net.layers[1:]:
            features.append(layer(features[-1]))
    assert [(128 // f.shape[2], 96 // f.shape[3]) for f in features] == [(s, s) for s in (2, 4, 8, 16, 32)]
    if encoder in FEATURE_ENCODERS:
        assert [f.shape[1] for f in features] == [width for _, width in FEATURE_ENCODERS[encoder]]


@pytest.mark.parametrize("encoder", list(FEATURE_ENCODERS))
def test_imagenet_weights_of_a_light_encoder(encoder, tmp_path, monkeypatch):
    """The torchvision state dict (here of a random model) fills the encoder: with RGB input it
    computes what torchvision's `features` do up to the stride-32 block; RGB-D gets the mean filter."""
    torch.manual_seed(1)
    reference = getattr(torchvision.models, encoder)(weights=None).eval()
    name = {"efficientnet_b0": "efficientnet_b0_rwightman-7f5810bc.pth"}.get(encoder, f"{encoder}-0123abcd.pth")
    (tmp_path / "checkpoints").mkdir()
    torch.save(reference.state_dict(), tmp_path / "checkpoints" / name)
    monkeypatch.setattr(torch.hub, "get_dir", lambda: str(tmp_path))
    net = small_net("rgb", encoder)
    names = load_imagenet_encoder(net, "hub")
    assert "stem.0.0.weight" in names
    assert not any(name.startswith(("decoder", "distance_head", "gain_head")) for name in names)
    image = torch.randn(1, 3, 64, 64)
    last = FEATURE_ENCODERS[encoder][-1][0]
    with torch.no_grad():
        y = net.stem(image)
        for layer in net.layers:
            y = layer(y)
        assert torch.equal(y, reference.features[:last](image))
    rgbd = small_net("rgbd", encoder)
    load_imagenet_encoder(rgbd, tmp_path / "checkpoints" / name)
    first = reference.features[0][0].weight
    assert torch.equal(rgbd.stem[0][0].weight[:, :3], first)
    assert torch.allclose(rgbd.stem[0][0].weight[:, 3], first.mean(1))
    torch.save(torchvision.models.resnet18(weights=None).state_dict(), tmp_path / "resnet18.pth")
    with pytest.raises(InputError, match=f"not a torchvision {encoder} state dict"):
        load_imagenet_encoder(rgbd, tmp_path / "resnet18.pth")


def test_distance_encoding_round_trip_and_threshold():
    labels = MODEL_CONF["labels"]
    distance = torch.tensor([0.0, 0.5, 1.0, 5.0, 10.0])
    encoded = encode_distance(distance, labels)
    assert encoded[-1] == 0 and (encoded[:-1] > 0).all()
    decoded = decode_distance(encoded, labels)
    assert decoded[0] < labels["frontier_threshold_px"] <= decoded[1]  # F = [D < l] exact for D = 0
    assert torch.allclose(decoded[1:], distance[1:])


def test_imagenet_weights_from_a_local_file(tmp_path):
    resnet = torchvision.models.resnet18(weights=None)
    path = tmp_path / "resnet18-f37072fd.pth"
    torch.save(resnet.state_dict(), path)
    net = small_net()
    names = load_imagenet_encoder(net, path)
    assert "layers.3.1.conv2.weight" in names
    assert torch.equal(net.layers[3][1].conv2.weight, resnet.layer4[1].conv2.weight)
    stem = net.stem[0].weight
    assert torch.equal(stem[:, :3], resnet.conv1.weight)
    assert torch.allclose(stem[:, 3], resnet.conv1.weight.mean(1))  # depth channel: mean of RGB filters
    with pytest.raises(InputError, match="not found"):
        load_imagenet_encoder(net, tmp_path / "missing.pth")
    torch.save(torchvision.models.resnet34(weights=None).state_dict(), tmp_path / "r34.pth")
    with pytest.raises(InputError, match="does not fit a resnet18"):
        load_imagenet_encoder(net, tmp_path / "r34.pth")


def test_model_file_round_trip(tmp_path):
    net = small_net()
    path = save_model(tmp_path / "m.safetensors", net, MODEL_CONF, info={"note": "test"})
    loaded, conf = load_model(path)
    assert conf["network"]["decoder_channels"] == [32, 16, 16, 8, 8] and conf["info"] == {"note": "test"}
    x = torch.randn(1, 4, 40, 48)
    with torch.no_grad():
        assert torch.equal(net(x)[0], loaded(x)[0])
    half, _ = load_model(save_model(tmp_path / "h.safetensors", net, MODEL_CONF, half=True))
    with torch.no_grad():
        assert torch.allclose(net(x)[1], half(x)[1], atol=5e-2)
    assert (tmp_path / "h.safetensors").stat().st_size < 0.6 * path.stat().st_size


def test_checkpoints_of_other_kinds_are_named_for_what_they_are(tmp_path, one_line_error):
    # eighth probe: a map predictor's checkpoint was "not written by frontiernet train" (E23); a dataset shard
    # (a zip archive) got torch's words, cut mid-word, asking to report a bug (E24)
    from frontiernet.cli.main import main

    mapex = tmp_path / "last.ckpt"
    torch.save({"state_dict": {"w": torch.zeros(2)}, "hyper_parameters": {"predictor": {"kind": "mapex"},
                                                                         "train": {}}}, mapex)
    shard = tmp_path / "00000-procedural-3-0000.zip"
    with zipfile.ZipFile(shard, "w") as archive:  # as datagen writes one: a folder a view, then meta.json
        archive.writestr("000000/rgb.png", b"")
        archive.writestr("meta.json", "{}")
    flat = tmp_path / "flat.zip"
    with zipfile.ZipFile(flat, "w") as archive:
        archive.writestr("meta.json", "{}")
    for path, reason in ((mapex, "a mapex map predictor's checkpoint (frontiernet train of configs/train_mapex.yaml), "
                                 "not a FrontierNet model's"),
                         (shard, "not a readable checkpoint (a zip archive, but not PyTorch's; a dataset shard?)"),
                         (flat, "not a readable checkpoint (a zip archive, but not PyTorch's; a dataset shard?)")):
        assert main(["export", str(path), "--format", "onnx", "--out", str(tmp_path / "m.onnx")]) == 2
        assert one_line_error() == f"frontiernet export: error: {path}: {reason}"


def test_bad_model_files_are_refused_by_name(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_model(tmp_path / "nope.safetensors")
    corrupt = tmp_path / "corrupt.safetensors"
    corrupt.write_bytes(b"\x00" * 100)
    with pytest.raises(InputError, match="corrupt.safetensors: not a readable"):
        load_model(corrupt)
    text = tmp_path / "notes.ckpt"
    text.write_text("hello\n")  # the weights-only unpickler failed on it with a bare KeyError
    with pytest.raises(InputError, match="notes.ckpt: not a readable checkpoint"):
        load_model(text)
    damaged = tmp_path / "damaged.ckpt"  # a zip archive as torch.save writes it, its pickle garbled
    torch.save({"state_dict": {"w": torch.zeros(2)}}, tmp_path / "whole.ckpt")
    with zipfile.ZipFile(tmp_path / "whole.ckpt") as whole, zipfile.ZipFile(damaged, "w") as out:
        for name in whole.namelist():
            out.writestr(name, b"hello world" if name.endswith("data.pkl") else whole.read(name))
    with pytest.raises(InputError, match="damaged.ckpt: not a readable checkpoint"):
        load_model(damaged)
    # weights of one architecture under the config of another
    from safetensors.torch import save_file
    wrong = tmp_path / "wrong.safetensors"
    save_model(wrong, small_net("rgb"), MODEL_CONF)
    from safetensors import safe_open
    with safe_open(str(wrong), "pt") as handle:
        meta = handle.metadata()
        tensors = {k: handle.get_tensor(k) for k in handle.keys()}
    meta["frontiernet_model"] = meta["frontiernet_model"].replace('"inputs": "rgb"', '"inputs": "rgbd"')
    save_file(tensors, str(wrong), metadata=meta)
    with pytest.raises(InputError, match="do not fit a resnet18/rgbd"):
        load_model(wrong)
    bare = tmp_path / "bare.safetensors"
    save_file({"w": torch.zeros(2)}, str(bare))
    with pytest.raises(InputError, match="not a frontiernet model"):
        load_model(bare)


class _Exploit:
    def __reduce__(self):
        return (os.system, (f"touch {os.environ['EXPLOIT_MARKER']}",))


def test_a_malicious_checkpoint_is_refused_and_runs_nothing(tmp_path, monkeypatch):
    marker = tmp_path / "pwned"
    monkeypatch.setenv("EXPLOIT_MARKER", str(marker))
    evil = tmp_path / "evil.ckpt"
    torch.save({"state_dict": {}, "hyper_parameters": {"model": {"network": {}}}, "payload": _Exploit()}, evil)
    with pytest.raises(InputError, match="evil.ckpt: refused"):
        load_model(evil)
    assert not marker.exists()
    plain = tmp_path / "plain.ckpt"
    with open(plain, "wb") as handle:
        pickle.dump(_Exploit(), handle)
    with pytest.raises(InputError, match="plain.ckpt"):
        load_model(plain)
    assert not marker.exists()


def test_input_checks_name_the_problem():
    rgb = np.zeros((32, 40, 3), np.uint8)
    depth = np.ones((32, 40), np.float32)
    assert check_images(rgb, depth, "rgbd") == (32, 40)
    with pytest.raises(InputError, match="must be \\(H, W, 3\\)"):
        check_images(np.zeros((32, 40), np.uint8), depth, "rgbd")
    with pytest.raises(InputError, match="depth map is 20 x 32 but the RGB image is 40 x 32"):
        check_images(rgb, np.ones((32, 20), np.float32), "rgbd")
    nan = depth.copy()
    nan[3, 4] = np.nan
    with pytest.raises(InputError, match="1 NaN pixels"):
        check_images(rgb, nan, "rgbd")
    with pytest.raises(InputError, match="no depth map"):
        check_images(rgb, None, "rgbd")
    assert check_images(None, depth, "depth") == (32, 40)


def test_depth_beyond_the_range_reads_as_invalid():
    """The paper's convention: depth beyond the sensor's 3.5 m is invalid (0), as the simulated
    sensor's beyond-range pixels the network learns from, not a wall at the range limit."""
    from frontiernet.model import normalise_images

    depth = torch.tensor([[[0.0, 1.75, 3.5, 3.5000002, 3.6, 20.0]]])  # 3.5000002: 3500 mm read back
    channel = normalise_images(None, depth, "depth", MODEL_CONF["input"])[0, 0, 0]
    assert torch.allclose(channel, torch.tensor([0.0, 0.5, 1.0, 1.0, 0.0, 0.0]))


def test_inference_normalisation_is_the_training_one_on_one_thread(monkeypatch):
    """Per-frame inputs are normalised on one torch thread (a busy machine's thread pool cost ~60x);
    the values are the training path's to the bit, and the caller's thread count is kept."""
    import frontiernet.model.predictor as predictor
    from frontiernet.model import normalise_batch, normalise_images

    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (2, 24, 32, 3), dtype=np.uint8)
    depth = (rng.random((2, 24, 32)) * 5).astype(np.float32)
    depth[0, 0, :6] = [0.0, 3.5, 3.5000002, np.nan, -1.0, np.inf]
    threads_seen = []

    def recording(*args):
        threads_seen.append(torch.get_num_threads())
        return normalise_images(*args)

    monkeypatch.setattr(predictor, "normalise_images", recording)
    previous = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        expected = normalise_images(torch.from_numpy(rgb).permute(0, 3, 1, 2).float() / 255.0,
                                    torch.from_numpy(depth), "rgbd", MODEL_CONF["input"]).numpy()
        got = normalise_batch(rgb, depth, "rgbd", MODEL_CONF["input"])
        assert torch.get_num_threads() == 2 and threads_seen == [1]
    finally:
        torch.set_num_threads(previous)
    assert got.dtype == np.float32 and got.shape == (2, 4, 24, 32)
    assert np.array_equal(got.view(np.uint32), expected.view(np.uint32))


def test_resize_and_crop_keeps_projections():
    """A 3D point's marker in the image is where the adjusted intrinsics project the point."""
    K = np.array([[525.0, 0, 319.5], [0, 525.0, 239.5], [0, 0, 1]])
    point = np.array([0.4, -0.2, 2.0])
    u, v = (K @ point)[:2] / point[2]
    rgb = np.zeros((480, 640, 3), np.uint8)
    rgb[int(round(v)) - 6:int(round(v)) + 7, int(round(u)) - 6:int(round(u)) + 7] = 255
    small, _, K2 = resize_and_crop(rgb, None, K, 320)
    assert small.shape == (320, 320, 3)
    rows, cols = np.nonzero(small[..., 0] > 127)
    u2, v2 = (K2 @ point)[:2] / point[2]
    assert abs(cols.mean() - u2) < 0.5 and abs(rows.mean() - v2) < 0.5


def test_predictor_runs_each_input_kind(tmp_path):
    rgb = np.random.default_rng(0).integers(0, 255, (48, 64, 3), dtype=np.uint8)
    depth = np.full((48, 64), 2.0, np.float32)
    for inputs in ("rgbd", "rgb", "depth"):
        path = save_model(tmp_path / f"{inputs}.safetensors", small_net(inputs), MODEL_CONF)
        distance, logits = Predictor(path, threads=1).predict(rgb, depth)
        assert distance.shape == (48, 64) and distance.dtype == np.float32
        assert logits.shape == (11, 48, 64)
        assert (distance > 0).all() and (distance <= MODEL_CONF["labels"]["truncation_px"] + 1e-5).all()


def test_a_pad_multiple_the_encoder_cannot_take_is_refused():
    # pad_multiple=16 built a network that crashed in the decoder on a 336 px input (issue 55)
    with pytest.raises(InputError, match="network.pad_multiple must be a positive multiple of 32 .*got 16"):
        NetworkConfig(pad_multiple=16)
    assert NetworkConfig(pad_multiple=64).pad_multiple == 64

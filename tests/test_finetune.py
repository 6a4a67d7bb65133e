"""Fine-tuning with fewer inputs and frozen layers: a model file that stores only its own weights and shares
the rest with its base (the shipped RGB model's form), read back whole, refused when its base is gone or
holds other weights; `frontiernet train init_inputs=rgb freeze=[...]` end to end, resume included."""

from __future__ import annotations

import json
import shutil

import pytest
import torch
from safetensors import safe_open

from conftest import REPO_ROOT
from frontiernet.cli.main import main
from frontiernet.errors import InputError
from frontiernet.model import FrontierNet, NetworkConfig, default_model_path, load_model, save_model
from frontiernet.model.files import BASE_KEY, SharedBase
from train.finetune import with_inputs

MODEL_CONF = {"input": {"rgb_mean": [0.5] * 3, "rgb_std": [0.25] * 3, "max_depth_m": 3.5},
              "labels": {"truncation_px": 8}, "inference": {}}
SHARED = ("layers.2", "layers.3")


def small_net(inputs: str = "rgbd", seed: int = 0) -> FrontierNet:
    torch.manual_seed(seed)
    return FrontierNet(NetworkConfig.from_dict({"encoder": "mobilenet_v3_small", "inputs": inputs,
                                                "decoder_channels": [16, 16, 8, 8, 8], "head_channels": 8}))


def test_a_file_on_a_base_stores_its_own_weights_and_loads_whole(tmp_path):
    base_net = small_net()
    base = save_model(tmp_path / "base.safetensors", base_net, MODEL_CONF)
    tuned = with_inputs(base_net, "rgb")
    with torch.no_grad():  # "training": everything but the shared stages moves
        for name, value in tuned.state_dict().items():
            if not SharedBase(base, SHARED).shares(name) and value.is_floating_point():
                value.add_(0.01)
    path = save_model(tmp_path / "rgb.safetensors", tuned, MODEL_CONF, base=SharedBase(base, SHARED))
    with safe_open(str(path), framework="pt") as handle:
        stored, record = set(handle.keys()), json.loads(handle.metadata()[BASE_KEY])
    assert not any(SharedBase(base, SHARED).shares(name) for name in stored) and stored
    assert record["file"] == "base.safetensors" and record["prefixes"] == list(SHARED)
    assert path.stat().st_size < 0.8 * base.stat().st_size
    loaded, conf = load_model(path)
    assert conf["network"]["inputs"] == "rgb"
    for name, value in tuned.state_dict().items():
        assert torch.equal(loaded.state_dict()[name], value), name
    # moved away from its base (and the base is no shipped file): one line naming both
    alone = tmp_path / "elsewhere"
    alone.mkdir()
    shutil.copy(path, alone / path.name)
    with pytest.raises(InputError, match="shares layers.2, layers.3 with base.safetensors, which is neither beside"):
        load_model(alone / path.name)
    # a base overwritten with other weights is not taken for the one it was tuned from
    save_model(base, small_net(seed=1), MODEL_CONF)
    with pytest.raises(InputError, match="holds other weights"):
        load_model(path)


def test_a_model_whose_shared_layers_moved_cannot_name_the_base(tmp_path):
    base_net = small_net()
    base = save_model(tmp_path / "base.safetensors", base_net, MODEL_CONF)
    with torch.no_grad():
        next(p for n, p in base_net.named_parameters() if n.startswith("layers.3")).add_(1.0)
    with pytest.raises(ValueError, match="layers.3"):
        save_model(tmp_path / "x.safetensors", base_net, MODEL_CONF, base=SharedBase(base, SHARED))


def test_fewer_inputs_keep_the_first_convolutions_filters_of_those_channels():
    rgbd = small_net()
    rgb, depth = with_inputs(rgbd, "rgb"), with_inputs(rgbd, "depth")
    first = next(n for n, v in rgbd.state_dict().items() if v.ndim == 4)
    assert torch.equal(rgb.state_dict()[first], rgbd.state_dict()[first][:, :3])
    assert torch.equal(depth.state_dict()[first], rgbd.state_dict()[first][:, 3:])
    image = torch.rand(1, 4, 64, 64)
    image[:, 3] = 0  # a depth channel of zeros adds nothing through the first convolution: same output
    for out_rgbd, out_rgb in zip(rgbd.eval()(image), rgb.eval()(image[:, :3])):
        assert torch.allclose(out_rgbd, out_rgb, atol=1e-5)
    with pytest.raises(InputError, match="init_inputs: rgbd cannot start from a rgb model"):
        with_inputs(rgb, "rgbd")


@pytest.mark.slow
def test_train_an_rgb_model_on_the_shipped_rgbd_one_with_frozen_stages(tiny_dataset, tmp_path, one_line_error, capsys):
    args = ["train", "--config", str(REPO_ROOT / "configs" / "train_tiny.yaml"), "--no-progress",
            f"data.path={tiny_dataset}", f"out={tmp_path}", "name=rgb", "trainer.max_epochs=1",
            "init_weights=default", "init_inputs=rgb", "freeze=[layers.2,layers.3]"]
    assert main(args) == 0
    path = tmp_path / "rgb" / "model.safetensors"
    model, conf = load_model(path)
    shipped, _ = load_model(default_model_path())
    assert conf["network"]["inputs"] == "rgb" and conf["info"]["freeze"] == list(SHARED)
    assert path.stat().st_size < 0.35 * default_model_path().stat().st_size  # 2 M of 12.5 M weights, float32
    own, base = model.state_dict(), shipped.state_dict()
    assert all(torch.equal(own[n], base[n]) for n in own if n.startswith(SHARED))  # BatchNorm statistics too
    decoder = next(n for n in own if n.startswith("decoder") and own[n].is_floating_point())
    assert not torch.equal(own[decoder], base[decoder])  # the decoder trained
    # the float16 export (the shipped form) still shares the stages: a sixth of the shipped file
    half = tmp_path / "rgb_half.safetensors"
    assert main(["export", str(path), "--format", "safetensors", "--half", "--out", str(half)]) == 0
    assert half.stat().st_size < 0.2 * default_model_path().stat().st_size
    exported = load_model(half)[0].state_dict()
    assert all(torch.allclose(exported[n], own[n], atol=1e-2, rtol=1e-2) for n in own if own[n].is_floating_point())
    # resumed without the fine-tuning keys: the checkpoint's hold, the file still shares the same stages
    assert main(args[:-3] + ["trainer.max_epochs=2", "--resume"]) == 0
    resumed, conf = load_model(path)
    assert conf["network"]["inputs"] == "rgb" and conf["info"]["steps"] > 0
    assert all(torch.equal(resumed.state_dict()[n], base[n]) for n in own if n.startswith(SHARED))
    # freeze needs a model file to share with; a prefix must name parameters
    capsys.readouterr()
    assert main(args[:-3] + ["name=b", "freeze=[layers.3]"]) == 2
    assert "freeze: keeps layers at init_weights's values" in one_line_error()
    assert main(args[:-1] + ["name=c", "freeze=[layer9]"]) == 2
    assert "freeze: layer9 names no parameter" in one_line_error()
    assert main(args[:-1] + ["name=e", "freeze=['']"]) == 2
    assert "freeze: an empty prefix would name every parameter" in one_line_error()
    assert main(args[:-1] + ["name=f", "model.network.inputs=depth"]) == 2  # asked for, but init_inputs says rgb
    assert "model.network.inputs: depth, but the run starts from init_weights's rgb" in one_line_error()
    assert main(args[:-3] + ["name=d", "init_inputs=rgb"]) == 2
    assert "init_inputs: rgb starts a model from init_weights, which is not set" in one_line_error()
    assert not any((tmp_path / name).exists() for name in "bcdef")

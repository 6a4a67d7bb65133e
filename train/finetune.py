"""Fine-tuning: a run's starting weights (``init_weights``), a model of fewer inputs started from a model
of more (``init_inputs``: the shipped RGB model from the RGB + depth one), and the layers kept at the
starting values (``freeze``), which the written model file then shares with its base instead of storing."""

from __future__ import annotations

import logging
from pathlib import Path

import torch
from omegaconf import OmegaConf

from frontiernet.errors import InputError
from frontiernet.model import FrontierNet, NetworkConfig, load_model
from frontiernet.model.files import SharedBase, init_weights_file

log = logging.getLogger(__name__)

CHANNELS = {"rgbd": ("r", "g", "b", "d"), "rgb": ("r", "g", "b"), "depth": ("d",)}
"""The network input's channels of each input kind, in order (``normalise_images``: RGB, then depth)."""


def init_file(conf) -> Path | None:
    """The ``init_weights`` file (``default``: the shipped RGB + depth model), None when unset."""
    source = conf.get("init_weights")
    if not source:
        return None
    return init_weights_file(source)


def initial_weights(conf) -> tuple[FrontierNet | None, dict]:
    """The model of ``conf.init_weights`` (its input kind changed to ``conf.init_inputs`` when set) and its
    file's ``labels`` ((None, {}) when unset); its network config replaces ``conf.model.network`` in place, so
    the run trains (and records) that architecture."""
    path = init_file(conf)
    if path is None:
        if conf.get("init_inputs"):
            raise InputError(f"init_inputs: {conf.init_inputs} starts a model from init_weights, which is not set")
        return None, {}
    model, file_conf = load_model(path)
    inputs = conf.get("init_inputs") or model.config.inputs
    if inputs != model.config.inputs:
        model = with_inputs(model, inputs)
    _check_network_asked(conf, model)
    conf.model.network = OmegaConf.create({**model.config.to_dict(), "pretrained": None})
    log.info("starting from the weights of %s (%s/%s)", conf.init_weights, model.config.encoder, inputs)
    return model, dict(file_conf["labels"])


def _check_network_asked(conf, model: FrontierNet) -> None:
    """InputError naming the first ``model.network`` key the config sets away from the shipped default to a
    value the `model` started from does not have (the started model's network replaces the config's, so
    such a setting would be dropped without a word)."""
    from frontiernet.config import load_config

    default = OmegaConf.to_container(load_config("model").network, resolve=True)
    asked = OmegaConf.to_container(conf.model.network, resolve=True)
    started = model.config.to_dict()
    for key, value in asked.items():
        if key in started and value != default.get(key) and _plain(value) != _plain(started[key]):
            hint = (f"give init_inputs={value} (the started network's first layer then takes {value})"
                    if key == "inputs" else f"leave model.network.{key} out")  # (was the bare key name)
            raise InputError(f"model.network.{key}: {value}, but the run starts from init_weights's "
                             f"{_plain(started[key])} (its network replaces model.network): {hint}")


def _plain(value):
    return list(value) if isinstance(value, (list, tuple)) else value


def with_inputs(model: FrontierNet, inputs: str) -> FrontierNet:
    """A copy of `model` that takes input kind `inputs` (a subset of its own channels): the first convolution
    keeps the filters of the channels it still gets; every other weight is the same. InputError when
    `inputs` has a channel `model` does not take."""
    own = CHANNELS[model.config.inputs]
    if inputs not in CHANNELS or not set(CHANNELS[inputs]) <= set(own):
        raise InputError(f"init_inputs: {inputs} cannot start from a {model.config.inputs} model (its channels "
                         f"must be among the model's: {', '.join(k for k in CHANNELS if set(CHANNELS[k]) <= set(own))})")
    keep = [own.index(channel) for channel in CHANNELS[inputs]]
    fresh = FrontierNet(NetworkConfig.from_dict({**model.config.to_dict(), "inputs": inputs}))
    target = fresh.state_dict()
    state = {}
    for name, value in model.state_dict().items():
        if target[name].shape != value.shape:  # the first convolution, the only one whose input is the image
            value = value[:, keep].clone()
        state[name] = value
    fresh.load_state_dict(state)
    return fresh


def shared_base(conf, network: FrontierNet | None = None) -> SharedBase | None:
    """The base the run's model file shares its frozen layers with (``freeze`` over ``init_weights``), None
    without ``freeze``. InputError naming the key: ``freeze`` without an ``init_weights`` model file, or a
    prefix that names no parameter of `network` (when given)."""
    prefixes = tuple(str(p) for p in (conf.get("freeze") or ()))
    if not prefixes:
        return None
    path = init_file(conf)
    if path is None or path.suffix != ".safetensors":
        raise InputError(f"freeze: keeps layers at init_weights's values, which must be a model file (.safetensors; "
                         f"export a checkpoint first), got init_weights={conf.get('init_weights')}")
    if any(not prefix.strip(".") for prefix in prefixes):
        raise InputError(f"freeze: an empty prefix would name every parameter, got {list(prefixes)}")
    base = SharedBase(path, prefixes)
    if network is not None:
        names = [name for name, _ in network.named_parameters()]
        for prefix in prefixes:
            if not any(SharedBase(path, (prefix,)).shares(name) for name in names):
                raise InputError(f"freeze: {prefix} names no parameter of the {network.config.encoder} network "
                                 f"(e.g. stem, layers.0 .. layers.3, decoder)")
        if all(base.shares(name) for name in names):
            raise InputError(f"freeze: {', '.join(prefixes)} name every parameter of the network: nothing would train")
    return base


def freeze(net: FrontierNet, base: SharedBase | None) -> list[torch.nn.Module]:
    """Stop the gradients of `net`'s parameters under ``base.prefixes``; returns the frozen modules, which
    the training module keeps in eval mode (their BatchNorm statistics stay the base's)."""
    if base is None:
        return []
    for name, parameter in net.named_parameters():
        if base.shares(name):
            parameter.requires_grad_(False)
    return [module for name, module in net.named_modules() if name and base.shares(name)]


__all__ = ["CHANNELS", "freeze", "init_file", "initial_weights", "shared_base", "with_inputs"]

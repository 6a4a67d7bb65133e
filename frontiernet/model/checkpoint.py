"""Model files: save and load FrontierNet weights safely.

Two formats are read, neither of which can run code when opened:

- **model files** ``*.safetensors`` (what ``frontiernet export --format safetensors`` and the
  shipped weights are): the tensors, plus the model config (``network``, ``input``, ``labels``,
  ``inference`` sections of ``configs/model.yaml``) and a free-form ``info`` record as JSON in
  the safetensors metadata;
- **training checkpoints** ``*.ckpt`` written by ``frontiernet train`` (Lightning): read with
  ``torch.load(..., weights_only=True)``, so a pickle that carries code is refused.
"""

from __future__ import annotations

import json
import pickle
import zipfile
from importlib import resources
from pathlib import Path

import torch

from ..errors import InputError
from ..io import atomic_write
from .network import FrontierNet, NetworkConfig

CONFIG_KEY = "frontiernet_model"
INFO_KEY = "frontiernet_info"
DEFAULT_MODEL = "frontiernet_rgbd_resnet18.safetensors"
SHIPPED_MODELS = {"rgbd": DEFAULT_MODEL, "rgb": "frontiernet_rgb_mobilenet_v3_large.safetensors"}
"""The model file shipped for each input kind (``frontiernet/weights/``): RGB + depth (the default,
the paper's) and RGB only (Table II's row; ``predict --image`` without ``--depth``). The RGB model
has the MobileNetV3-Large encoder (3.5 M parameters, 7 MB in float16): a second ResNet-18 file
(25 MB) would take the tracked tree past what travels to a GPU node with the wheels it needs."""


def shipped_model_path(inputs: str = "rgbd") -> Path:
    """The shipped model file for input kind `inputs` (``rgbd`` | ``rgb``); InputError when that
    model is not shipped (yet): say what to give instead."""
    if inputs not in SHIPPED_MODELS:
        raise InputError(f"no model is shipped for {inputs!r} input; shipped: {', '.join(SHIPPED_MODELS)}")
    path = Path(str(resources.files("frontiernet").joinpath("weights", SHIPPED_MODELS[inputs])))
    if not path.is_file():
        given = "an RGB image alone" if inputs == "rgb" else f"{inputs} input"
        raise InputError(f"{path.name}: no shipped model takes {given} in this installation "
                         f"(frontiernet/weights/README.md); give --depth for the RGB + depth model, or --model FILE")
    return path


def default_model_path() -> Path:
    """The default shipped model file, RGB + depth (``frontiernet/weights/``, see its model card)."""
    return Path(str(resources.files("frontiernet").joinpath("weights", DEFAULT_MODEL)))


def save_model(path: str | Path, model: FrontierNet, model_conf: dict, info: dict | None = None,
               half: bool = False) -> Path:
    """Write `model` as a self-describing safetensors file, atomically.

    Args:
        model_conf: plain dict with the ``input``, ``labels`` and ``inference`` sections
            (``network`` is taken from the model itself).
        info: JSON-serialisable record (training data, epochs, metrics) kept in the file.
        half: store float tensors as float16 (half the size; loading casts back to float32).
    """
    from safetensors.torch import save

    from omegaconf import OmegaConf

    conf = {key: OmegaConf.to_container(OmegaConf.create(dict(model_conf[key])), resolve=True)
            for key in ("input", "labels", "inference")}
    conf["network"] = model.config.to_dict()
    tensors = {}
    for name, value in model.state_dict().items():
        value = value.detach().cpu()
        if half and value.is_floating_point():
            value = value.half()
        tensors[name] = value.contiguous()
    metadata = {CONFIG_KEY: json.dumps(conf), INFO_KEY: json.dumps(info or {})}
    payload = save(tensors, metadata=metadata)
    return atomic_write(path, lambda temporary: temporary.write_bytes(payload))


def load_model(path: str | Path | None = None) -> tuple[FrontierNet, dict]:
    """Load a model file or training checkpoint (None: the shipped model).

    Returns:
        (model in eval mode on the CPU, float32; its config dict with ``network``, ``input``,
        ``labels``, ``inference`` and ``info``).
    Raises:
        InputError naming the file: missing, corrupt, not a FrontierNet file, or weights that
        do not fit the architecture the file declares.
    """
    path = default_model_path() if path is None else Path(path)
    if not path.is_file():
        raise InputError(f"{path}: model file not found")
    if path.suffix == ".safetensors":
        state, conf = _read_safetensors(path)
    else:
        state, conf = _read_checkpoint(path)
    try:
        network = NetworkConfig.from_dict(conf["network"])
    except InputError as error:
        raise InputError(f"{path}: {error}") from None
    model = FrontierNet(network)
    state = {name: value.float() if value.is_floating_point() else value for name, value in state.items()}
    own = model.state_dict()
    missing = sorted(set(own) - set(state))
    unexpected = sorted(set(state) - set(own))
    wrong = sorted(n for n in set(own) & set(state) if own[n].shape != state[n].shape)
    if missing or unexpected or wrong:
        first = (missing or unexpected or wrong)[0]
        raise InputError(f"{path}: weights do not fit a {network.encoder}/{network.inputs} FrontierNet "
                         f"({len(missing)} missing, {len(unexpected)} unexpected, {len(wrong)} of another "
                         f"shape; first: {first})")
    model.load_state_dict(state)
    model.eval()
    return model, conf


def _read_safetensors(path: Path) -> tuple[dict, dict]:
    from safetensors import SafetensorError, safe_open

    try:
        with safe_open(str(path), framework="pt") as handle:
            metadata = handle.metadata() or {}
            state = {name: handle.get_tensor(name) for name in handle.keys()}
    except (SafetensorError, OSError, ValueError) as error:
        raise InputError(f"{path}: not a readable safetensors file ({error})") from None
    if CONFIG_KEY not in metadata:
        raise InputError(f"{path}: safetensors file without a FrontierNet config (not a frontiernet model)")
    try:
        conf = json.loads(metadata[CONFIG_KEY])
        conf["info"] = json.loads(metadata.get(INFO_KEY, "{}"))
    except json.JSONDecodeError:
        raise InputError(f"{path}: the FrontierNet config in the file is not valid JSON") from None
    return state, conf


def _read_checkpoint(path: Path) -> tuple[dict, dict]:
    """Weights and model config of a Lightning checkpoint written by ``frontiernet train`` (a
    PyTorch zip archive; anything else, a bare pickle included, is refused unopened)."""
    if not zipfile.is_zipfile(path):
        raise InputError(f"{path}: not a readable checkpoint (not a PyTorch zip archive, the format "
                         "frontiernet train writes)")
    try:
        checkpoint = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as error:
        raise InputError(f"{path}: refused: the checkpoint holds objects other than weights and plain "
                         f"data (opening it could run code): {str(error).splitlines()[0][:160]}") from None
    except Exception as error:  # a damaged archive: the unpickler fails with KeyError, IndexError, ...
        raise InputError(f"{path}: not a readable checkpoint ({error.__class__.__name__}: "
                         f"{str(error).splitlines()[0][:120] if str(error) else 'truncated?'})") from None
    if not isinstance(checkpoint, dict) or "state_dict" not in checkpoint:
        raise InputError(f"{path}: not a frontiernet training checkpoint (no state_dict)")
    model_conf = (checkpoint.get("hyper_parameters") or {}).get("model")
    if not isinstance(model_conf, dict) or "network" not in model_conf:
        raise InputError(f"{path}: checkpoint has no FrontierNet model config (not written by frontiernet train)")
    prefix = "net."
    state = {name[len(prefix):]: value for name, value in checkpoint["state_dict"].items()
             if name.startswith(prefix)}
    conf = {key: model_conf[key] for key in ("network", "input", "labels", "inference")}
    train_conf = (checkpoint.get("hyper_parameters") or {}).get("train") or {}
    conf["info"] = {"checkpoint": path.name, "epoch": checkpoint.get("epoch"),
                    "steps": checkpoint.get("global_step"), "val_scenes": train_conf.get("val_scenes", [])}
    return state, conf

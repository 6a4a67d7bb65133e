"""Model files: which hold torch weights (the shipped ``.safetensors`` and training ``.ckpt`` files,
which the network loads, against exports: ``.onnx``, TorchScript, which only a runtime runs), and how
they are read and written (:func:`read_model_file`, :func:`save_model`).

A model file may share tensors with another model file, its *base* (:class:`SharedBase`): a model
fine-tuned with some layers kept at the base's values (``frontiernet train`` with ``freeze``) stores
only its own tensors, and names the base with a digest of the shared ones. The shipped RGB-only
model is such a file on the shipped RGB + depth model (``frontiernet/weights/``).
"""

from __future__ import annotations

import hashlib
import json
import pickle
import zipfile
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import torch

from ..errors import InputError
from ..io import write_bytes

RUNTIME_GROUP = "frontiernet.runtimes"
"""The entry point group of the runtimes of exported model formats (``deploy``: ``onnx``, ``pt``, ...;
the registry is :data:`frontiernet.model.predictor.RUNTIMES`, torch files built in)."""

CONFIG_KEY = "frontiernet_model"
"""safetensors metadata: the model config (``network``, ``input``, ``labels``, ``inference``) as JSON."""
INFO_KEY = "frontiernet_info"
"""safetensors metadata: a free-form JSON record (training data, steps, metrics)."""
DEFAULT_MODEL = "frontiernet_rgbd_resnet18.safetensors"
"""The default shipped model file (RGB + depth; ``init_weights: default`` of training)."""
BASE_KEY = "frontiernet_base"
"""safetensors metadata of a file that shares tensors with a base file: JSON ``{"file": the base's file
name, "prefixes": the shared tensor-name prefixes, "digest": sha256 of the shared tensors as the base
stores them}`` (:func:`tensors_digest`)."""


@dataclass(frozen=True)
class SharedBase:
    """A model file whose tensors named under `prefixes` (e.g. ``layers.2``: that layer's weights and
    BatchNorm statistics) a model keeps unchanged, so that its file need not store them."""

    path: Path
    prefixes: tuple[str, ...]

    def shares(self, name: str) -> bool:
        """Whether tensor `name` is one of the shared ones."""
        return any(name == p or name.startswith(p + ".") for p in self.prefixes)


def tensors_digest(tensors: dict) -> str:
    """sha256 (hex) of `tensors` (name -> tensor): names, dtypes, shapes and bytes, in name order."""
    digest = hashlib.sha256()
    for name in sorted(tensors):
        value = tensors[name].detach().cpu().contiguous()
        digest.update(f"{name}|{value.dtype}|{tuple(value.shape)}|".encode())
        digest.update(value.reshape(-1).view(torch.uint8).numpy().tobytes())
    return digest.hexdigest()


def is_export(path: str | Path) -> bool:
    """Whether model file `path` is an export (``.onnx``, TorchScript ``.pt``, ...: a format a runtime
    plugin of :data:`RUNTIME_GROUP` reads), which runs but holds no trainable torch weights."""
    from ..registry import Registry

    return Path(path).suffix.lower().lstrip(".") in Registry("model format", RUNTIME_GROUP).plugins()


def torch_model_file(path: str | Path) -> Path:
    """`path` as a Path if it is a file that may hold torch weights; InputError naming it when it is
    missing, a folder, empty, or an export (``.onnx``, TorchScript: it runs in ``predict`` and
    ``explore``, but holds no weights to load, evaluate or export again)."""
    from ..io import input_file

    path = input_file(path, "model file", empty_ok=False)
    if is_export(path):
        raise InputError(f"{path}: an exported model ({path.suffix}); this needs the model file (.safetensors) "
                         "or the training checkpoint (.ckpt) it was exported from")
    return path


def read_model_file(path: Path) -> tuple[dict, dict]:
    """(tensors as stored, name -> tensor; the config dict with ``network``, ``input``, ``labels``,
    ``inference`` and ``info``) of a model file (``.safetensors``, its base's shared tensors filled in)
    or a training checkpoint (``.ckpt``). InputError naming the file when it cannot be read as one, or
    when a weight is not finite (:func:`check_finite`)."""
    path = Path(path)
    if path.suffix != ".safetensors" and not _looks_like_safetensors(path):  # (a model file renamed .bin reads)
        state, conf = _read_checkpoint(path)
        check_model_config(conf, path)
        check_finite(state, path)
        return state, conf
    state, metadata = _read_safetensors(path)
    if CONFIG_KEY not in metadata:
        raise InputError(f"{path}: safetensors file without a FrontierNet config (not a frontiernet model)")
    conf = embedded_model_config(metadata[CONFIG_KEY], path)
    try:
        conf["info"] = json.loads(metadata.get(INFO_KEY, "{}"))
        base = json.loads(metadata[BASE_KEY]) if BASE_KEY in metadata else None
    except json.JSONDecodeError:
        raise InputError(f"{path}: its {INFO_KEY} or {BASE_KEY} record is not valid JSON") from None
    if base is not None:
        shared, found = _base_tensors(path, base)
        state.update(shared)
        conf["base"] = {"file": found.name, "prefixes": list(base["prefixes"]), "path": str(found)}
    check_finite(state, path)
    return state, conf


MODEL_SECTIONS = ("network", "input", "labels", "inference")
"""The sections of a model config (``configs/model.yaml``'s) that every model file embeds."""


def embedded_model_config(text, path: Path) -> dict:
    """The model config that model file `path` embeds as JSON `text` (a safetensors file's :data:`CONFIG_KEY`
    metadata, an ONNX model's metadata, a TorchScript file's extra file), checked
    (:func:`check_model_config`); InputError naming the file when it is not valid JSON. The one reader of
    every model format's embedded config: ``predict``, ``explore``, ``export`` and ``evaluate`` alike."""
    try:
        conf = json.loads(text)
    except (json.JSONDecodeError, UnicodeDecodeError, TypeError, RecursionError):
        raise InputError(f"{path}: its embedded model config is not valid JSON (a damaged or hand-edited "
                         "model file: export it again)") from None
    check_model_config(conf, path)
    return conf


def check_model_config(conf, path: Path) -> None:
    """InputError naming model file `path` and the key when its embedded model config `conf` is not a JSON
    object of the :data:`MODEL_SECTIONS`, holds a value outside the range ``configs/ranges/model.yaml``
    declares (``labels.num_classes must be an integer in [2, 256], got -3``; a NaN truncation) or breaks a
    relation it declares."""
    from ..config import check_ranges

    if not isinstance(conf, dict):
        raise InputError(f"{path}: its embedded model config is not a JSON object of sections "
                         f"({', '.join(MODEL_SECTIONS)}); a damaged or hand-edited model file: export it again")
    missing = [name for name in MODEL_SECTIONS if not isinstance(conf.get(name), dict)]
    if missing:
        raise InputError(f"{path}: its embedded model config lacks the {missing[0]} section (or it is no JSON "
                         "object); a damaged or hand-edited model file: export it again")
    try:
        check_ranges(conf, {"": "model"})
    except InputError as error:
        raise InputError(f"{path}: its embedded model config is out of range: {error}") from None


def first_non_finite(tensors: dict) -> str | None:
    """The name of the first floating-point tensor of `tensors` (name -> tensor; other values skipped) that
    holds a NaN or an infinity, or None."""
    for name, value in tensors.items():
        if torch.is_tensor(value) and value.is_floating_point() and not bool(torch.isfinite(value).all()):
            return name
    return None


def check_finite(tensors: dict, path: Path) -> None:
    """Refuse, naming model file `path` and the first such tensor, weights (name -> tensor) that hold a NaN
    or an infinity (a run that diverged, a damaged file): the network would predict NaN, which reads as
    no frontier anywhere."""
    name = first_non_finite(tensors)
    if name is not None:
        raise InputError(f"{path}: weights are not all finite ({name} holds NaN or infinity); the model "
                         f"file is damaged or its training diverged")


def model_base(conf: dict) -> SharedBase | None:
    """The :class:`SharedBase` of a model read with config `conf` (:func:`read_model_file`'s ``base``: a
    model file on a base, or a checkpoint trained with ``freeze``), None for a model that shares nothing.
    Whatever writes such a model again (``export``, ``train``) passes it to :func:`save_model`."""
    record = conf.get("base")
    return SharedBase(Path(record["path"]), tuple(record["prefixes"])) if record else None


def _looks_like_safetensors(path: Path) -> bool:
    """Whether `path` starts as a safetensors file does: an 8-byte little-endian header length, then '{'."""
    try:
        with open(path, "rb") as handle:
            head = handle.read(9)
    except OSError:
        return False
    return len(head) == 9 and 0 < int.from_bytes(head[:8], "little") < 100_000_000 and head[8:9] == b"{"


def shipped_weights_folder() -> Path:
    """``frontiernet/weights/``, where the shipped model files are."""
    return Path(str(resources.files("frontiernet").joinpath("weights")))


def default_model_path() -> Path:
    """The default shipped model file, RGB + depth (``frontiernet/weights/``, see its model card)."""
    return shipped_weights_folder() / DEFAULT_MODEL


def init_weights_file(init) -> Path:
    """The file training's ``init_weights`` value `init` names: ``default`` is :func:`default_model_path`."""
    return default_model_path() if str(init) == "default" else Path(str(init))


def _base_tensors(path: Path, base: dict) -> tuple[dict, Path]:
    """(the shared tensors of model file `path`, the base file they were read from): the base (metadata
    `base`, :data:`BASE_KEY`) is looked for beside `path` and then among the shipped weights; InputError
    when none is there or the one found holds other tensors."""
    try:
        name, prefixes, digest = str(base["file"]), tuple(base["prefixes"]), str(base["digest"])
    except (KeyError, TypeError):
        raise InputError(f"{path}: its {BASE_KEY} record lacks file, prefixes or digest") from None
    shared = SharedBase(Path(name), prefixes)
    found = [candidate for candidate in (path.parent / name, shipped_weights_folder() / name) if candidate.is_file()]
    if not found:
        raise InputError(f"{path}: stores only its own weights and shares {', '.join(prefixes)} with {name}, "
                         f"which is neither beside it nor among the shipped weights ({shipped_weights_folder()})")
    for candidate in found:
        tensors, _ = _read_safetensors(candidate)
        tensors = {k: v for k, v in tensors.items() if shared.shares(k)}
        if tensors and tensors_digest(tensors) == digest:
            return tensors, candidate
    raise InputError(f"{path}: shares {', '.join(prefixes)} with {name}, but {found[0]} holds other weights "
                     f"(not the model it was fine-tuned from)")


def _read_safetensors(path: Path) -> tuple[dict, dict]:
    """(tensors, metadata) of a safetensors file; InputError naming it when it is not one."""
    from safetensors import SafetensorError, safe_open

    try:
        with safe_open(str(path), framework="pt") as handle:
            metadata = handle.metadata() or {}
            state = {name: handle.get_tensor(name) for name in handle.keys()}
    except (SafetensorError, OSError, ValueError) as error:
        raise InputError(f"{path}: not a readable safetensors file ({error})") from None
    return state, metadata


def load_checkpoint(path: str | Path, what: str = "readable checkpoint", *, mmap: bool = False):
    """What ``torch.load`` reads from the training checkpoint `path` (plain data only: no code runs); InputError
    ``<path>: not a <what> (...)`` saying why otherwise: not a PyTorch zip archive (truncated, or another kind of
    file: refused unopened, a bare pickle included), a zip archive but not PyTorch's, objects other than weights
    and plain data, or torch's error. The one reader of ``.ckpt`` files: models (:func:`read_model_file`), a
    training to resume (:mod:`train.resume`), map predictors (:mod:`frontiernet.mapprediction.predictor`)."""
    if not zipfile.is_zipfile(path):  # (torch: a RuntimeError, an EOFError or an OSError, none naming the cause)
        raise InputError(f"{path}: not a {what} (not a PyTorch zip archive, the format frontiernet train writes: "
                         "truncated, or another kind of file)")
    try:
        return torch.load(path, map_location="cpu", weights_only=True, mmap=mmap)
    except pickle.UnpicklingError as error:
        raise InputError(f"{path}: refused: the checkpoint holds objects other than weights and plain "
                         f"data (opening it could run code): {str(error).splitlines()[0][:160]}") from None
    except Exception as error:  # a damaged archive: the unpickler fails with KeyError, IndexError, ...
        text = str(error).splitlines()[0] if str(error) else ""
        if 'hasRecord("version")' in text or "inline_container" in text:  # (torch's zip reader's words, cut
            reason = "a zip archive, but not PyTorch's; a dataset shard?"  # mid-sentence, asked to report a bug)
        else:
            reason = f"{error.__class__.__name__}: {text[:120] if text else 'truncated?'}"
        raise InputError(f"{path}: not a {what} ({reason})") from None


def _read_checkpoint(path: Path) -> tuple[dict, dict]:
    """Weights and model config of a Lightning checkpoint written by ``frontiernet train``
    (:func:`load_checkpoint`)."""
    checkpoint = load_checkpoint(path)
    if not isinstance(checkpoint, dict) or "state_dict" not in checkpoint:
        raise InputError(f"{path}: not a frontiernet training checkpoint (no state_dict)")
    hyper = checkpoint.get("hyper_parameters") or {}
    model_conf = hyper.get("model")
    if not isinstance(model_conf, dict) or "network" not in model_conf:
        predictor = hyper.get("predictor")
        if isinstance(predictor, dict) and "kind" in predictor:  # (was "not written by frontiernet train": it was)
            raise InputError(f"{path}: a {predictor['kind']} map predictor's checkpoint (frontiernet train of "
                             f"configs/train_{predictor['kind']}.yaml), not a FrontierNet model's")
        raise InputError(f"{path}: checkpoint has no FrontierNet model config (not written by frontiernet train)")
    prefix = "net."
    state = {name[len(prefix):]: value for name, value in checkpoint["state_dict"].items()
             if name.startswith(prefix)}
    conf = {key: model_conf.get(key) for key in MODEL_SECTIONS}  # (checked by the caller: check_model_config)
    train_conf = (checkpoint.get("hyper_parameters") or {}).get("train") or {}
    conf["info"] = {"checkpoint": path.name, "epoch": checkpoint.get("epoch"),
                    "steps": checkpoint.get("global_step"), "val_scenes": train_conf.get("val_scenes", [])}
    if train_conf.get("freeze") and train_conf.get("init_weights"):  # trained with frozen layers: they stay shared
        base = init_weights_file(train_conf["init_weights"])
        conf["base"] = {"file": base.name, "prefixes": list(train_conf["freeze"]), "path": str(base)}
    return state, conf


def save_model(path: str | Path, model, model_conf: dict, info: dict | None = None, half: bool = False,
               base: SharedBase | None = None) -> Path:
    """Write `model` as a self-describing safetensors file, atomically.

    Args:
        model_conf: plain dict with the ``input``, ``labels`` and ``inference`` sections
            (``network`` is taken from the model itself).
        info: JSON-serialisable record (training data, epochs, metrics) kept in the file.
        half: store float tensors as float16 (half the size; loading casts back to float32).
        base: the model file whose tensors under ``base.prefixes`` the model kept (fine-tuned with
            them frozen): they are left out and the base is named (:data:`BASE_KEY`). ValueError when
            the model's values of them are not the base's (they were trained after all).
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
    if base is not None:
        stored, _ = _read_safetensors(Path(base.path))
        shared = {name: value for name, value in stored.items() if base.shares(name)}
        changed = [name for name in tensors if base.shares(name) and (
            name not in shared or not torch.equal(tensors[name].to(shared[name].dtype), shared[name]))]
        if changed or not shared:
            raise ValueError(f"the model's {changed[0] if changed else ', '.join(base.prefixes)} is not "
                             f"{base.path}'s: it cannot share it")
        tensors = {name: value for name, value in tensors.items() if not base.shares(name)}
        metadata[BASE_KEY] = json.dumps({"file": Path(base.path).name, "prefixes": list(base.prefixes),
                                         "digest": tensors_digest(shared)})
    payload = save(tensors, metadata=metadata)
    return write_bytes(path, payload)


__all__ = ["BASE_KEY", "CONFIG_KEY", "DEFAULT_MODEL", "INFO_KEY", "MODEL_SECTIONS", "RUNTIME_GROUP", "SharedBase",
           "check_finite", "check_model_config", "embedded_model_config", "is_export", "default_model_path",
           "init_weights_file", "load_checkpoint", "model_base", "read_model_file", "save_model", "shipped_weights_folder", "tensors_digest", "torch_model_file"]

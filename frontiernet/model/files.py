"""Which model files hold torch weights: the shipped ``.safetensors`` and training ``.ckpt`` files,
which the network loads, against exports (``.onnx``, TorchScript), which only a runtime runs."""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError

RUNTIME_GROUP = "frontiernet.runtimes"
"""The entry point group of the runtimes of exported model formats (``deploy``: ``onnx``, ``pt``, ...;
the registry is :data:`frontiernet.model.predictor.RUNTIMES`, torch files built in)."""


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


__all__ = ["RUNTIME_GROUP", "is_export", "torch_model_file"]

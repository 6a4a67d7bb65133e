"""``export(model, format, out)``: ONNX, TorchScript or a compact safetensors model file.

Every exported file carries the model config (input kind, normalisation, label encoding) so
``deploy.runtime.load_runtime`` needs nothing else: ONNX in its ``metadata_props`` under
``frontiernet_model``, TorchScript as the extra file ``frontiernet_model.json``. Exported
graphs take any batch size and any image size (dynamic axes; the network pads to a
multiple of 32 inside the graph).
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import torch

from frontiernet.errors import InputError, positive_number
from frontiernet.io import atomic_path, check_not_an_input, check_output_file
from frontiernet.model import default_model_path, load_model, save_model
from frontiernet.model.files import model_base
from frontiernet.model.network import CONFIG_KEY

FORMATS = ("onnx", "torchscript", "safetensors")
SUFFIXES = {"onnx": (".onnx",), "torchscript": (".pt", ".ts", ".torchscript"), "safetensors": (".safetensors",)}
"""The file names of each format that ``predict``, ``explore`` and ``load_model`` read (the runtimes of
``frontiernet.runtimes`` by suffix, torch weights as ``.safetensors``)."""
TORCHSCRIPT_EXTRA = "frontiernet_model.json"
OPSET = 18


def _config_json(conf: dict) -> str:
    return json.dumps({key: conf[key] for key in ("network", "input", "labels", "inference", "info") if key in conf})


def check_threshold(value: float, labels: dict) -> float:
    """`value` (``--frontier-threshold``, the l of F = [D < l]) as a float in (d_min, r), d_min and r the model's
    ``labels.min_distance_px`` and ``labels.truncation_px``: its distance D is a softplus-decoded ``r * exp(-y)``
    <= r, so l = r marks every pixel but those of D exactly r a frontier (100.00 % of an image), a larger l every
    pixel; and it was trained on distances clamped at d_min from below (``encode_distance``), so l <= d_min marks
    (almost) none (0.05 px: 1 pixel of an image, against 2,913 at the model's own). As
    ``labels.min_distance_px < labels.frontier_threshold_px < labels.truncation_px`` of configs/ranges/model.yaml.
    InputError naming the option otherwise."""
    r, low = float(labels["truncation_px"]), float(labels.get("min_distance_px") or 0.0)
    value = positive_number(value, "--frontier-threshold", "pixels")
    own = f"this model's own: {float(labels['frontier_threshold_px']):g} px"
    if value >= r:
        raise InputError(f"--frontier-threshold must be in ({low:g}, {r:g}) pixels, got {value:g}: the model's "
                         f"distance field is truncated at labels.truncation_px = {r:g} px, so a threshold there or above marks "
                         f"every pixel a frontier ({own})")
    if value <= low:
        raise InputError(f"--frontier-threshold must be in ({low:g}, {r:g}) pixels, got {value:g}: the model learned "
                         f"distances clamped at labels.min_distance_px = {low:g} px, so a threshold there or below "
                         f"marks (almost) no pixel a frontier ({own})")
    return value


def export(model_path: str | Path | None, fmt: str, out: str | Path, half: bool = False,
           frontier_threshold_px: float | None = None) -> Path:
    """Write the model (a model file or training checkpoint; None: the shipped one) as `fmt`.

    Args:
        fmt: ``onnx`` | ``torchscript`` | ``safetensors``.
        half: safetensors only: store float16 weights (half the size).
        frontier_threshold_px: the threshold l (pixels, D < l is a frontier) that runtimes of the
            written file use, e.g. the best-F1 l that ``frontiernet evaluate`` reports; None
            keeps the model's.
    Returns:
        The written path (written atomically: a failed export leaves nothing behind).
    """
    if fmt not in FORMATS:
        raise InputError(f"--format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    if half and fmt != "safetensors":
        raise InputError(f"--half writes float16 safetensors only; {fmt} files keep float32 weights (leave --half out)")
    out = check_output_file(out)  # a folder in the way fails now, not after the export
    source = Path(default_model_path() if model_path is None else model_path)
    check_not_an_input(out, [(source, "the model being exported")], "--out")  # --force: written over as it is read
    if out.suffix.lower() not in SUFFIXES[fmt]:  # models are read by their suffix: another would not load again
        raise InputError(f"--out {out.name}: {fmt} files are read back by their suffix; name it "
                         f"{' or '.join('*' + suffix for suffix in SUFFIXES[fmt])}")
    if not out.parent.is_dir():
        raise InputError(f"{out.parent}: output folder does not exist")
    if frontier_threshold_px is not None:  # (its bounds are the model's: check_threshold)
        positive_number(frontier_threshold_px, "--frontier-threshold", "pixels")
    model, conf = load_model(model_path)
    if frontier_threshold_px is not None:
        conf["labels"]["frontier_threshold_px"] = check_threshold(frontier_threshold_px, conf["labels"])
    if fmt == "safetensors":
        return save_model(out, model, conf, info=conf.get("info"), half=half, base=model_base(conf))
    channels = model.config.in_channels
    size = int(conf["inference"]["size"])
    example = torch.zeros(1, channels, size, size)
    if fmt == "torchscript":
        extra = {TORCHSCRIPT_EXTRA: _config_json(conf)}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FutureWarning)  # torch.jit is deprecated, still supported
            scripted = torch.jit.script(model)
            with atomic_path(out) as temporary:
                torch.jit.save(scripted, str(temporary), _extra_files=extra)
            return Path(out)
    with atomic_path(out) as temporary:
        _export_onnx(model, example, temporary, conf)
    return Path(out)


def _export_onnx(model, example: torch.Tensor, path: Path, conf: dict) -> None:
    import onnx

    dims = {0: torch.export.Dim("batch", min=1, max=256), 2: torch.export.Dim("height", min=8, max=8192),
            3: torch.export.Dim("width", min=8, max=8192)}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        program = torch.onnx.export(model, (example,), dynamo=True, input_names=["image"],
                                    output_names=["distance", "gain_logits"], dynamic_shapes=({**dims},),
                                    opset_version=OPSET, verbose=False)
    proto = program.model_proto
    entry = proto.metadata_props.add()
    entry.key, entry.value = CONFIG_KEY, _config_json(conf)
    onnx.save_model(proto, str(path))

"""``load_runtime(path)``: one ``predict(rgb, depth) -> (distance_field, gain_logits)`` for
every model format.

- ``.onnx``: onnxruntime (CPU, or CUDA when onnxruntime-gpu is installed);
- ``.pt`` / ``.ts`` TorchScript: ``torch.jit.load``;
- ``.safetensors`` model files and ``.ckpt`` checkpoints: :class:`frontiernet.model.Predictor`.

All share :class:`frontiernet.model.Runtime`'s input checks, normalisation and decoding, so
the three agree to float precision (``tests/test_deploy.py``).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import torch

from frontiernet.errors import InputError
from frontiernet.model import Runtime, open_runtime
from frontiernet.model.files import embedded_model_config
from frontiernet.model.network import CONFIG_KEY
from frontiernet.model.predictor import torch_threads

from .export import TORCHSCRIPT_EXTRA


class OnnxRuntime(Runtime):
    """An exported ONNX model run by onnxruntime (``threads``: intra-op threads; None = torch's
    intra-op thread count, so one setting holds for every runtime of the process, e.g. a
    benchmark worker's share of the cores)."""

    def __init__(self, path: str | Path, threads: int | None = None):
        import onnxruntime

        path = Path(path)
        options = onnxruntime.SessionOptions()
        options.intra_op_num_threads = int(threads or torch.get_num_threads())
        options.inter_op_num_threads = 1
        try:
            self.session = onnxruntime.InferenceSession(str(path), options,
                                                        providers=onnxruntime.get_available_providers())
        except Exception as error:  # noqa: BLE001  onnxruntime raises its own exception types
            raise InputError(f"{path}: not a loadable ONNX model ({str(error).splitlines()[0][:120]})") from None
        metadata = self.session.get_modelmeta().custom_metadata_map
        if CONFIG_KEY not in metadata:
            raise InputError(f"{path}: ONNX model without a FrontierNet config (export it with frontiernet export)")
        self.conf = embedded_model_config(metadata[CONFIG_KEY], path)  # the safetensors reader's checks

    def run(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        distance, logits = self.session.run(None, {"image": image})
        return distance, logits


class TorchScriptRuntime(Runtime):
    """An exported TorchScript model (``threads``: torch intra-op threads while predicting)."""

    def __init__(self, path: str | Path, threads: int | None = None):
        path = Path(path)
        extra = {TORCHSCRIPT_EXTRA: ""}
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", FutureWarning)  # torch.jit is deprecated, still supported
                self.module = torch.jit.load(str(path), map_location="cpu", _extra_files=extra)
        except Exception as error:  # noqa: BLE001  torch.jit raises RuntimeError and others
            raise InputError(f"{path}: not a loadable TorchScript model ({str(error).splitlines()[0][:120]})") from None
        if not extra[TORCHSCRIPT_EXTRA]:
            raise InputError(f"{path}: TorchScript model without a FrontierNet config (export it with "
                             f"frontiernet export)")
        self.conf = embedded_model_config(extra[TORCHSCRIPT_EXTRA], path)
        self.module.eval()
        self.threads = threads

    @torch.inference_mode()
    def run(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        with torch_threads(self.threads):
            distance, logits = self.module(torch.from_numpy(image))
        return distance.numpy(), logits.numpy()


load_runtime = open_runtime  # one dispatcher, in the library; the formats above register under
# the ``frontiernet.runtimes`` entry point group (pyproject.toml)

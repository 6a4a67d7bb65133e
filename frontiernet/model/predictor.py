"""Runtimes: ``predict(rgb, depth) -> (distance_field, gain_logits)`` for any model format, and
``predict_frame(rgb, depth, K)``: a camera frame resized to the working size, intrinsics adjusted.

:class:`Runtime` holds what every format shares (resizing, input checks and normalisation, output
decoding); :class:`Predictor` runs a torch model file or checkpoint. ``deploy.runtime`` adds
ONNX (onnxruntime) and TorchScript behind the same call.
"""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path

import numpy as np
import torch

from .checkpoint import load_model
from ..errors import InputError
from ..registry import Registry
from .inputs import decode_distance, invalid_to_zero, network_input, resize_and_crop


@contextmanager
def torch_threads(threads: int | None):
    """Run the block with `threads` torch intra-op threads (None: unchanged), then restore."""
    previous = torch.get_num_threads()
    if threads:
        torch.set_num_threads(int(threads))
    try:
        yield
    finally:
        if threads:
            torch.set_num_threads(previous)


class Runtime:
    """Base of the runtimes. Subclasses set ``conf`` (a model config dict with ``network``,
    ``input``, ``labels``, ``inference``) and implement :meth:`run`."""

    conf: dict

    @property
    def inputs(self) -> str:
        """Input kind of the model: rgbd, rgb or depth."""
        return self.conf["network"]["inputs"]

    @property
    def labels(self) -> dict:
        return self.conf["labels"]

    def run(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Raw network on a normalised (1, C, H, W) float32 input: (1, 1, H, W) y, (1, K, H, W) logits."""
        raise NotImplementedError

    def predict(self, rgb: np.ndarray | None, depth: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Run the network on one image.

        Args:
            rgb: (H, W, 3) uint8 RGB (ignored by depth-only models; may be None for them).
            depth: (H, W) float32 metres, 0 = invalid, no NaN (ignored by RGB-only models).
        Returns:
            distance_field: (H, W) float32 pixels in (0, r], distance to the nearest frontier pixel;
            gain_logits: (K, H, W) float32 gain-class logits.
        """
        if self.inputs == "depth":
            rgb = None
        elif self.inputs == "rgb":
            depth = None
        image = network_input(rgb, depth, self.inputs, self.conf["input"]).numpy()
        distance, logits = self.run(image)
        distance_px = decode_distance(np.asarray(distance, np.float32)[0, 0], self.labels)
        return distance_px, np.asarray(logits, np.float32)[0]

    def predict_frame(self, rgb: np.ndarray | None, depth: np.ndarray | None, K: np.ndarray | None = None, *,
                      size: int | None = None, crop: bool = True) -> tuple[dict, np.ndarray | None]:
        """The network on one camera frame at its working size: resize so the short side is `size`
        px and centre-crop to a square (the public demo's recipe), adjust the intrinsics, predict,
        decode.

        Args:
            rgb: (H, W, 3) uint8 RGB, or None (depth-only models).
            depth: (H, W) float32 metres, invalid as NaN, inf, 0 or negative (the network is given
                0 there), or None (RGB-only models). A model ignores an input it does not take.
            K: (3, 3) intrinsics of the frame (pixels), or None.
            size: working size (None: the model's ``inference.size``; 0: the frame's own size).
            crop: centre-crop to ``size x size``; False keeps the whole frame, its long side rounded to
                a multiple of the network's ``pad_multiple`` (see :func:`~.inputs.resize_and_crop`).
        Returns:
            outputs at the working size (h, w): ``rgb`` and ``depth`` as the network saw them
            (resized; depth keeps the caller's invalid marks; None stays None), ``distance_field``
            (h, w) float32 px, ``gain_logits`` (K, h, w) float32, ``gain_class`` (h, w) uint8 and
            ``frontier_mask`` (h, w) bool (``D < l``, l from the model's labels);
            and the (3, 3) float64 intrinsics at that size (None when `K` is None; `K` itself at size 0).
        Raises:
            InputError: RGB and depth of different sizes, or an input the model cannot take.
        """
        if rgb is not None and depth is not None and rgb.shape[:2] != depth.shape:
            raise InputError(f"depth map is {depth.shape[1]} x {depth.shape[0]} but the image is "
                             f"{rgb.shape[1]} x {rgb.shape[0]}; they must be the same size")
        size = self.conf["inference"]["size"] if size is None else size
        if size:
            multiple = 1 if crop else int(self.conf["network"]["pad_multiple"])
            rgb, depth, K = resize_and_crop(rgb, depth, K, int(size), crop, multiple)
        distance_px, logits = self.predict(rgb, None if depth is None else invalid_to_zero(depth))
        return {"rgb": rgb, "depth": depth, "distance_field": distance_px, "gain_logits": logits,
                "gain_class": logits.argmax(0).astype(np.uint8),
                "frontier_mask": distance_px < float(self.labels["frontier_threshold_px"])}, K


class Predictor(Runtime):
    """A torch model file (``.safetensors``) or training checkpoint (``.ckpt``).

    Args:
        model: the file (None: the shipped model).
        threads: torch intra-op threads while predicting (None: leave torch's setting).
        device: "cpu" or "cuda".
    """

    def __init__(self, model: str | Path | None = None, threads: int | None = None, device: str = "cpu"):
        self.model, self.conf = load_model(model)
        self.device = torch.device(device)
        # channels-last (NHWC) weights and inputs: the convolutions skip layout reorders (CPU, 1 thread:
        # 0.87x the time of NCHW at 320 px, 0.75x at 480 px, `frontiernet bench inference`); outputs
        # agree to ~1e-5
        self.model.to(self.device, memory_format=torch.channels_last)
        self.threads = threads

    @torch.inference_mode()
    def run(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        with torch_threads(self.threads):
            tensor = torch.from_numpy(image).to(self.device).contiguous(memory_format=torch.channels_last)
            distance, logits = self.model(tensor)
        return distance.float().cpu().numpy(), logits.float().cpu().numpy()


RUNTIMES = Registry("model format", "frontiernet.runtimes", {"safetensors": Predictor, "ckpt": Predictor})
"""Runtimes by model file suffix (without the dot): a Runtime class built as ``Class(path, threads)``.
Torch files are built in; other formats register under the entry point group
``frontiernet.runtimes`` (``deploy`` adds ONNX as ``onnx`` and TorchScript as ``pt``, ``ts``,
``torchscript``)."""


def open_runtime(path: str | Path | None = None, threads: int | None = None) -> Runtime:
    """The runtime for a model file, chosen by its suffix in :data:`RUNTIMES` (None: the shipped
    model, torch).

    Raises:
        InputError: a missing file or a format no installed runtime reads.
    """
    if path is None:
        return Predictor(None, threads=threads)
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: model file not found")
    suffix = path.suffix.lower().lstrip(".")
    return RUNTIMES.get(suffix, label=f"{path}: model format")(path, threads)

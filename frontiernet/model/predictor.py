"""From a camera frame to the network's outputs: the one prediction recipe every runtime shares.

:meth:`Runtime.predict_frame` is the recipe: the frame resized to the working size and centre-cropped
(:func:`resize_and_crop`, intrinsics adjusted), invalid depth made 0 (:func:`invalid_to_zero`), the
channels checked and normalised (:func:`network_input`), the network run (:meth:`Runtime.run`, one per
model format) and its distance head decoded (:func:`decode_distance`). :class:`Predictor` runs a torch
model file or checkpoint; ``deploy.runtime`` adds ONNX (onnxruntime) and TorchScript behind the same
call; :func:`open_runtime` picks the runtime by the file's suffix (:data:`RUNTIMES`). Training
normalises its batches and encodes its targets with the same functions (:func:`normalise_images`,
:func:`encode_distance`).

Input normalisation (``configs/model.yaml`` section ``input``):

- RGB: uint8 (H, W, 3) -> float in [0, 1] -> ``(x - mean) / std`` with ImageNet statistics;
- depth: float metres (H, W) -> ``depth / max_depth`` in (0, 1] where ``0 < depth <= max_depth``,
  else 0, which means invalid (the sensor convention of TUM, Redwood and most RGB-D drivers; the
  paper: depth beyond the 3.5 m range is invalid). NaN is refused: callers map their invalid
  pixels to 0 first (:func:`invalid_to_zero`).

Channel order is RGB then depth. Output decoding (``labels`` section): the distance head's
``y`` gives ``D = r * exp(-y)`` pixels, frontier pixels are ``D < l`` (docs/design.md section 4).
"""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path

import cv2
import numpy as np
import torch

from ..errors import InputError
from ..registry import Registry
from .files import RUNTIME_GROUP
from .network import load_model


RANGE_TOLERANCE_M = 1e-3
"""Depth up to this far past ``input.max_depth_m`` still counts as in range: datasets store depth in
whole millimetres, so a surface at 3.4996 m reads back as 3.500 m (3.5000002 in float32)."""


def invalid_to_zero(depth: np.ndarray) -> np.ndarray:
    """(H, W) float32 depth with NaN / inf / negative values replaced by 0 (invalid)."""
    depth = np.asarray(depth, np.float32)
    return np.where(np.isfinite(depth) & (depth > 0), depth, 0.0).astype(np.float32)


def beyond_range_invalid(depth: np.ndarray, max_depth_m: float) -> np.ndarray:
    """(H, W) float32 metres with depths beyond `max_depth_m` set to NaN (invalid).

    The network is trained on simulated depth, which has no return beyond the sensor range
    (3.5 m, ``input.max_depth_m``); real sensors and monocular models see further, so their
    far depths are made invalid the same way before the network sees them."""
    depth = np.asarray(depth, np.float32)
    with np.errstate(invalid="ignore"):
        return np.where(depth <= float(max_depth_m), depth, np.nan).astype(np.float32)


def fill_invalid_nearest(depth: np.ndarray) -> np.ndarray:
    """(H, W) float32 metres with every invalid pixel (NaN, <= 0) given the depth of the nearest
    valid pixel (scipy's Euclidean distance transform); all-invalid maps are returned as they are.

    Real sensors return nothing on glass, black or shiny surfaces, at the image border of a
    registered Kinect frame and too close; a network trained in simulation reads "no depth" as
    free space beyond the sensor range, so these holes become false frontiers unless filled."""
    from scipy.ndimage import distance_transform_edt

    depth = np.asarray(depth, np.float32)
    invalid = ~(np.isfinite(depth) & (depth > 0))
    if not invalid.any() or invalid.all():
        return depth.copy()
    _, (rows, cols) = distance_transform_edt(invalid, return_indices=True)
    return depth[rows, cols]


def check_images(rgb: np.ndarray | None, depth: np.ndarray | None, inputs: str) -> tuple[int, int]:
    """Validate what a model with input kind `inputs` (rgbd | rgb | depth) is given.

    Returns the image size (H, W). Raises :class:`InputError` with a one-line reason.
    """
    if inputs in ("rgbd", "rgb"):
        if rgb is None:
            raise InputError(f"this model takes {'RGB + depth' if inputs == 'rgbd' else 'RGB'} input; "
                             f"no RGB image was given")
        rgb = np.asarray(rgb)
        if rgb.ndim != 3 or rgb.shape[2] != 3:
            raise InputError(f"RGB image must be (H, W, 3), got shape {tuple(rgb.shape)}")
        if rgb.dtype != np.uint8:
            raise InputError(f"RGB image must be uint8, got {rgb.dtype}")
    if inputs in ("rgbd", "depth"):
        if depth is None:
            raise InputError(f"this model takes {'RGB + depth' if inputs == 'rgbd' else 'depth'} input; "
                             f"no depth map was given")
        depth = np.asarray(depth)
        if depth.ndim != 2:
            raise InputError(f"depth map must be (H, W), got shape {tuple(depth.shape)}")
        if not np.issubdtype(depth.dtype, np.floating):
            raise InputError(f"depth map must be float metres, got {depth.dtype} (convert units first)")
        if np.isnan(depth).any():
            raise InputError(f"depth map has {int(np.isnan(depth).sum())} NaN pixels; mark invalid pixels "
                             f"with 0 (frontiernet.model.invalid_to_zero)")
    if inputs == "rgbd" and rgb.shape[:2] != depth.shape:
        raise InputError(f"depth map is {depth.shape[1]} x {depth.shape[0]} but the RGB image is "
                         f"{rgb.shape[1]} x {rgb.shape[0]}; they must be the same size")
    size = rgb.shape[:2] if rgb is not None and inputs != "depth" else depth.shape
    if min(size) < 8:
        raise InputError(f"image of {size[1]} x {size[0]} pixels is too small for the network")
    return int(size[0]), int(size[1])


def network_input(rgb: np.ndarray | None, depth: np.ndarray | None, inputs: str, input_conf) -> torch.Tensor:
    """(1, C, H, W) float32 tensor of the normalised channels for input kind `inputs`.

    Args:
        rgb: (H, W, 3) uint8, or None for depth-only models.
        depth: (H, W) float metres, 0 = invalid, or None for RGB-only models.
        input_conf: the ``input`` section of ``configs/model.yaml``.
    """
    check_images(rgb, depth, inputs)
    return torch.from_numpy(normalise_batch(
        None if rgb is None else np.asarray(rgb)[None],
        None if depth is None else np.asarray(depth, np.float32)[None], inputs, input_conf))


def normalise_batch(rgb: np.ndarray | None, depth: np.ndarray | None, inputs: str, input_conf) -> np.ndarray:
    """(B, C, H, W) float32 from (B, H, W, 3) uint8 RGB and (B, H, W) float depth (unchecked).

    On one torch thread: these elementwise steps take ~1.5 ms for a 320 px frame on one core, and
    torch's thread pool, waiting on a core another process holds, took 95 ms (2 threads on the
    2-core development machine beside a benchmark). Elementwise results do not depend on the
    thread count."""
    with torch_threads(1):
        rgb01 = None if rgb is None else torch.from_numpy(np.ascontiguousarray(rgb)).permute(0, 3, 1, 2).float() / 255.0
        depth = None if depth is None else torch.from_numpy(np.asarray(depth, np.float32))
        return np.ascontiguousarray(normalise_images(rgb01, depth, inputs, input_conf).numpy())


def normalise_images(rgb: torch.Tensor | None, depth: torch.Tensor | None, inputs: str, input_conf) -> torch.Tensor:
    """(B, C, H, W) float32 network input, on the inputs' device (training normalises on the GPU).

    Args:
        rgb: (B, 3, H, W) float RGB in [0, 1] (ignored for depth-only models).
        depth: (B, H, W) float metres, 0 = invalid (ignored for RGB-only models).
        inputs: ``rgbd`` | ``rgb`` | ``depth``.
        input_conf: the ``input`` section of ``configs/model.yaml``: RGB ``(x - rgb_mean) / rgb_std``
            (ImageNet statistics), depth ``d / max_depth_m`` for ``0 < d <= max_depth_m`` and 0 (invalid)
            elsewhere. As the paper has it, depth beyond the sensor's range (3.5 m) is invalid: the
            simulated sensor the network learns from returns nothing there, so a depth that reaches
            past it (a monocular estimate, a real sensor, a prior scaled by the augmentation) reads
            as no return, not as a wall at the range limit.
    """
    channels = []
    if inputs in ("rgbd", "rgb"):
        mean = torch.tensor(input_conf["rgb_mean"], dtype=torch.float32, device=rgb.device)[:, None, None]
        std = torch.tensor(input_conf["rgb_std"], dtype=torch.float32, device=rgb.device)[:, None, None]
        channels.append((rgb.float() - mean) / std)
    if inputs in ("rgbd", "depth"):
        max_depth = float(input_conf["max_depth_m"])
        depth = depth.float()
        in_range = (depth > 0) & (depth <= max_depth + RANGE_TOLERANCE_M)  # a depth stored in millimetres
        channels.append(torch.where(in_range, depth.clamp(max=max_depth) / max_depth, 0.0)[:, None])  # may round up
    return torch.cat(channels, dim=1).contiguous()


def encode_distance(distance_px: torch.Tensor, labels_conf) -> torch.Tensor:
    """Normalised target ``-log(max(D, d_min) / r)`` (>= 0) from D in pixels (any shape)."""
    r = float(labels_conf["truncation_px"])
    clamped = distance_px.clamp(min=float(labels_conf["min_distance_px"]), max=r)
    return -torch.log(clamped / r)


def decode_distance(normalised, labels_conf):
    """D in pixels ``r * exp(-y)`` from the distance head's output y (tensor or array)."""
    r = float(labels_conf["truncation_px"])
    if isinstance(normalised, torch.Tensor):
        return r * torch.exp(-normalised)
    return (r * np.exp(-np.asarray(normalised, np.float32))).astype(np.float32)


MIN_INPUT_PX, MAX_INPUT_PX = 8, 2048
"""The network input sizes (pixels, the short side) a user may ask for (``--size``, ``data.image_size``,
``augment.crop_size``): the smallest the exports take, and 6.4 times the paper's 320 (a larger
one only runs out of memory)."""


def input_size(value, name: str) -> int:
    """`value` as a network input size in [:data:`MIN_INPUT_PX`, :data:`MAX_INPUT_PX`] pixels;
    InputError naming `name` (``--size``) otherwise."""
    from ..errors import whole_number

    return whole_number(value, name, MIN_INPUT_PX, MAX_INPUT_PX)


def resize_and_crop(rgb: np.ndarray | None, depth: np.ndarray | None, K: np.ndarray | None, size: int,
                    crop: bool = True, multiple: int = 1):
    """Resize so the short side is `size`, centre-crop to ``size x size`` (unless not `crop`:
    then the whole image is kept, its long side rounded to a multiple of `multiple` px, e.g. the
    network's padding multiple, so no padded border looks like a depth edge), adjust intrinsics.

    The public demo code's preprocessing (resize + centre crop to 320 x 320). RGB is resized
    with area averaging, depth with nearest neighbour (no invented depths across edges).

    Args:
        rgb: (H, W, 3) uint8 or None; depth: (H, W) float32 metres or None; K: (3, 3) or None.
    Returns:
        (rgb, depth, K) at ``size x size`` (without `crop`: the resized size; None stays None).
    """
    height, width = (rgb if rgb is not None else depth).shape[:2]
    new_w, new_h, left, top, crop_w, crop_h = working_geometry(height, width, size, crop, multiple)
    if rgb is not None:
        rgb = cv2.resize(np.ascontiguousarray(rgb), (new_w, new_h), interpolation=cv2.INTER_AREA)
        rgb = np.ascontiguousarray(rgb[top:top + crop_h, left:left + crop_w])
    if depth is not None:
        depth = cv2.resize(np.ascontiguousarray(depth, np.float32), (new_w, new_h), interpolation=cv2.INTER_NEAREST)
        depth = np.ascontiguousarray(depth[top:top + crop_h, left:left + crop_w])
    return rgb, depth, None if K is None else working_intrinsics(K, height, width, size, crop, multiple)


def working_geometry(height: int, width: int, size: int, crop: bool = True, multiple: int = 1) -> tuple[int, ...]:
    """(resized width, height, crop's left, top, cropped width, height) in pixels of an `height` x `width`
    image at network size `size` (:func:`resize_and_crop`)."""
    scale = size / min(height, width)
    new_w, new_h = max(size, round(width * scale)), max(size, round(height * scale))
    if not crop and multiple > 1:
        new_w, new_h = (max(multiple, int(round(side / multiple)) * multiple) for side in (new_w, new_h))
    left, top = ((new_w - size) // 2, (new_h - size) // 2) if crop else (0, 0)
    return (new_w, new_h, left, top, *((size, size) if crop else (new_w, new_h)))


def working_intrinsics(K: np.ndarray, height: int, width: int, size: int, crop: bool = True,
                       multiple: int = 1) -> np.ndarray:
    """(3, 3) float64 intrinsics `K` of an `height` x `width` image at network size `size`, resized and
    cropped as :func:`resize_and_crop` does it (pixel centres: pixel 0's centre moves to ``0.5 s - 0.5``)."""
    new_w, new_h, left, top, _, _ = working_geometry(height, width, size, crop, multiple)
    K = np.asarray(K, np.float64).copy()
    K[0, 0] *= new_w / width
    K[1, 1] *= new_h / height
    K[0, 2] = (K[0, 2] + 0.5) * new_w / width - 0.5 - left
    K[1, 2] = (K[1, 2] + 0.5) * new_h / height - 0.5 - top
    return K


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
                a multiple of the network's ``pad_multiple`` (see :func:`resize_and_crop`).
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


RUNTIMES = Registry("model format", RUNTIME_GROUP, {"safetensors": Predictor, "ckpt": Predictor})
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
    from ..io import input_file

    path = input_file(path, "model file", empty_ok=False)
    suffix = path.suffix.lower().lstrip(".")
    return RUNTIMES.get(suffix, label=f"{path}: model format")(path, threads)

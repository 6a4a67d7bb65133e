"""The one interface every depth source implements, and the input checks they share.

A depth source turns a camera frame into a metric depth map:

* ``rgb``: (H, W, 3) uint8 image.
* ``K``: (3, 3) float64 pinhole intrinsics, OpenCV convention (pixel centres at
  integer coordinates).
* ``gt_depth``: optional (H, W) float32 ground-truth z-depth in metres, NaN = invalid
  (non-finite or non-positive values are also read as invalid).
* output: (H, W) float32 z-depth along the optical axis in metres, NaN = invalid
  (never 0). Monocular models return dense maps.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np

from ..config import option_section
from ..errors import InputError
from ._conf import shipped_options


class DepthSource(ABC):
    """A depth source. Subclasses set :attr:`name` and those of the flags below that differ from
    their defaults.

    A source is built as ``Source(conf)``, `conf` its section of ``configs/depth.yaml`` as the run
    resolved it: every key of the shipped section (:meth:`options`), no other (:meth:`section`).
    """

    name: str = "depth"
    #: True when :meth:`estimate` needs ``gt_depth`` (simulation only).
    requires_ground_truth: bool = False
    #: True when ``gt_depth`` should reach past the depth sensor's range (every surface hit at any
    #: distance, NaN only where nothing is hit; the simulator's ``Frame.hit_depth``): a monocular
    #: model sees far surfaces too. False: the range-limited sensor depth (``Frame.depth``).
    sees_past_range: bool = False
    #: True when the depth smears foreground into background at discontinuities ("flying pixels":
    #: monocular networks, whose decoders upsample from a coarse grid): the explorer's map leaves
    #: out the pixels at depth edges (``map.depth_edge_rtol``). False: sharp edges (ground truth).
    flying_pixels: bool = False
    #: True when the output depends on the seed given to :meth:`reset` (emulated noise): runs
    #: that differ only in their seed differ.
    seeded: bool = False
    #: True when :meth:`estimate` reads the focal length of ``K`` (Metric3D's canonical camera
    #: sets its metric scale); False: ``K`` is only checked, and a command without the camera's
    #: intrinsics may hand it a nominal one (``frontiernet predict --depth depth_anything_v2``).
    uses_intrinsics: bool = False

    @classmethod
    def options(cls) -> tuple[str, ...]:
        """The keys of the source's section of the shipped ``configs/depth.yaml``, all of which its
        constructor takes."""
        return shipped_options(cls.name)

    @classmethod
    def section(cls, conf) -> dict[str, Any]:
        """`conf`, the source's section of a depth config (DictConfig or mapping, as the run resolved
        it), as a plain ``dict``: every key of :meth:`options`, no other.

        Raises:
            InputError: not a mapping, a missing option, or an unknown one (named, with its closest
                spellings: typos fail loudly).
        """
        return option_section(conf, cls.options(), f"depth.{cls.name}")

    @classmethod
    def check_files(cls, conf) -> None:
        """Before a run's setup: InputError naming what is missing when the files the source loads (its
        weights, its code) are not where `conf` (its section) says, found without loading them (a
        missing file costs a second, not the minutes of a run's setup). Sources without files: nothing."""

    def reset(self, seed: int | None = None) -> None:
        """Start a new episode; sources with randomness reseed from `seed`."""

    @abstractmethod
    def estimate(self, rgb: np.ndarray, K: np.ndarray, gt_depth: np.ndarray | None = None) -> np.ndarray:
        """(H, W) float32 metres, NaN invalid, for one (H, W, 3) uint8 frame."""

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r})"


def check_rgb(rgb: np.ndarray) -> np.ndarray:
    """Validate an (H, W, 3) uint8 image; return it as a C-contiguous array."""
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape[0] < 1 or rgb.shape[1] < 1:
        raise InputError(f"rgb: expected an (H, W, 3) image, got shape {rgb.shape}")
    if rgb.dtype != np.uint8:
        raise InputError(f"rgb: expected dtype uint8, got {rgb.dtype}")
    return np.ascontiguousarray(rgb)


def check_K(K: np.ndarray) -> np.ndarray:
    """Validate (3, 3) pinhole intrinsics with positive focal lengths; return float64."""
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)):
        raise InputError(f"K: expected finite (3, 3) intrinsics, got shape {K.shape}")
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise InputError(f"K: focal lengths must be positive, got fx={K[0, 0]}, fy={K[1, 1]}")
    return K


def check_gt_depth(gt_depth: np.ndarray | None, shape: tuple[int, int] | None, source: str) -> np.ndarray:
    """Validate ground truth for `source`: (H, W) metres, returned float32 with NaN invalid.

    Non-finite and non-positive values are turned into NaN. `shape` (H, W), when given,
    must match.
    """
    if gt_depth is None:
        raise InputError(f"gt_depth: depth source '{source}' needs ground-truth depth, got None")
    depth = np.array(gt_depth, dtype=np.float32, copy=True)
    if depth.ndim != 2:
        raise InputError(f"gt_depth: expected an (H, W) depth map, got shape {depth.shape}")
    if shape is not None and depth.shape != tuple(shape):
        raise InputError(f"gt_depth: shape {depth.shape} does not match the image's {tuple(shape)}")
    with np.errstate(invalid="ignore"):
        depth[~(np.isfinite(depth) & (depth > 0))] = np.nan
    return depth


def resolve_device(device: str) -> str:
    """Map a config ``device`` (``auto``, ``cpu``, ``cuda``, ``cuda:N``) to a torch device string."""
    import torch

    device = str(device)
    if device == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise InputError(f"device: '{device}' requested but CUDA is not available (use 'cpu' or 'auto')")
    if device != "cpu" and not device.startswith("cuda"):
        raise InputError(f"device: expected auto, cpu, cuda or cuda:N, got '{device}'")
    return device

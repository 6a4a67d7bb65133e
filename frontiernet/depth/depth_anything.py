"""Depth Anything V2 (metric) through Hugging Face ``transformers``.

Weights are read, never downloaded: from a local folder (config ``path``) holding
``config.json``, ``model.safetensors`` and ``preprocessor_config.json``, or from the
Hugging Face hub cache by repo id (config ``repo_id``, e.g.
``depth-anything/Depth-Anything-V2-Metric-Indoor-Small-hf``; also ``-Base-hf``,
``-Large-hf`` and the ``Outdoor`` variants). The metric models take no intrinsics: they
predict depth for the camera statistics they were trained on (Hypersim indoors,
Virtual KITTI outdoors), so ``K`` is only checked.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..errors import InputError
from ._conf import number
from .base import DepthSource, check_K, check_rgb, resolve_device

WEIGHT_FILES = ("config.json", "model.safetensors", "preprocessor_config.json")


def hf_cache_dir() -> Path:
    """The Hugging Face hub cache (honours ``HF_HUB_CACHE`` / ``HF_HOME``)."""
    try:
        from huggingface_hub import constants

        return Path(constants.HF_HUB_CACHE)
    except ImportError:  # pragma: no cover - huggingface_hub comes with transformers
        home = os.environ.get("HF_HOME", os.path.join(os.path.expanduser("~"), ".cache", "huggingface"))
        return Path(os.environ.get("HF_HUB_CACHE", os.path.join(home, "hub")))


def _cache_entry(repo_id: str) -> Path:
    return hf_cache_dir() / ("models--" + repo_id.replace("/", "--"))


def _missing_folder_message(folder: Path, missing: list[str], repo_id: str) -> str:
    return (
        f"depth_anything_v2: no weights in {folder} (missing {', '.join(missing)}). Put "
        f"{', '.join(WEIGHT_FILES)} there, or on a machine with internet run "
        f"`huggingface-cli download {repo_id} --local-dir {folder}` and copy the folder here"
    )


def _missing_cache_message(repo_id: str) -> str:
    cache = _cache_entry(repo_id)
    return (
        f"depth_anything_v2: '{repo_id}' is not in the Hugging Face cache ({cache} has no complete "
        f"{', '.join(WEIGHT_FILES)}). On a machine with internet run `huggingface-cli download {repo_id}` "
        f"and copy {cache} here, or set depth.depth_anything_v2.path to a folder holding those files"
    )


def _import_transformers():
    try:
        import torch  # noqa: F401
        from transformers import AutoImageProcessor, AutoModelForDepthEstimation
    except ImportError as error:
        raise InputError(
            f"depth_anything_v2 needs the 'transformers' package ({error}); install it with "
            "`pip install frontiernet[depth]`"
        ) from None
    return AutoImageProcessor, AutoModelForDepthEstimation


def load_depth_anything(path: str | Path | None, repo_id: str, device: str):
    """Load ``(image_processor, model)`` from local folder `path`, else from the hub cache.

    Raises :class:`InputError` naming the folder (or cache entry) and the expected files
    when the weights are absent; nothing is downloaded (``local_files_only=True``).
    """
    AutoImageProcessor, AutoModelForDepthEstimation = _import_transformers()
    if path is not None:
        folder = Path(path).expanduser()
        missing = [name for name in WEIGHT_FILES if not (folder / name).is_file()]
        if missing:
            raise InputError(_missing_folder_message(folder, missing, repo_id))
        source = str(folder)
    else:
        source = repo_id
    try:
        processor = AutoImageProcessor.from_pretrained(source, local_files_only=True)
        model = AutoModelForDepthEstimation.from_pretrained(source, local_files_only=True)
    except Exception as error:  # noqa: BLE001 - any failure to read user-provided weights
        if path is None and isinstance(error, OSError):
            raise InputError(_missing_cache_message(repo_id)) from None
        detail = (str(error).strip().splitlines() or [type(error).__name__])[0]
        raise InputError(f"depth_anything_v2: cannot load weights from {source}: {detail}") from None
    depth_type = getattr(model.config, "depth_estimation_type", "metric")
    if depth_type != "metric":
        raise InputError(
            f"depth_anything_v2: {source} is a '{depth_type}' depth model; use a metric one "
            "(e.g. depth-anything/Depth-Anything-V2-Metric-Indoor-Small-hf)"
        )
    return processor, model.to(device).eval()


class DepthAnythingV2(DepthSource):
    """Depth Anything V2 metric depth: (H, W, 3) uint8 RGB -> (H, W) float32 metres, dense. Its
    weights: ``path``, else ``repo_id`` from the Hugging Face hub cache."""

    name = "depth_anything_v2"
    flying_pixels = True

    def __init__(self, conf: Mapping[str, Any]) -> None:
        c = self.section(conf)
        self.device = resolve_device(c["device"])
        self.min_depth = number(c, "min_depth", self.name)
        self.processor, self.model = load_depth_anything(c["path"], str(c["repo_id"]), self.device)

    @classmethod
    def check_files(cls, conf) -> None:
        """The weights folder ``path`` holds :data:`WEIGHT_FILES`, or the hub cache has a snapshot of
        ``repo_id`` with them (what :func:`load_depth_anything` reads)."""
        c = cls.section(conf)
        if c["path"] is not None:
            folder = Path(c["path"]).expanduser()
            missing = [name for name in WEIGHT_FILES if not (folder / name).is_file()]
            if missing:
                raise InputError(_missing_folder_message(folder, missing, str(c["repo_id"])))
            return
        snapshots = _cache_entry(str(c["repo_id"])) / "snapshots"
        if not any(all((snapshot / name).exists() for name in WEIGHT_FILES)
                   for snapshot in (snapshots.iterdir() if snapshots.is_dir() else ())):
            raise InputError(_missing_cache_message(str(c["repo_id"])))

    def estimate(self, rgb: np.ndarray, K: np.ndarray, gt_depth: np.ndarray | None = None) -> np.ndarray:
        """Predict depth; ``predicted_depth`` is resized bilinearly to the input's (H, W)."""
        import torch
        import torch.nn.functional as F

        rgb = check_rgb(rgb)
        check_K(K)
        inputs = self.processor(images=rgb, return_tensors="pt")
        pixel_values = inputs["pixel_values"].to(self.device)
        with torch.inference_mode():
            predicted = self.model(pixel_values=pixel_values).predicted_depth  # (1, h, w) metres
            depth = F.interpolate(predicted[:, None].float(), size=rgb.shape[:2], mode="bilinear", align_corners=False)
        depth = depth[0, 0].cpu().numpy().astype(np.float32)
        depth[~np.isfinite(depth)] = np.nan
        with np.errstate(invalid="ignore"):
            return np.maximum(depth, np.float32(self.min_depth))

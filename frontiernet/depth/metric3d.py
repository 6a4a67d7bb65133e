"""Metric3D v2 through ``torch.hub`` from a local clone (never downloaded).

Code: a clone of github.com/YvanYin/Metric3D (config ``repo_dir``), or torch.hub's own
cache ``<torch.hub.get_dir()>/yvanyin_metric3d_main``. Weights: config ``weights``, or
``<torch.hub.get_dir()>/checkpoints/<file>`` with the file names of that repo's
``hubconf.py`` (:data:`CHECKPOINTS`). The model is built with ``pretrain=False`` and the
checkpoint's ``model_state_dict`` loaded from the local file.

Inference follows the example of Metric3D's ``hubconf.py``: resize keeping the aspect
ratio to fit ``input_size``, pad with the mean colour, normalise, run
``model.inference({'input': x})``, unpad, resize back (bilinear), and undo the canonical
camera: ``depth = canonical_depth * fx_scaled / canonical_focal`` with
``fx_scaled = K[0, 0] * resize scale``.
"""

from __future__ import annotations

import pickle
from pathlib import Path
from typing import Any, Mapping

import cv2
import numpy as np

from ..errors import InputError
from ._conf import number
from .base import DepthSource, check_K, check_rgb, resolve_device

#: Checkpoint file of each v2 model, as named in Metric3D's hubconf.py.
CHECKPOINTS = {
    "metric3d_vit_small": "metric_depth_vit_small_800k.pth",
    "metric3d_vit_large": "metric_depth_vit_large_800k.pth",
    "metric3d_vit_giant2": "metric_depth_vit_giant2_800k.pth",
}
WEIGHTS_URL = "https://huggingface.co/JUGGHM/Metric3D/resolve/main/"
HUB_REPO_NAMES = ("yvanyin_metric3d_main", "YvanYin_Metric3D_main")


def find_repo_dir(repo_dir: str | Path | None) -> Path:
    """The Metric3D code folder (holding ``hubconf.py``), or :class:`InputError` saying where."""
    import torch

    hub = Path(torch.hub.get_dir())
    candidates = [Path(repo_dir).expanduser()] if repo_dir is not None else [hub / name for name in HUB_REPO_NAMES]
    for folder in candidates:
        if (folder / "hubconf.py").is_file():
            return folder
    raise InputError(
        f"metric3d_v2: no Metric3D code at {candidates[0]} (no hubconf.py). On a machine with internet run "
        f"`git clone https://github.com/YvanYin/Metric3D {hub / HUB_REPO_NAMES[0]}` and copy it here, "
        "or set depth.metric3d_v2.repo_dir to a clone"
    )


def find_weights(weights: str | Path | None, model: str) -> Path:
    """The checkpoint of `model`, or :class:`InputError` naming the path and file name."""
    import torch

    file_name = CHECKPOINTS[model]
    path = Path(weights).expanduser() if weights is not None else Path(torch.hub.get_dir()) / "checkpoints" / file_name
    if not path.is_file():
        raise InputError(
            f"metric3d_v2: no weights for {model} at {path}. Download {WEIGHTS_URL}{file_name} on a machine "
            f"with internet and put it at {path}, or set depth.metric3d_v2.weights to the file"
        )
    return path


def load_metric3d(repo_dir: Path, model: str, weights: Path, device: str, trust_checkpoint: bool = False):
    """Build `model` with ``torch.hub.load(repo_dir, model, source='local', pretrain=False)``
    and load ``model_state_dict`` from the local checkpoint `weights`; eval mode on `device`."""
    import torch

    try:
        net = torch.hub.load(str(repo_dir), model, source="local", pretrain=False)
    except ImportError as error:
        raise InputError(
            f"metric3d_v2: Metric3D's code in {repo_dir} needs the package '{error.name}' "
            f"(`pip install {error.name}`; Metric3D also lists mmengine and timm)"
        ) from None
    except AttributeError:
        raise InputError(f"metric3d_v2: {repo_dir}/hubconf.py has no entry point '{model}'") from None
    try:
        checkpoint = torch.load(weights, map_location="cpu", weights_only=not trust_checkpoint)
    except pickle.UnpicklingError:
        raise InputError(
            f"metric3d_v2: {weights} holds pickled Python objects besides tensors; if you trust the "
            "file, set depth.metric3d_v2.trust_checkpoint=true"
        ) from None
    except (OSError, RuntimeError, EOFError) as error:
        raise InputError(f"metric3d_v2: {weights} is not a readable torch checkpoint ({error})") from None
    state = checkpoint.get("model_state_dict", checkpoint) if isinstance(checkpoint, dict) else None
    if not isinstance(state, dict):
        raise InputError(f"metric3d_v2: {weights} holds no state dict ('model_state_dict')")
    result = net.load_state_dict(state, strict=False)  # strict=False as Metric3D's hubconf does
    if state and len(result.unexpected_keys) == len(state):
        raise InputError(f"metric3d_v2: no tensor of {weights} fits {model}; is it the right checkpoint?")
    return net.to(device).eval()


class Metric3DV2(DepthSource):
    """Metric3D v2 metric depth: (H, W, 3) uint8 RGB + K -> (H, W) float32 metres, dense."""

    name = "metric3d_v2"
    flying_pixels = True
    uses_intrinsics = True

    def __init__(self, conf: Mapping[str, Any]) -> None:
        c = self.section(conf)
        self.model_name = str(c["model"])
        if self.model_name not in CHECKPOINTS:
            raise InputError(f"depth.metric3d_v2.model: expected one of {sorted(CHECKPOINTS)}, got '{self.model_name}'")
        self.input_size = tuple(int(v) for v in c["input_size"])
        if len(self.input_size) != 2 or min(self.input_size) < 1:
            raise InputError(f"depth.metric3d_v2.input_size: expected [height, width], got {c['input_size']}")
        self.canonical_focal = number(c, "canonical_focal", self.name, minimum=1e-6)
        self.pad_value = np.asarray(c["pad_value"], dtype=np.float32).reshape(3)
        self.mean = np.asarray(c["mean"], dtype=np.float32).reshape(3)
        self.std = np.asarray(c["std"], dtype=np.float32).reshape(3)
        self.min_depth = number(c, "min_depth", self.name)
        self.max_depth = number(c, "max_depth", self.name, minimum=self.min_depth)
        self.device = resolve_device(c["device"])
        repo_dir = find_repo_dir(c["repo_dir"])
        weights = find_weights(c["weights"], self.model_name)
        self.model = load_metric3d(repo_dir, self.model_name, weights, self.device, bool(c["trust_checkpoint"]))

    @classmethod
    def check_files(cls, conf) -> None:
        """The Metric3D code folder and the model's checkpoint are where the section says."""
        c = cls.section(conf)
        if str(c["model"]) not in CHECKPOINTS:
            raise InputError(f"depth.metric3d_v2.model: expected one of {sorted(CHECKPOINTS)}, got '{c['model']}'")
        find_repo_dir(c["repo_dir"])
        find_weights(c["weights"], str(c["model"]))

    def preprocess(self, rgb: np.ndarray) -> tuple[np.ndarray, float, tuple[int, int, int, int]]:
        """Resize (keep aspect) into ``input_size``, pad with ``pad_value``, normalise.

        Returns the (3, h_in, w_in) float32 network input, the resize scale, and the padding
        (top, bottom, left, right) in pixels.
        """
        h, w = rgb.shape[:2]
        in_h, in_w = self.input_size
        scale = min(in_h / h, in_w / w)
        new_h, new_w = max(1, int(h * scale)), max(1, int(w * scale))
        resized = cv2.resize(rgb, (new_w, new_h), interpolation=cv2.INTER_LINEAR)
        top, left = (in_h - new_h) // 2, (in_w - new_w) // 2
        padded = np.empty((in_h, in_w, 3), dtype=np.float32)
        padded[:] = self.pad_value
        padded[top : top + new_h, left : left + new_w] = resized
        normalised = (padded - self.mean) / self.std
        pad = (top, in_h - new_h - top, left, in_w - new_w - left)
        return np.ascontiguousarray(normalised.transpose(2, 0, 1)), scale, pad

    def estimate(self, rgb: np.ndarray, K: np.ndarray, gt_depth: np.ndarray | None = None) -> np.ndarray:
        """Predict metric depth; `K` sets the de-canonical scale ``K[0, 0] * scale / canonical_focal``."""
        import torch
        import torch.nn.functional as F

        rgb = check_rgb(rgb)
        K = check_K(K)
        x, scale, (top, bottom, left, right) = self.preprocess(rgb)
        with torch.inference_mode():
            pred, _confidence, _output = self.model.inference({"input": torch.from_numpy(x)[None].to(self.device)})
            pred = pred.float().reshape(1, 1, *pred.shape[-2:])
            if tuple(pred.shape[-2:]) != self.input_size:  # the hubconf example assumes equal sizes
                pred = F.interpolate(pred, size=self.input_size, mode="bilinear", align_corners=False)
            pred = pred[..., top : self.input_size[0] - bottom, left : self.input_size[1] - right]
            pred = F.interpolate(pred, size=rgb.shape[:2], mode="bilinear", align_corners=False)
        depth = pred[0, 0].cpu().numpy() * np.float32(K[0, 0] * scale / self.canonical_focal)
        depth[~np.isfinite(depth)] = np.nan
        with np.errstate(invalid="ignore"):
            return np.clip(depth, self.min_depth, self.max_depth).astype(np.float32)

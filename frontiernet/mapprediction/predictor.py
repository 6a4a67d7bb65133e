"""Map predictor files, and predictions of the unseen map from an :class:`~frontiernet.mapping.OccupancyMap`.

A predictor file (``*.safetensors``, what ``frontiernet train --config configs/train_seer.yaml`` or
``train_mapex.yaml`` writes as ``predictor.safetensors``) holds the weights of every member of an
:class:`~.networks.Ensemble` and, in its metadata, :data:`FORMAT`, the :class:`~.networks.PredictorSpec`
(kind, architecture, members, voxel size, crop shape, band) and an ``info`` record (training scenes,
steps, validation scores). A training checkpoint (``.ckpt``) loads too (plain data only).

:meth:`MapPredictor.predict_crop` (kind ``seer``) predicts the occupancy of the crop around a frontier
cluster; :meth:`MapPredictor.predict_topdown` (kind ``mapex``) the mean and variance over the ensemble of
the top-down map. Known cells keep their observed state in both (LaMa's ``inpainted`` output, which
MapEx reads, is the input where known), so only the unknown cells carry predictions.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
import torch

from ..errors import InputError
from ..io import input_file, write_bytes
from ..mapping.occupancy import FREE, OCCUPIED, UNKNOWN
from .encodings import crop_input, crop_states, map_topdown_states, topdown_input, topdown_probability
from .networks import Ensemble, PredictorSpec

FORMAT = "frontiernet-map-predictor-1"
"""The metadata ``format`` of a predictor file."""
SHIPPED = {"seer": "mappredictor_seer.safetensors", "mapex": "mappredictor_mapex.safetensors"}
"""Shipped predictor files in ``frontiernet/weights/``, by kind."""


@dataclass
class CropPrediction:
    """A crop's prediction: `probability` (X, Y, Z) float32 occupancy probability (known voxels 0 or 1),
    `states` (X, Y, Z) int8 the map's crop, `corner` (3,) int64 map index of the crop's first voxel."""

    probability: np.ndarray
    states: np.ndarray
    corner: np.ndarray


class MapPredictor:
    """A loaded predictor: its :class:`~.networks.PredictorSpec` (``spec``), ensemble (``net``, eval mode,
    CPU, float32) and ``info``; ``path`` names its file in messages."""

    def __init__(self, spec: PredictorSpec, net: Ensemble, info: dict | None = None, path: str | Path = "predictor"):
        self.spec, self.net, self.info, self.path = spec, net.eval(), dict(info or {}), str(path)

    @property
    def kind(self) -> str:
        return self.spec.kind

    @property
    def occupied_threshold(self) -> float:
        """Predicted probability above which a cell counts as occupied (``predictor.occupied_threshold``)."""
        return float(self.spec.extra.get("occupied_threshold", 0.5))

    @property
    def receptive_radius(self) -> int:
        """Input cells farther than this from an output cell do not change it (:class:`~.networks.Ensemble`)."""
        return self.net.receptive_radius

    @property
    def multiple(self) -> int:
        """The network's input multiple: a crop of the map started on a multiple of it is predicted as
        the whole map would be (the strided levels see the same blocks)."""
        return self.net.multiple

    def _check(self, kind: str, voxel_size: float) -> None:
        if self.kind != kind:
            raise InputError(f"{self.path}: a {self.kind} predictor, not a {kind} one "
                             f"({'predict_crop' if kind == 'seer' else 'predict_topdown'} needs kind {kind})")
        if not np.isclose(float(voxel_size), self.spec.voxel_size, rtol=1e-6, atol=0.0):
            raise InputError(f"{self.path}: trained on {self.spec.voxel_size} m voxels, given a map of "
                             f"{float(voxel_size)} m voxels")

    def _run(self, inputs: np.ndarray) -> np.ndarray:
        """(M, B, ...) float32 probabilities of (B, C, ...) inputs, padded to the network's multiple."""
        x = torch.from_numpy(np.ascontiguousarray(inputs, np.float32))
        spatial = x.shape[2:]
        multiple = self.net.multiple
        pads = [(-n) % multiple for n in spatial]
        if any(pads):
            pad = []
            for extra in reversed(pads):
                pad += [0, extra]
            # padding is unknown space: one-hot unknown (seer) or probability 0.5 with its mask (mapex)
            fill = torch.zeros(x.shape[1])
            fill[0] = 1.0 if self.kind == "seer" else 0.5
            if self.kind == "mapex":
                fill[1] = 1.0
            x = torch.cat([torch.nn.functional.pad(x[:, c:c + 1], pad, value=float(fill[c]))
                           for c in range(x.shape[1])], dim=1)
        with torch.inference_mode():
            logits = self.net(x)[:, :, 0]
        logits = logits[(slice(None), slice(None)) + tuple(slice(0, n) for n in spatial)]
        return torch.sigmoid(logits).numpy()

    def predict_crop_states(self, states: np.ndarray, voxel_size: float) -> np.ndarray:
        """(X, Y, Z) float32 occupancy probability of an (X, Y, Z) int8 crop of states (``crop_shape``)
        at `voxel_size` metres; known voxels keep their state (0 free, 1 occupied).

        Raises:
            InputError: a predictor of another kind, another voxel size or another crop shape.
        """
        self._check("seer", voxel_size)
        states = np.asarray(states)
        if states.shape != tuple(self.spec.crop_shape):
            raise InputError(f"{self.path}: takes crops of {list(self.spec.crop_shape)} voxels, given "
                             f"{list(states.shape)}")
        probability = self._run(crop_input(states)[None])[0, 0]
        return _keep_known(probability, states)

    def predict_crop(self, occupancy, centre, floor_z: float | None = None) -> CropPrediction:
        """The crop of `occupancy` around `centre` ((2,) or (3,) world metres: a frontier cluster's centre;
        z from the layer of `floor_z`, None: the map's bottom) and its predicted occupancy probability."""
        self._check("seer", occupancy.voxel_size)
        states, corner = crop_states(occupancy, centre, self.spec.crop_shape, floor_z)
        return CropPrediction(self.predict_crop_states(states, occupancy.voxel_size), states, corner)

    def predict_topdown_states(self, states2d: np.ndarray, voxel_size: float) -> tuple[np.ndarray, np.ndarray]:
        """(mean, variance) over the ensemble, both (X, Y) float32, of the occupancy probability of an (X, Y)
        int8 top-down map of states (:func:`~.encodings.topdown_states`); known cells keep their state
        (mean 0 or 1, variance 0). The variance is the unbiased one over the members (MapEx's
        ``torch.var`` over its ensemble), 0 for a single member."""
        self._check("mapex", voxel_size)
        states2d = np.asarray(states2d)
        if states2d.ndim != 2:
            raise InputError(f"{self.path}: takes an (X, Y) top-down map, given shape {list(states2d.shape)}")
        members = self._run(topdown_input(topdown_probability(states2d))[None])[:, 0]
        mean = members.mean(axis=0)
        variance = members.var(axis=0, ddof=1) if len(members) > 1 else np.zeros_like(mean)
        known = states2d != UNKNOWN
        return _keep_known(mean, states2d), np.where(known, 0.0, variance).astype(np.float32)

    def predict_topdown(self, occupancy, z: float) -> tuple[np.ndarray, np.ndarray]:
        """(mean, variance), (X, Y) float32, of the whole map's top-down view at camera height `z` (world
        metres; the band ``z +- band_m``): :meth:`predict_topdown_states` of it."""
        self._check("mapex", occupancy.voxel_size)
        return self.predict_topdown_states(map_topdown_states(occupancy, z, self.spec.band_m), occupancy.voxel_size)


def _keep_known(probability: np.ndarray, states: np.ndarray) -> np.ndarray:
    out = np.asarray(probability, np.float32).copy()
    out[states == FREE] = 0.0
    out[states == OCCUPIED] = 1.0
    return out


# --------------------------------------------------------------------------- files

def shipped_predictor_path(kind: str) -> Path:
    """The shipped predictor file of `kind` (it may not exist yet: :func:`load_predictor` says so)."""
    if kind not in SHIPPED:
        raise InputError(f"no predictor kind {kind!r}; kinds: {', '.join(SHIPPED)}")
    return Path(str(resources.files("frontiernet").joinpath("weights", SHIPPED[kind])))


def save_predictor(path: str | Path, spec: PredictorSpec, state: dict, info: dict | None = None) -> Path:
    """Write a predictor file atomically: `state` (the :class:`~.networks.Ensemble`'s state dict) and the
    metadata (:data:`FORMAT`, `spec`, `info`)."""
    from safetensors.torch import save

    tensors = {name: value.detach().cpu().contiguous() for name, value in state.items()}
    metadata = {"format": FORMAT, "spec": json.dumps(spec.to_dict()), "info": json.dumps(info or {})}
    return write_bytes(path, save(tensors, metadata=metadata))


def _read(path: Path) -> tuple[dict, dict, dict]:
    """(state dict, spec dict, info) of a predictor file or a training checkpoint."""
    if path.suffix == ".safetensors":
        from safetensors import SafetensorError, safe_open

        try:
            with safe_open(str(path), framework="pt") as handle:
                metadata = handle.metadata() or {}
                if metadata.get("format") != FORMAT:  # before reading the tensors (a FrontierNet model: 25 MB)
                    raise InputError(f"{path}: not a map predictor file (format {metadata.get('format')!r}, "
                                     f"expected {FORMAT!r}; a FrontierNet model?)")
                state = {name: handle.get_tensor(name) for name in handle.keys()}
        except (SafetensorError, OSError, ValueError) as error:
            if isinstance(error, InputError):
                raise
            raise InputError(f"{path}: not a readable safetensors file ({error})") from None
        try:
            return state, json.loads(metadata["spec"]), json.loads(metadata.get("info", "{}"))
        except (KeyError, ValueError):
            raise InputError(f"{path}: the predictor description in the file is missing or not JSON") from None
    from ..model.files import load_checkpoint

    checkpoint = load_checkpoint(path, "predictor file or training checkpoint")
    hyper = checkpoint.get("hyper_parameters", {}) if isinstance(checkpoint, dict) else {}
    if "predictor" not in hyper or "state_dict" not in checkpoint:
        raise InputError(f"{path}: not a map predictor checkpoint (no predictor description; a FrontierNet one?)")
    state = {name[len("net."):]: value for name, value in checkpoint["state_dict"].items() if name.startswith("net.")}
    scenes = (hyper.get("train") or {}).get("scenes") or {}
    return state, dict(hyper["predictor"]), {"checkpoint": str(path), "train_scenes": list(scenes.get("train", [])),
                                             "val_scenes": list(scenes.get("val", []))}


def load_predictor(path: str | Path | None = None, kind: str | None = None) -> MapPredictor:
    """Load a predictor file or checkpoint (None: the shipped one of `kind`).

    Raises:
        InputError naming the file: missing, unreadable, not a predictor, of another `kind`, or weights
            that do not fit the architecture it declares (missing, unexpected or of another shape).
    """
    if path is None:
        if kind is None:
            raise InputError("load_predictor: give a predictor file or a kind (seer, mapex)")
        path = shipped_predictor_path(kind)
        if not path.is_file():
            raise InputError(f"{path}: no {kind} predictor is shipped yet; train one (docs/mapprediction.md) "
                             f"and give its predictor.safetensors")
    path = input_file(path, "predictor file", empty_ok=False)
    state, spec_dict, info = _read(path)
    try:
        spec = PredictorSpec.from_dict(spec_dict)
    except InputError as error:
        raise InputError(f"{path}: {error}") from None
    if kind is not None and spec.kind != kind:
        raise InputError(f"{path}: a {spec.kind} predictor, expected a {kind} one")
    net = spec.build()
    own = net.state_dict()
    state = {name: value.float() if value.is_floating_point() else value for name, value in state.items()}
    missing, unexpected = sorted(set(own) - set(state)), sorted(set(state) - set(own))
    wrong = sorted(n for n in set(own) & set(state) if own[n].shape != state[n].shape)
    if missing or unexpected or wrong:
        first = (missing or unexpected or wrong)[0]
        raise InputError(f"{path}: weights do not fit the {spec.kind} predictor it declares ({len(missing)} "
                         f"missing, {len(unexpected)} unexpected, {len(wrong)} of another shape; first: {first})")
    net.load_state_dict(state)
    return MapPredictor(spec, net, info, path)


__all__ = ["FORMAT", "SHIPPED", "CropPrediction", "MapPredictor", "load_predictor", "save_predictor",
           "shipped_predictor_path"]

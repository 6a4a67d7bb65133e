"""The two map-prediction networks: small UNets that train on two CPU cores.

* :class:`CropNet` (SEER's encoding): a 3D UNet over a crop of the map around a frontier cluster,
  one-hot unknown / free / occupied in (3 channels, ``(B, 3, X, Y, Z)``), occupancy logits out
  (``(B, 1, X, Y, Z)``). SEER's own network (tyuezhan/SEER ``model_dense_nosdf.py``, built in
  ``net_node.py`` as ``GenModel(8, 1, 16, 16, 2, ...)``) has 115k parameters, two strided levels and a
  refinement back to full resolution; this one keeps that size and depth (full resolution, /2, /4)
  and widens its receptive field with dilated convolutions at /4 (a wall 3 m away is 30 voxels).
* :class:`TopdownNet` (MapEx's encoding): a 2D UNet over the top-down map, the occupancy probability
  (0 free, 0.5 unknown, 1 occupied) and the unknown mask in (LaMa's image + mask, castacks/MapEx
  ``lama_pred_utils.py``), occupancy logits out. MapEx runs an ensemble of LaMa models (tens of
  millions of parameters each) on a GPU; an ensemble of these (:class:`Ensemble`) runs on a CPU.

Every size is a field of :class:`NetworkSettings` (``predictor.network`` of the training configs);
the sizes shipped are those of ``configs/train_seer.yaml`` and ``configs/train_mapex.yaml``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import torch
from torch import nn

from ..errors import InputError

KINDS = ("seer", "mapex")
"""The predictor kinds: ``seer`` (3D crops, :class:`CropNet`) and ``mapex`` (top-down, :class:`TopdownNet`)."""


@dataclass(frozen=True)
class NetworkSettings:
    """The architecture of one network (a member of an ensemble).

    Attributes:
        widths: channels per level, full resolution first; each further level halves x and y
            (and z, for the 3D network).
        dilations: dilation of each convolution of the deepest level (its receptive field).
        in_channels: input channels (3 for the crops' one-hot states, 2 for the top-down map).
    """

    widths: tuple[int, ...] = (8, 16, 36)
    dilations: tuple[int, ...] = (1, 2, 4)
    in_channels: int = 3

    def __post_init__(self) -> None:
        for name in ("widths", "dilations"):
            values = tuple(getattr(self, name))
            if not values or not all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in values):
                raise InputError(f"predictor.network.{name} must list positive integers, got {list(values)}")
            object.__setattr__(self, name, values)
        if len(self.widths) < 2:
            raise InputError(f"predictor.network.widths needs at least 2 levels, got {list(self.widths)}")
        if not isinstance(self.in_channels, int) or self.in_channels < 1:
            raise InputError(f"predictor.network.in_channels must be a positive integer, got {self.in_channels!r}")

    @classmethod
    def from_dict(cls, values: dict) -> NetworkSettings:
        known = {"widths", "dilations", "in_channels"}
        unknown = sorted(set(values) - known)
        if unknown:
            raise InputError(f"unknown predictor.network setting(s): {', '.join(unknown)}")
        return cls(**{key: tuple(value) if isinstance(value, (list, tuple)) else value
                      for key, value in values.items()})

    def to_dict(self) -> dict:
        return {key: list(value) if isinstance(value, tuple) else value for key, value in asdict(self).items()}


def _conv(dims: int, c_in: int, c_out: int, kernel: int = 3, stride: int = 1, dilation=1) -> nn.Sequential:
    """Convolution (same size for stride 1), batch norm, ReLU, in 2D or 3D."""
    Conv, Norm = (nn.Conv2d, nn.BatchNorm2d) if dims == 2 else (nn.Conv3d, nn.BatchNorm3d)
    if isinstance(dilation, int):
        dilation = (dilation,) * dims
    padding = tuple(d * (kernel // 2) for d in dilation) if stride == 1 else 0
    return nn.Sequential(Conv(c_in, c_out, kernel, stride=stride, padding=padding, dilation=dilation, bias=False),
                         Norm(c_out), nn.ReLU(inplace=True))


class _Residual(nn.Module):
    """x + f(x): the deepest level's convolutions (a residual stack keeps the dilated ones trainable)."""

    def __init__(self, body: nn.Module) -> None:
        super().__init__()
        self.body = body

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.body(x)


class UNet(nn.Module):
    """A UNet in 2D or 3D, light at full resolution (where a crop has 153,600 voxels).

    Down: strided 2x2(x2) convolutions from the input to each coarser level (``widths[1:]``), one
    3x3(x3) convolution per intermediate level, residual dilated convolutions at the deepest level.
    Up: transposed 2x2(x2) convolutions, the skip features concatenated and merged by a 3x3(x3)
    convolution; at full resolution the skip is the input itself and the merge a 1x1 convolution
    (to ``widths[0]`` channels), then a 1x1 head. The known cells are in the input, so the full-resolution
    detail they carry reaches the head without a full-resolution 3x3x3 convolution, which would cost
    as much as the rest of the network. Inputs must be divisible by 2^(levels - 1) on every axis
    (the callers pad)."""

    def __init__(self, settings: NetworkSettings, dims: int) -> None:
        super().__init__()
        widths, self.dims = settings.widths, dims
        self.multiple = 2 ** (len(widths) - 1)
        ConvT = nn.ConvTranspose2d if dims == 2 else nn.ConvTranspose3d
        steps = (settings.in_channels,) + tuple(widths[1:])
        self.down = nn.ModuleList(_conv(dims, a, b, kernel=2, stride=2) for a, b in zip(steps[:-1], steps[1:]))
        self.level = nn.ModuleList(_conv(dims, w, w) for w in widths[1:-1])
        deepest = widths[-1]
        self.bottom = nn.Sequential(*(_Residual(_conv(dims, deepest, deepest, dilation=self._dilation(d)))
                                      for d in settings.dilations))
        self.up = nn.ModuleList(ConvT(b, a, 2, stride=2, bias=False) for a, b in zip(widths[:-1], widths[1:]))
        self.merge = nn.ModuleList([_conv(dims, widths[0] + settings.in_channels, widths[0], kernel=1)]
                                   + [_conv(dims, 2 * w, w) for w in widths[1:-1]])
        self.head = (nn.Conv2d if dims == 2 else nn.Conv3d)(widths[0], 1, 1)
        levels = len(widths)
        self.receptive_radius = int(  # a bound, in full-resolution cells, on how far an input reaches an output:
            sum(2 ** i for i in range(levels - 1))  # the strided 2x2 downs (one cell of level i: 2^i cells)
            + sum(2 ** i for i in range(1, levels - 1))  # the 3x3 convolutions of the intermediate levels
            + sum(settings.dilations) * 2 ** (levels - 1)  # the dilated 3x3 ones of the deepest level
            + sum(2 ** (i + 1) for i in range(levels - 1))  # the transposed 2x2 ups
            + sum(2 ** i for i in range(1, levels - 1)))  # the 3x3 merges (the full-resolution one is 1x1)

    def _dilation(self, d: int):
        # the crops are 24 voxels high (6 at /4): z dilates at most 2
        return d if self.dims == 2 else (d, d, min(d, 2))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        skips = [x]
        for index, down in enumerate(self.down):
            x = down(x)
            if index < len(self.level):
                x = self.level[index](x)
                skips.append(x)
        x = self.bottom(x)
        for index in reversed(range(len(self.up))):
            x = self.merge[index](torch.cat([self.up[index](x), skips[index]], dim=1))
        return self.head(x)


class CropNet(UNet):
    """SEER's crop predictor: (B, 3, X, Y, Z) one-hot states -> (B, 1, X, Y, Z) occupancy logits."""

    def __init__(self, settings: NetworkSettings) -> None:
        super().__init__(settings, 3)


class TopdownNet(UNet):
    """MapEx's top-down predictor: (B, 2, X, Y) probability and unknown mask -> (B, 1, X, Y) logits."""

    def __init__(self, settings: NetworkSettings) -> None:
        super().__init__(settings, 2)


class Ensemble(nn.Module):
    """`members` networks of one kind and architecture; ``forward`` -> (M, B, 1, ...) logits."""

    def __init__(self, kind: str, settings: NetworkSettings, members: int = 1) -> None:
        super().__init__()
        if kind not in KINDS:
            raise InputError(f"predictor.kind must be one of {', '.join(KINDS)}, got {kind!r}")
        if not isinstance(members, int) or isinstance(members, bool) or members < 1:
            raise InputError(f"predictor.members must be a positive integer, got {members!r}")
        expected = 3 if kind == "seer" else 2
        if settings.in_channels != expected:
            raise InputError(f"predictor.network.in_channels must be {expected} for a {kind} predictor, "
                             f"got {settings.in_channels}")
        Net = CropNet if kind == "seer" else TopdownNet
        self.kind, self.settings = kind, settings
        self.members = nn.ModuleList(Net(settings) for _ in range(members))

    @property
    def multiple(self) -> int:
        """Input sizes must be multiples of this on every axis."""
        return self.members[0].multiple

    @property
    def receptive_radius(self) -> int:
        """Input cells farther than this (on any axis, full resolution) from an output cell do not change
        it (a bound: the UNet's strides, kernels and dilations summed)."""
        return self.members[0].receptive_radius

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.stack([member(x) for member in self.members])


def parameter_count(module: nn.Module) -> int:
    """Number of trainable parameters of `module`."""
    return sum(p.numel() for p in module.parameters() if p.requires_grad)


@dataclass(frozen=True)
class PredictorSpec:
    """What a predictor file declares: its kind, architecture, member count and the map encoding it
    was trained on (checked against the maps it is given).

    Attributes:
        kind: ``seer`` or ``mapex``.
        network: the architecture of each member.
        members: ensemble size (MapEx's variance needs at least 2; SEER uses 1).
        voxel_size: metres; the map's voxel size must equal it.
        crop_shape: (X, Y, Z) voxels of a ``seer`` crop (SEER: 80 x 80 x 24 at 0.1 m).
        band_m: half height of the ``mapex`` top-down band around the camera height, metres.
    """

    kind: str
    network: NetworkSettings
    members: int = 1
    voxel_size: float = 0.1
    crop_shape: tuple[int, int, int] = (80, 80, 24)
    band_m: float = 0.3
    extra: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"kind": self.kind, "network": self.network.to_dict(), "members": self.members,
                "voxel_size": self.voxel_size, "crop_shape": list(self.crop_shape), "band_m": self.band_m,
                "extra": dict(self.extra)}

    @classmethod
    def from_dict(cls, values: dict) -> PredictorSpec:
        try:
            network = NetworkSettings.from_dict(dict(values["network"]))
            spec = cls(str(values["kind"]), network, int(values["members"]), float(values["voxel_size"]),
                       tuple(int(n) for n in values["crop_shape"]), float(values["band_m"]),
                       dict(values.get("extra") or {}))
        except (KeyError, TypeError, ValueError) as error:
            raise InputError(f"predictor description lacks or mangles {error}") from None
        if spec.kind not in KINDS:
            raise InputError(f"predictor kind must be one of {', '.join(KINDS)}, got {spec.kind!r}")
        if len(spec.crop_shape) != 3 or min(spec.crop_shape) < 1 or not spec.voxel_size > 0 or not spec.band_m > 0:
            raise InputError(f"predictor crop_shape must be 3 positive voxel counts and voxel_size, band_m "
                             f"positive, got {list(spec.crop_shape)}, {spec.voxel_size}, {spec.band_m}")
        multiple = 2 ** (len(network.widths) - 1)
        if spec.kind == "seer" and any(n % multiple for n in spec.crop_shape):
            raise InputError(f"predictor crop_shape {list(spec.crop_shape)} must be divisible by {multiple} "
                             f"(2 ^ (levels - 1) of predictor.network.widths)")
        return spec

    def build(self) -> Ensemble:
        """A fresh (randomly initialised) :class:`Ensemble` of this architecture."""
        return Ensemble(self.kind, self.network, self.members)


__all__ = ["KINDS", "CropNet", "Ensemble", "NetworkSettings", "PredictorSpec", "TopdownNet", "UNet",
           "parameter_count"]

"""The FrontierNet network: a UNet on a torchvision encoder with two heads.

docs/design.md section 2, paper section III-C. The encoder is a torchvision ResNet (18, 34 or 50:
the paper's family) or one of the lighter torchvision MobileNetV3 (large, small) and
EfficientNet-B0 (``FEATURE_ENCODERS``); its first convolution takes the configured input channels
(RGB + depth prior, RGB only or depth only); a shared UNet decoder upsamples back to full
resolution, with skip features at strides 2, 4, 8 and 16; two heads of three convolutions each
predict

- the normalised distance field ``y = -log(max(D, d_min) / r)`` (1 channel, non-negative by a
  softplus: D <= r everywhere, so y >= 0);
- the information-gain class logits (K = 11 channels).

Inputs of any size work: they are zero-padded on the right and bottom to a multiple of the
encoder stride (32) and the outputs are cropped back, so nothing is resized inside the network.

The network's weights come from files read here, none of which can run code when opened
(:func:`load_model`, :func:`save_model`):

- **model files** ``*.safetensors`` (what ``frontiernet export --format safetensors`` and the
  shipped weights are): the tensors, plus the model config (``network``, ``input``, ``labels``,
  ``inference`` sections of ``configs/model.yaml``) and a free-form ``info`` record as JSON in
  the safetensors metadata (a file fine-tuned with some layers frozen stores only its own tensors and
  names the file it shares the others with: :mod:`.files`);
- **training checkpoints** ``*.ckpt`` written by ``frontiernet train`` (Lightning): read with
  ``torch.load(..., weights_only=True)``, so a pickle that carries code is refused;
- **ImageNet encoder weights** (torchvision state dicts, training's starting point,
  :func:`load_imagenet_encoder`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Optional

import torch
import torch.nn.functional as F
from torch import nn

from ..errors import InputError
from ..io import input_file
from .files import (CONFIG_KEY, DEFAULT_MODEL, INFO_KEY, default_model_path,  # noqa: F401 (re-exported)
                    read_model_file, save_model, shipped_weights_folder, torch_model_file)

RESNET_ENCODERS = ("resnet18", "resnet34", "resnet50")
FEATURE_ENCODERS = {
    # torchvision models whose encoder is their `features` Sequential: for each output stride 2, 4,
    # 8, 16, 32 the end index (exclusive) of the blocks that run at that stride, and their channels.
    # The skip/deepest features are the outputs of blocks [1, 3, 6, 12, 15] (mobilenet_v3_large),
    # [0, 1, 3, 8, 11] (mobilenet_v3_small), [1, 2, 3, 5, 7] (efficientnet_b0). The last block of
    # `features`, the classifier's 1x1 expansion to 960 / 576 / 1280 channels, is left out (as in
    # timm's features_only EfficientNet): the pooled classifier needs it, and 6-8x the channels
    # would make the first decoder stage's input that much wider.
    "mobilenet_v3_large": ((2, 16), (4, 24), (7, 40), (13, 112), (16, 160)),
    "mobilenet_v3_small": ((1, 16), (2, 16), (4, 24), (9, 48), (12, 96)),
    "efficientnet_b0": ((2, 16), (3, 24), (4, 40), (6, 112), (8, 320)),
}
ENCODERS = (*RESNET_ENCODERS, *FEATURE_ENCODERS)
ENCODER_STRIDE = 32
"""Every encoder's deepest output stride: an input padded to a multiple of it keeps the skip features'
sizes at exactly half of the level above (another multiple fails in the decoder's concatenation)."""
INPUT_CHANNELS = {"rgbd": 4, "rgb": 3, "depth": 1}


def _torchvision_model(name: str) -> nn.Module:
    """torchvision's `name` model, untrained (an encoder's skeleton; weights come from a model file
    or ImageNet's). torchvision is imported here, not with this module: importing it takes ~1.5 s
    (it pulls in torch._dynamo), which every command that runs an exported (ONNX) model and only
    reads this module's constants would pay."""
    import torchvision

    return getattr(torchvision.models, name)(weights=None)


@dataclass(frozen=True)
class NetworkConfig:
    """Architecture of :class:`FrontierNet` (``configs/model.yaml`` section ``network``)."""

    encoder: str = "resnet18"
    inputs: str = "rgbd"
    decoder_channels: tuple[int, ...] = (128, 64, 32, 16, 16)
    head_channels: int = 16
    num_classes: int = 11
    pad_multiple: int = 32

    def __post_init__(self):
        if self.encoder not in ENCODERS:
            raise InputError(f"network.encoder must be one of {', '.join(ENCODERS)}, got {self.encoder!r}")
        if self.inputs not in INPUT_CHANNELS:
            raise InputError(f"network.inputs must be one of {', '.join(INPUT_CHANNELS)}, got {self.inputs!r}")
        if len(self.decoder_channels) != 5 or min(self.decoder_channels) < 1:
            raise InputError(f"network.decoder_channels must list 5 positive widths, got "
                             f"{list(self.decoder_channels)}")
        if self.num_classes < 2 or self.head_channels < 1:
            raise InputError("network.num_classes must be >= 2 and head_channels >= 1")
        if self.pad_multiple < 1 or self.pad_multiple % ENCODER_STRIDE:
            raise InputError(f"network.pad_multiple must be a positive multiple of {ENCODER_STRIDE} (the encoder's "
                             f"stride), got {self.pad_multiple}")

    @property
    def in_channels(self) -> int:
        return INPUT_CHANNELS[self.inputs]

    def to_dict(self) -> dict:
        values = asdict(self)
        values["decoder_channels"] = list(self.decoder_channels)
        return values

    @classmethod
    def from_dict(cls, values) -> NetworkConfig:
        values = dict(values)
        known = {name for name in cls.__dataclass_fields__}
        unknown = sorted(set(values) - known - {"pretrained"})
        if unknown:
            raise InputError(f"unknown network setting(s): {', '.join(unknown)}")
        values.pop("pretrained", None)
        if "decoder_channels" in values:
            values["decoder_channels"] = tuple(int(c) for c in values["decoder_channels"])
        return cls(**values)


def _conv_block(in_channels: int, out_channels: int) -> nn.Sequential:
    """3x3 conv, batch norm, ReLU."""
    return nn.Sequential(nn.Conv2d(in_channels, out_channels, 3, padding=1, bias=False),
                         nn.BatchNorm2d(out_channels), nn.ReLU(inplace=True))


class DecoderStage(nn.Module):
    """Upsample x2, concatenate the skip feature (if any), two conv blocks."""

    def __init__(self, in_channels: int, skip_channels: int, out_channels: int):
        super().__init__()
        self.convs = nn.Sequential(_conv_block(in_channels + skip_channels, out_channels),
                                   _conv_block(out_channels, out_channels))

    def forward(self, x: torch.Tensor, skip: Optional[torch.Tensor]) -> torch.Tensor:
        x = F.interpolate(x, scale_factor=2.0, mode="nearest")
        if skip is not None:
            x = torch.cat([x, skip], dim=1)
        return self.convs(x)


def _head(in_channels: int, width: int, out_channels: int) -> nn.Sequential:
    """Three convolutions (paper: each head has three conv layers)."""
    return nn.Sequential(nn.Conv2d(in_channels, width, 3, padding=1), nn.ReLU(inplace=True),
                         nn.Conv2d(width, width, 3, padding=1), nn.ReLU(inplace=True),
                         nn.Conv2d(width, out_channels, 1))


class FrontierNet(nn.Module):
    """UNet with a torchvision encoder, a shared decoder and two heads.

    ``forward(x)`` takes the normalised input (B, C, H, W) float32 (see
    :func:`frontiernet.model.predictor.network_input`) and returns

    - ``distance``: (B, 1, H, W) float32, the normalised distance field y >= 0
      (``D = r * exp(-y)`` pixels, :func:`frontiernet.model.predictor.decode_distance`);
    - ``gain_logits``: (B, K, H, W) float32 logits of the gain classes.
    """

    def __init__(self, config: NetworkConfig):
        super().__init__()
        self.config = config
        # every encoder is stem (stride 2), pool, then four layers (strides 4, 8, 16, 32): forward is
        # the same for all, and ResNet parameter names are those of the model files written before
        if config.encoder in FEATURE_ENCODERS:
            skips, deepest = self._feature_encoder(config)
        else:
            resnet = _torchvision_model(config.encoder)
            conv1 = nn.Conv2d(config.in_channels, 64, kernel_size=7, stride=2, padding=3, bias=False)
            self.stem = nn.Sequential(conv1, resnet.bn1, resnet.relu)               # stride 2, 64 ch
            self.pool = resnet.maxpool
            self.layers = nn.ModuleList([resnet.layer1, resnet.layer2, resnet.layer3, resnet.layer4])
            expansion = 4 if config.encoder == "resnet50" else 1
            skips = [64] + [c * expansion for c in (64, 128, 256)]                     # strides 2, 4, 8, 16
            deepest = 512 * expansion                                                  # stride 32
        stages, previous = [], deepest
        for out_channels, skip in zip(config.decoder_channels, [*reversed(skips), 0]):
            stages.append(DecoderStage(previous, skip, out_channels))
            previous = out_channels
        self.decoder = nn.ModuleList(stages)
        self.distance_head = _head(previous, config.head_channels, 1)
        self.gain_head = _head(previous, config.head_channels, config.num_classes)
        self.pad_multiple = int(config.pad_multiple)

    def _feature_encoder(self, config: NetworkConfig) -> tuple[list[int], int]:
        """Stem, pool (identity) and layers from a torchvision model's `features` blocks, split at
        the ends in FEATURE_ENCODERS; the first convolution is rebuilt for the input channels (as
        the ResNet one: same kernel, stride and padding, torch's default initialisation)."""
        features = _torchvision_model(config.encoder).features
        first = features[0][0]
        features[0][0] = nn.Conv2d(config.in_channels, first.out_channels, kernel_size=first.kernel_size,
                                   stride=first.stride, padding=first.padding, bias=False)
        ends = [end for end, _ in FEATURE_ENCODERS[config.encoder]]
        groups = [nn.Sequential(*features[start:end]) for start, end in zip([0, *ends[:-1]], ends)]
        self.stem, self.pool, self.layers = groups[0], nn.Identity(), nn.ModuleList(groups[1:])
        channels = [width for _, width in FEATURE_ENCODERS[config.encoder]]
        return channels[:4], channels[4]

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        # written for TorchScript and ONNX export too: shape arithmetic stays symbolic
        height, width = x.shape[-2], x.shape[-1]
        multiple = self.pad_multiple
        pad_bottom = (multiple - height % multiple) % multiple
        pad_right = (multiple - width % multiple) % multiple
        x = F.pad(x, [0, pad_right, 0, pad_bottom])
        skips: list[torch.Tensor] = [self.stem(x)]
        y = self.pool(skips[0])
        for index, layer in enumerate(self.layers):
            y = layer(y)
            if index < 3:
                skips.append(y)
        for index, stage in enumerate(self.decoder):
            skip: Optional[torch.Tensor] = skips[3 - index] if index < 4 else None
            y = stage(y, skip)
        distance = F.softplus(self.distance_head(y))
        gain_logits = self.gain_head(y)
        return distance[:, :, :height, :width], gain_logits[:, :, :height, :width]


def load_imagenet_encoder(model: FrontierNet, source: str | Path) -> list[str]:
    """Copy ImageNet weights into the encoder of `model`, in place.

    Args:
        source: the torchvision state-dict file of the model's encoder (``resnet18-f37072fd.pth``,
            ``mobilenet_v3_large-8738ca79.pth``, ``efficientnet_b0_rwightman-7f5810bc.pth`` and the
            like), or ``"hub"`` for that file in the torch hub cache. Nothing is downloaded.
    Returns:
        The names of the encoder parameters that were set.
    The first convolution's RGB filters are copied to the RGB channels; a depth channel gets
    their mean (the usual way to extend an RGB encoder).
    """
    path = resolve_pretrained(model.config.encoder, source)
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:  # noqa: BLE001  a corrupt file or a pickle with code in it
        raise InputError(f"{path}: not a loadable torchvision state dict ({error.__class__.__name__})") from None
    resnet = model.config.encoder in RESNET_ENCODERS
    first_conv = "conv1.weight" if resnet else "features.0.0.weight"
    rgb_filters = state.get(first_conv)
    if rgb_filters is None or rgb_filters.shape[1] != 3:
        kind = "ResNet" if resnet else model.config.encoder
        raise InputError(f"{path}: not a torchvision {kind} state dict (no 3-channel {first_conv})")
    inputs = model.config.inputs
    conv1 = {"rgbd": torch.cat([rgb_filters, rgb_filters.mean(1, keepdim=True)], 1),
             "rgb": rgb_filters, "depth": rgb_filters.mean(1, keepdim=True)}[inputs]
    if resnet:
        mapping = {"stem.0.weight": conv1}
        for name, value in state.items():
            if name.startswith("bn1."):
                mapping["stem.1." + name[4:]] = value
            elif name.startswith("layer"):
                index, rest = name[5], name[7:]
                mapping[f"layers.{int(index) - 1}.{rest}"] = value
    else:
        mapping = _feature_encoder_mapping(model.config.encoder, state)
        mapping["stem.0.0.weight"] = conv1
    own = model.state_dict()
    bad = [n for n, v in mapping.items() if n not in own or own[n].shape != v.shape]
    if bad:
        raise InputError(f"{path}: does not fit a {model.config.encoder} encoder (first mismatch: {bad[0]})")
    model.load_state_dict(mapping, strict=False)
    return sorted(mapping)


def _feature_encoder_mapping(encoder: str, state: dict) -> dict:
    """Our names for the `features.{block}.*` tensors of a torchvision state dict (the last block,
    left out of the encoder, and the classifier are skipped)."""
    ends = [end for end, _ in FEATURE_ENCODERS[encoder]]
    place = {}  # block index -> our prefix
    for group, (start, end) in enumerate(zip([0, *ends[:-1]], ends)):
        for block in range(start, end):
            place[block] = f"stem.{block}" if group == 0 else f"layers.{group - 1}.{block - start}"
    mapping = {}
    for name, value in state.items():
        parts = name.split(".", 2)
        if parts[0] == "features" and len(parts) == 3 and parts[1].isdigit() and int(parts[1]) in place:
            mapping[f"{place[int(parts[1])]}.{parts[2]}"] = value
    return mapping


def resolve_pretrained(encoder: str, source: str | Path) -> Path:
    """The ImageNet weights file of ``network.pretrained`` `source` (a path, or ``hub``: the torch hub
    cache's file for `encoder`); InputError naming it when there is none (``train`` asks before its setup)."""
    if str(source) != "hub":
        return input_file(Path(source).expanduser(), "ImageNet weights file, network.pretrained")
    checkpoints = Path(torch.hub.get_dir()) / "checkpoints"
    found = sorted(checkpoints.glob(f"{encoder}[-_]*.pth"))  # efficientnet_b0_rwightman-7f5810bc.pth
    if not found:
        raise InputError(f"network.pretrained=hub: no {encoder}-*.pth or {encoder}_*.pth in {checkpoints}; put "
                         f"torchvision's ImageNet file there (nothing is downloaded) or set network.pretrained=null")
    return found[-1]


SHIPPED_MODELS = {"rgbd": DEFAULT_MODEL, "rgb": "frontiernet_rgb_resnet18.safetensors"}
"""The model file shipped for each input kind (``frontiernet/weights/``): RGB + depth (the default,
the paper's) and RGB only (Table II's row; ``predict --image`` without ``--depth``). The RGB model is
the RGB + depth one fine-tuned on RGB alone with the ResNet's last two stages kept (``train``'s
``init_inputs: rgb``, ``freeze``): its file stores the 2 M weights it changed (4 MB in float16) and
shares the other 10.5 M with the RGB + depth file (:mod:`.files`); a second whole ResNet-18 file
(25 MB) would take the tracked tree past what travels to a GPU node with the wheels it needs."""


def shipped_model_path(inputs: str = "rgbd") -> Path:
    """The shipped model file for input kind `inputs` (``rgbd`` | ``rgb``); InputError when that
    model is not shipped (yet): say what to give instead."""
    if inputs not in SHIPPED_MODELS:
        raise InputError(f"no model is shipped for {inputs!r} input; shipped: {', '.join(SHIPPED_MODELS)}")
    path = shipped_weights_folder() / SHIPPED_MODELS[inputs]
    if not path.is_file():
        given = "an RGB image alone" if inputs == "rgb" else f"{inputs} input"
        raise InputError(f"{path.name}: no shipped model takes {given} in this installation "
                         f"(frontiernet/weights/README.md); give --depth for the RGB + depth model (a depth map, or "
                         f"a monocular model that estimates it from the image: depth_anything_v2, metric3d_v2), "
                         f"or --model FILE")
    return path


def load_model(path: str | Path | None = None) -> tuple[FrontierNet, dict]:
    """Load a model file or training checkpoint (None: the shipped model).

    Returns:
        (model in eval mode on the CPU, float32; its config dict with ``network``, ``input``,
        ``labels``, ``inference`` and ``info``).
    Raises:
        InputError naming the file: missing, corrupt, not a FrontierNet file, weights that
        do not fit the architecture the file declares, or weights that are not all finite.
    """
    path = torch_model_file(default_model_path() if path is None else path)
    state, conf = read_model_file(path)
    try:
        network = NetworkConfig.from_dict(conf["network"])
    except InputError as error:
        raise InputError(f"{path}: {error}") from None
    model = FrontierNet(network)
    state = {name: value.float() if value.is_floating_point() else value for name, value in state.items()}
    own = model.state_dict()
    missing = sorted(set(own) - set(state))
    unexpected = sorted(set(state) - set(own))
    wrong = sorted(n for n in set(own) & set(state) if own[n].shape != state[n].shape)
    if missing or unexpected or wrong:
        first = (missing or unexpected or wrong)[0]
        raise InputError(f"{path}: weights do not fit a {network.encoder}/{network.inputs} FrontierNet "
                         f"({len(missing)} missing, {len(unexpected)} unexpected, {len(wrong)} of another "
                         f"shape; first: {first})")
    model.load_state_dict(state)
    model.eval()
    return model, conf

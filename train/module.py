"""The LightningModule: FrontierNet with its loss, metrics and optimiser (glue-factory style:
the model class owns what it is trained and judged with)."""

from __future__ import annotations

import math

import lightning as L
from lightning.pytorch.callbacks import Callback, Timer
import torch

from frontiernet.errors import InputError
from frontiernet.model import FrontierNet, NetworkConfig, load_imagenet_encoder
from frontiernet.model.files import first_non_finite

from .losses import frontier_loss
from .metrics import FrontierMetrics


def check_schedule(optim: dict, has_max_time: bool) -> None:
    """Refuse, naming the key, an ``optim.schedule`` or ``optim.horizon`` the module cannot follow
    (``has_max_time``: whether ``trainer.max_time`` is set, which the time horizon ends at)."""
    for key, allowed in (("schedule", ("cosine", "constant")), ("horizon", ("steps", "time"))):
        if optim.get(key, allowed[0]) not in allowed:
            raise InputError(f"optim.{key}: must be one of {', '.join(allowed)}, got {optim[key]!r}")
    if optim.get("horizon") == "time" and not has_max_time:
        raise InputError("optim.horizon: 'time' ends the schedule at trainer.max_time, which is not set")


class TrainingDiverged(InputError):
    """Training stopped being finite: the settings make it diverge (a too large ``optim.lr``, a near-zero
    ``model.input`` std); a user error, reported in one line (exit 2)."""


class FiniteTraining(Callback):
    """Stops training where it stops being finite, with :class:`TrainingDiverged` naming the step and the
    keys that usually cause it (`keys`: key -> value): at a training loss that is not finite (before its
    backward pass), and at a checkpoint whose weights or buffers are not (a BatchNorm variance overflows
    while the loss stays finite); so no diverged weights are saved. Without it a diverged run trained to its
    end on NaN and failed only when its weights were read back."""

    def __init__(self, keys: dict):
        self.keys = dict(keys)

    def _diverged(self, trainer, what: str) -> TrainingDiverged:
        settings = ", ".join(f"{key}={value}" for key, value in self.keys.items())
        return TrainingDiverged(f"{what} at step {trainer.global_step + 1} (epoch {trainer.current_epoch + 1}): the "
                                f"settings make training diverge ({settings}); lower optim.lr or correct them. The "
                                "diverged weights were not saved (earlier checkpoints are kept)")

    def on_before_backward(self, trainer, module, loss: torch.Tensor) -> None:
        if not bool(torch.isfinite(loss.detach()).all()):
            raise self._diverged(trainer, f"the training loss became {float(loss.detach().float().mean())}")

    def on_save_checkpoint(self, trainer, module, checkpoint: dict) -> None:
        name = first_non_finite(checkpoint["state_dict"])
        if name is not None:
            raise self._diverged(trainer, f"the network's {name} became NaN or infinite")


class FrontierNetModule(L.LightningModule):
    """Trains :class:`FrontierNet` with ``alpha * L1 + CE + Dice`` and tracks Table II metrics.

    Args:
        model: plain dict, the ``model`` section of the training config (``configs/model.yaml``
            layout: network, input, labels, inference).
        train: plain dict, the ``loss`` and ``optim`` sections and ``max_steps``.
    Both are saved as hyperparameters, so a checkpoint is self-describing and loads with
    ``torch.load(weights_only=True)`` (plain data only).
    """

    def __init__(self, model: dict, train: dict):
        super().__init__()
        self.save_hyperparameters()
        self.net = FrontierNet(NetworkConfig.from_dict(model["network"]))
        pretrained = model["network"].get("pretrained")
        if pretrained:
            load_imagenet_encoder(self.net, pretrained)
        self.metrics = FrontierMetrics(model["labels"])
        self.validated_at_step = -1  # global step of the newest validation (not the sanity check)
        self.channels_last = False  # NHWC weights and inputs (use_channels_last), set before training
        self.frozen: list[torch.nn.Module] = []  # modules kept at their starting values (freeze)

    def freeze(self, modules: list[torch.nn.Module]) -> None:
        """Keep `modules` (their parameters already without gradients: ``train.finetune.freeze``) in eval
        mode whenever the network trains, so that their BatchNorm statistics do not move either."""
        self.frozen = list(modules)
        self.train(self.training)

    def train(self, mode: bool = True):
        super().train(mode)
        for module in getattr(self, "frozen", ()):
            module.eval()
        return self

    def use_channels_last(self, enabled: bool) -> None:
        """Keep the network's weights, and so its activations, in NHWC order (``trainer.channels_last``):
        cuDNN's bf16 / fp16 convolutions run on tensor cores without layout transposes (PyTorch's
        channels-last tutorial). The numbers are the same; only the memory order changes."""
        self.channels_last = bool(enabled)
        self.net.to(memory_format=torch.channels_last if enabled else torch.contiguous_format)

    def forward(self, image: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.net(image)

    def _loss(self, batch: dict) -> tuple[dict, torch.Tensor, torch.Tensor]:
        image = batch["image"]  # (B, C, S, S) float32, normalised (network_batch)
        if self.channels_last:
            image = image.contiguous(memory_format=torch.channels_last)
        distance, logits = self.net(image)
        terms = frontier_loss(distance, logits, batch, self.hparams.train["loss"], self.hparams.model["labels"])
        return terms, distance, logits

    def training_step(self, batch: dict, batch_index: int) -> torch.Tensor:
        terms, _, _ = self._loss(batch)
        size = batch["image"].shape[0]
        self.log_dict({f"train/{name}": value for name, value in terms.items()}, batch_size=size,
                      prog_bar=False, on_step=True, on_epoch=False)
        self.log("loss", terms["loss"], prog_bar=True, logger=False, batch_size=size)
        return terms["loss"]

    def validation_step(self, batch: dict, batch_index: int) -> None:
        terms, distance, logits = self._loss(batch)
        size = batch["image"].shape[0]
        self.log_dict({f"val/{name}": value for name, value in terms.items()}, batch_size=size, sync_dist=True)
        self.metrics.update(distance, logits, batch)

    def on_validation_epoch_end(self) -> None:
        metrics = self.metrics.compute()
        scalars = {f"val/{k}": float(v) for k, v in metrics.items() if isinstance(v, float) and not math.isnan(v)}
        self.log_dict(scalars, sync_dist=False)
        self.log("val_df_error_px", metrics["df_error_px"], prog_bar=True, logger=False)
        self.log("val_gain_dice", metrics["gain_dice"], prog_bar=True, logger=False)
        self.metrics.reset()
        if not self.trainer.sanity_checking:
            self.validated_at_step = self.global_step

    def configure_optimizers(self):
        optim = self.hparams.train["optim"]
        optimizer = torch.optim.AdamW([p for p in self.parameters() if p.requires_grad], lr=float(optim["lr"]),
                                      weight_decay=float(optim["weight_decay"]))
        total = max(int(self.trainer.estimated_stepping_batches), 1)
        warmup = min(int(optim["warmup_steps"]), total // 2)
        schedule = optim["schedule"]
        final = float(optim["final_lr_fraction"])
        horizon = optim.get("horizon", "steps")
        timer = next((c for c in self.trainer.callbacks if isinstance(c, Timer)), None)
        check_schedule(optim, timer is not None and timer.time_remaining() is not None)

        def factor(step: int) -> float:
            if step < warmup:
                return (step + 1) / warmup
            if schedule == "constant":
                return 1.0
            progress = min((step - warmup) / max(total - warmup, 1), 1.0)
            if horizon == "time":  # whichever ends first: the steps or trainer.max_time (training time so far,
                # resumed sessions included, over the whole allowance; Budgeted Training, Li et al., ICLR 2020)
                elapsed = timer.time_elapsed()
                progress = max(progress, min(elapsed / max(elapsed + timer.time_remaining(), 1e-9), 1.0))
            return final + (1.0 - final) * 0.5 * (1.0 + math.cos(math.pi * progress))

        scheduler = torch.optim.lr_scheduler.LambdaLR(optimizer, factor)
        return {"optimizer": optimizer, "lr_scheduler": {"scheduler": scheduler, "interval": "step"}}

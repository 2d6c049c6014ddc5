"""Training the light network: a thin LightningModule, and loading trained weights."""

from __future__ import annotations

import os
from pathlib import Path

import lightning as L
import torch
import torch.nn.functional as F
from hydra.utils import instantiate
from omegaconf import OmegaConf

from unps.errors import InputError
from unps.lightnet.bins import decode_lights, encode_lights
from unps.lightnet.materials import FAMILIES
from unps.lightnet.network import LATE_STRIDES, LightNet
from unps.lightnet.outline import jittered_outlines

SHIPPED = Path(__file__).parent / "weights" / "lightnet.pt"


def batch_light_errors(directions: torch.Tensor, intensities: torch.Tensor, true_directions: torch.Tensor,
                 true_intensities: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-sample direction MAE (degrees) and scale-invariant intensity error.

    Args:
        directions, true_directions: (B, n, 3); intensities, true_intensities: (B, n).

    Returns:
        (B,) and (B,).
    """
    cos = (F.normalize(directions, dim=-1) * true_directions).sum(-1).clamp(-1, 1)
    mae = torch.rad2deg(torch.acos(cos)).mean(-1)
    scale = (true_intensities * intensities).sum(-1) / (intensities ** 2).sum(-1).clamp_min(1e-12)
    error = ((true_intensities - scale[:, None] * intensities).abs() / true_intensities).mean(-1)
    return mae, error


def bin_losses(logits: dict[str, torch.Tensor], directions: torch.Tensor,
               intensities: torch.Tensor) -> dict[str, torch.Tensor]:
    """Cross-entropy of the network's ``azimuth``, ``elevation`` and ``intensity`` logits (B, n, bins)
    against the bins of the true (B, n, 3) directions and (B, n) intensities."""
    targets = encode_lights(directions, intensities)
    return {name: F.cross_entropy(logits[name].flatten(0, 1), target.flatten())
            for name, target in zip(("azimuth", "elevation", "intensity"), targets)}


class LightEstimation(L.LightningModule):
    """Cross-entropy on azimuth, elevation and intensity bins; Adam.

    Args:
        net: the :class:`LightNet`.
        lr: Adam's learning rate.
        lr_milestones: steps after which the learning rate is multiplied by ``lr_gamma``.
        soft_decode: decode predictions by soft-arg-max (else arg-max) for the metrics.
        config: the resolved run config, stored in every checkpoint.
        outline_jitter: the share of each training batch's samples whose outline is perturbed
            before the network sees it (``data.outline_jitter``, :mod:`unps.lightnet.outline`);
            the draws are a function of ``seed`` and the step, so a resumed run goes on as it ran.
        seed: the run's seed.
    """

    def __init__(self, net: LightNet, lr: float = 5e-4, lr_milestones: tuple[int, ...] = (),
                 lr_gamma: float = 0.3, soft_decode: bool = True, config: dict | None = None,
                 outline_jitter: float = 0.0, seed: int = 0):
        super().__init__()
        self.net, self.lr, self.soft_decode = net, lr, soft_decode
        self.lr_milestones, self.lr_gamma = list(lr_milestones), lr_gamma
        self.config = config or {}
        self.outline_jitter, self.seed = outline_jitter, seed

    def forward(self, images, mask):
        return self.net(images, mask)

    def _step(self, batch, stage: str):
        logits = {k: v.float() for k, v in self.net(batch["images"], batch["mask"]).items()}   # bf16-mixed
        losses = bin_losses(logits, batch["directions"], batch["intensities"])
        loss = sum(losses.values())
        directions, intensities = decode_lights(logits["azimuth"], logits["elevation"],
                                                logits["intensity"], self.soft_decode)
        mae, int_err = batch_light_errors(directions, intensities, batch["directions"],
                                    batch["intensities"])
        log = dict(batch_size=len(mae), on_step=stage == "train", on_epoch=stage != "train")
        self.log(f"{stage}/loss", loss, **log)
        self.log(f"{stage}/direction_mae", mae.mean(), **log)
        self.log(f"{stage}/intensity_error", int_err.mean(), **log)
        for name, value in losses.items():
            self.log(f"{stage}/loss_{name}", value, batch_size=len(mae), on_step=stage == "train",
                     on_epoch=stage != "train")
        if stage == "val":
            for code, family in enumerate(FAMILIES):
                pick = batch["family"] == code
                if pick.any():
                    self.log(f"val/{family}/direction_mae", mae[pick].mean(), batch_size=int(pick.sum()))
                    self.log(f"val/{family}/intensity_error", int_err[pick].mean(),
                             batch_size=int(pick.sum()))
        return {"loss": loss, "directions": directions, "intensities": intensities}

    def training_step(self, batch, batch_index):
        if self.outline_jitter > 0:
            generator = torch.Generator(device=batch["mask"].device)
            generator.manual_seed(self.seed * 1_000_003 + self.global_step)   # resumes as it ran
            images, mask = jittered_outlines(batch["images"], batch["mask"], self.outline_jitter, generator)
            batch = {**batch, "images": images, "mask": mask}
        return self._step(batch, "train")["loss"]

    def validation_step(self, batch, batch_index):
        return self._step(batch, "val")

    def configure_optimizers(self):
        optimizer = torch.optim.Adam(self.net.parameters(), lr=self.lr)
        schedule = torch.optim.lr_scheduler.MultiStepLR(optimizer, self.lr_milestones, self.lr_gamma)
        return {"optimizer": optimizer, "lr_scheduler": {"scheduler": schedule, "interval": "step"}}

    def on_save_checkpoint(self, checkpoint: dict) -> None:
        checkpoint["unps_config"] = self.config


def network_config(config: dict) -> dict:
    """A run config's ``light`` node, with the strides of the networks saved before the node
    named them (:data:`LATE_STRIDES`)."""
    return {"strides": list(LATE_STRIDES), **config["light"]}


def build_net(config: dict) -> LightNet:
    """The network a run config describes (its ``light`` node)."""
    return instantiate(OmegaConf.create(network_config(config)), _partial_=True)()


def load_lightnet(path: str | os.PathLike | None = None) -> tuple[LightNet, dict]:
    """A trained light network and the config it was trained with.

    Args:
        path: a Lightning checkpoint of ``unps.train`` or a file written by
            :func:`export_weights`; default: the weights shipped with unps.
    """
    path = Path(path).expanduser() if path else SHIPPED
    if not path.is_file():
        raise InputError(f"{path}: light-network weights not found")
    try:
        saved = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as e:  # torch raises several types for foreign files
        raise InputError(f"{path}: not a light-network checkpoint ({e})") from None
    if not isinstance(saved, dict) or "unps_config" not in saved:
        raise InputError(f"{path}: not a unps light-network checkpoint (no unps_config inside)")
    net = build_net(saved["unps_config"])
    state = saved["state_dict"]
    if any(k.startswith("net.") for k in state):
        state = {k.removeprefix("net."): v for k, v in state.items() if k.startswith("net.")}
    net.load_state_dict({k: v.float() for k, v in state.items()})
    return net.eval(), saved["unps_config"]


def export_weights(checkpoint: str | os.PathLike, out: str | os.PathLike, notes: dict) -> Path:
    """Write a slim weights file (float16 network, run config, ``notes``) from a checkpoint."""
    from unps.io.files import atomic_path

    saved = torch.load(checkpoint, map_location="cpu", weights_only=False)
    state = {k.removeprefix("net."): v.half() for k, v in saved["state_dict"].items()
             if k.startswith("net.")}
    with atomic_path(out) as tmp:
        torch.save({"state_dict": state, "unps_config": saved["unps_config"], "notes": notes}, tmp)
    return Path(out)

"""The per-subject optimisation: a thin LightningModule around the inverse-rendering networks.

Every step renders a batch of images through the physical model

    X̃_i = s_i · V_i ⊙ ρ_i ⊙ max(N_ny · l_i, 0),

ρ_i = f_sp(X_i + noise, R_i(N_o, l_i), features), N_o = ξ_n1(ξ_f(X)), N_ny = ξ_n2(N_o) (or N_o with
interreflections off), and compares it with the observed X_i. The images are divided by their
light intensities, so s_i = 1 unless the lights are refined (then s_i and l_i are learnt).
V_i is 1, or, with cast shadows on (beyond the paper), 0 where the depth integrated from N_o at
the last update hides the pixel from light i.

Frame: x right, y up, z toward the camera; light directions point from the surface to the light.
"""

from __future__ import annotations

import math

import lightning as L
import numpy as np
import torch
import torch.nn.functional as F

from unps.errors import Diverged
from unps.geometry import cast_shadows, integrate_normals
from unps.inverse.rng import restore_rng, rng_state
from unps.inverse.schedule import Schedule
from unps.inverse.interreflection import Interreflection
from unps.inverse.networks import NormalNet, ReflectanceNet, normal_net_input, shading, specular_map
from unps.timing import Span, stage


def visibility(normals: np.ndarray, mask: np.ndarray, directions: torch.Tensor) -> torch.Tensor:
    """V: 1 where each light reaches a pixel, 0 where the surface of ``normals`` shadows it.

    Args:
        normals: (H, W, 3) unit normals; their depth is integrated (in pixels) and marched
            toward each light with one sample per pixel of the grid's diagonal.
        mask: (H, W) bool.
        directions: (n, 3) unit, surface to light; the shadows are marched on their device.

    Returns:
        (n, 1, H, W) float32, on ``directions``' device.
    """
    device = directions.device
    depth = torch.as_tensor(np.nan_to_num(integrate_normals(normals, mask)), dtype=torch.float32,
                            device=device)
    h, w = mask.shape
    hidden = cast_shadows(depth, torch.as_tensor(mask, device=device), directions.detach().float(), 1.0,
                          int(np.ceil(np.hypot(h, w))))
    return (~hidden).float()[:, None]


def residual_weight(images: torch.Tensor, mask: torch.Tensor, residual: str,
                    albedo: torch.Tensor | None = None, floor: float = 0.1) -> torch.Tensor:
    """Each pixel's weight in the L1 loss (``preset.residual``).

    Args:
        images: (n, 3, H, W) observed images.
        mask: (1, 1, H, W) float, 1 on the object.
        residual: ``absolute``: every pixel 1; ``relative``: 1 / the pixel's mean brightness over
            the images and channels, that brightness floored at ``floor`` × its median over the
            object; ``sqrt``: 1 / √(that floored brightness); ``albedo``: 1 / ``albedo``, floored
            the same way (the residual in shading units: a dark material counts as much as a
            bright one, a pixel dark because the shape hides it from the lights does not). The
            weights are scaled to mean 1 over the object and are 0 off it.
        albedo: (1, 1, H, W) the initialisation's albedo (any scale), for ``albedo``.

    Returns:
        (1, 1, H, W) weights.

    Example:
        >>> images = torch.tensor([1.0, 0.5, 0.25]).view(1, 1, 1, 3).expand(2, 3, 1, 3)
        >>> weight = residual_weight(images, torch.ones(1, 1, 1, 3), "relative")
        >>> [round(w, 4) for w in weight.flatten().tolist()]    # 1 : 2 : 4, mean 1
        [0.4286, 0.8571, 1.7143]
    """
    if residual == "absolute":
        return torch.ones_like(mask)
    if residual == "albedo":
        if albedo is None:
            raise ValueError("residual='albedo' needs the albedo")
        brightness = albedo
    else:
        brightness = images.mean((0, 1), keepdim=True)
    least = floor * brightness[mask > 0].median()
    weight = 1 / brightness.clamp_min(float(least) if least > 0 else 1e-12)
    if residual == "sqrt":
        weight = weight.sqrt()
    return weight * mask * mask.sum() / (weight * mask).sum()


DARK_SHARE = 0.2
"""A pixel whose initial albedo is under this share of the object's median is of a dark material
(black phenolic beside white paint), held toward N_init by ``preset.dark_hold``."""


def dark_weight(albedo: torch.Tensor | None, mask: torch.Tensor, share: float = DARK_SHARE) -> torch.Tensor:
    """Each pixel's weight in the hold toward N_init (``preset.dark_hold``): 1 − albedo / (``share``
    × the object's median albedo), clamped to [0, 1]: 1 where the albedo is 0, none from ``share``
    of the median up, and 0 off the object.

    Args:
        albedo: (1, 1, H, W) the initialisation's albedo (any scale); None: nothing is held.
        mask: (1, 1, H, W) float, 1 on the object.

    Returns:
        (1, 1, H, W) weights in [0, 1].

    Example:
        >>> albedo = torch.tensor([0.0, 0.05, 0.1, 0.5, 1.0, 1.0, 1.0]).view(1, 1, 1, 7)
        >>> dark_weight(albedo, torch.ones(1, 1, 1, 7)).flatten().tolist()    # median 0.5
        [1.0, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0]
    """
    if albedo is None:
        return torch.zeros_like(mask)
    least = share * albedo[mask > 0].median()
    return (1 - albedo / least.clamp_min(1e-12)).clamp(0, 1) * mask


def reconstruction_error(reconstruction: torch.Tensor, observed: torch.Tensor,
                         headroom: torch.Tensor | None = None) -> torch.Tensor:
    """Each value's absolute error |X̃ − X|, or, with a ``headroom`` h, its distance to the
    interval [X, X + h] that the value may stand for (a value read as 0 is any light below the
    first level). (B, 3, H, W) each; h ≥ 0.

    Example:
        >>> observed, headroom = torch.tensor([0.0, 0.0, 0.5]), torch.tensor([0.1, 0.1, 0.0])
        >>> reconstruction_error(torch.tensor([0.05, 0.3, 0.4]), observed, headroom)
        tensor([0.0000, 0.2000, 0.1000])
    """
    difference = reconstruction - observed
    if headroom is None:
        return difference.abs()
    return (difference - headroom).clamp_min(0) + (-difference).clamp_min(0)


def without_common_rotation(offsets: torch.Tensor, lights: torch.Tensor) -> torch.Tensor:
    """Light offsets less the part that turns all the lights together.

    A small rotation ω of every light moves light i by ω × l_i; the ω whose moves are nearest
    ``offsets`` in least squares solves Σ(I − l_i l_iᵀ) ω = Σ l_i × o_i, and its moves are taken
    away. Linear in ``offsets``, so the gradient is projected alike.

    Args:
        offsets: (n, 3) additive offsets to the unit directions, camera frame.
        lights: (n, 3) unit directions, camera frame; not all parallel.

    Returns:
        (n, 3) the offsets with no common rotation left (to first order).

    Example:
        >>> lights = torch.nn.functional.normalize(torch.tensor([[0., 0, 1], [1, 0, 1], [0, 1, 1]]), dim=1)
        >>> turn = torch.cross(torch.tensor([0.01, -0.02, 0.03]).expand(3, 3), lights, dim=1)
        >>> bool(without_common_rotation(turn, lights).abs().max() < 1e-7)
        True
    """
    eye = torch.eye(3, dtype=lights.dtype, device=lights.device)
    moment = (eye - lights[:, :, None] * lights[:, None, :]).sum(0)
    omega = torch.linalg.solve(moment, torch.cross(lights, offsets, dim=1).sum(0))
    return offsets - torch.cross(omega.expand_as(lights), lights, dim=1)


class InverseRendering(L.LightningModule):
    """Loss, optimiser and logging of one subject's fit.

    The loss is the L1 reconstruction error over a random ``pixel_keep`` share of the object's
    pixels (clipped values left out), plus, for the first ``prior_steps`` steps,
    ``prior_weight``·mean‖N_o − N_init‖²:
    networks initialised at random produce arbitrary normals, and without this pull the
    reflectance network can explain the images with any of them; Taniai & Maehara found a weight
    of 0.1 for 50 of 1000 steps enough to start in the robust initialisation's basin, and short
    enough not to keep its errors (shadows and highlights the reflectance maps then explain).
    After it, ``dark_hold``·Σ w‖N_o − N_init‖² / (object pixels) keeps the pixels of a dark
    material near N_init, w their :func:`dark_weight` (beyond the paper): the L1 loss hardly feels
    their normals, and a network shared with a bright material moves them at will. In every step,
    ``highlight_hold``·Σ‖N_o − h‖² / (object pixels) pulls the pixels lit by a specular highlight
    toward its half vector h (beyond the paper, :meth:`pull_toward_highlights`): the L1 loss takes
    their bright images for outliers.

    Args:
        normal_net, reflectance_net: the networks.
        images: (n, 3, H, W) images divided by their intensities and by their 99th percentile
            over the object.
        mask: (H, W) bool.
        light_directions: (n, 3) unit.
        init_normals: (3, H, W) robust-initialisation normals N_init.
        interreflection: ξ_n2, or None to render with N_o.
        schedule: the hyper-parameters.
        refine_lights: learn per-image directions and intensity scales, starting from the given.
        true_normals: (3, H, W) ground truth, for the progress bar's MAE only.
        fingerprint: identifies the run; stored in checkpoints so a resume cannot mix runs.
        usable: (n, 1, H, W) 1 where a value may enter the loss, 0 where it is clipped; None: all.
        headroom: (n, 3, H, W) how much brighter than read each value may be (values read as 0,
            ``preset.censor_black``; :func:`unps.inverse.grids.black_headroom`), in the units of
            ``images``: a rendering between a value and its headroom costs nothing; None: none.
        shadows: render the shadows that the current surface casts (V_i above).
        albedo: (1, 1, H, W) the initialisation's albedo, for ``preset.residual=albedo`` and the
            hold on dark materials.
        precision: ``bf16-mixed`` runs both networks under bfloat16 autocast (``preset.precision``).
        highlit: (H, W) long, the image whose light shows each pixel a specular highlight, −1
            where none does (``preset.highlight_hold``); None: none.
    """

    log_every = 10
    """Steps between the figures the logger writes (the trainer's ``log_every_n_steps``)."""

    def __init__(self, normal_net: NormalNet, reflectance_net: ReflectanceNet, images: torch.Tensor,
                 mask: np.ndarray, light_directions: torch.Tensor, init_normals: torch.Tensor,
                 interreflection: Interreflection | None, schedule: Schedule,
                 refine_lights: bool = False, true_normals: torch.Tensor | None = None,
                 fingerprint: str = "", usable: torch.Tensor | None = None, shadows: bool = False,
                 albedo: torch.Tensor | None = None, precision: str = "32-true",
                 headroom: torch.Tensor | None = None, highlit: torch.Tensor | None = None):
        super().__init__()
        self.networks_in_bf16 = precision == "bf16-mixed"
        self.normal_net, self.reflectance_net = normal_net, reflectance_net
        self.schedule, self.interreflection = schedule, interreflection
        self.refine_lights, self.fingerprint, self.shadows = refine_lights, fingerprint, shadows
        self._resumed_rng: dict | None = None   # a checkpoint's RNG state, until the next step
        self._update_source: np.ndarray | None = None   # (H, W, 3) N_o of the last update
        self.mask_np = mask
        channels_last = torch.channels_last
        self.register_buffer("images", images.contiguous(memory_format=channels_last), persistent=False)
        self.register_buffer("mask", torch.as_tensor(mask, dtype=torch.float32)[None, None],
                             persistent=False)
        self.register_buffer("normal_input", normal_net_input(images, self.mask[0, 0]), persistent=False)
        self.register_buffer("initial_lights", light_directions, persistent=False)
        self.register_buffer("init_normals", init_normals[None], persistent=False)
        self.register_buffer("usable", None if usable is None
                             else usable.contiguous(memory_format=channels_last), persistent=False)
        self.register_buffer("headroom", None if headroom is None
                             else headroom.contiguous(memory_format=channels_last), persistent=False)
        self.register_buffer("true_normals", None if true_normals is None else true_normals[None],
                             persistent=False)
        self.register_buffer("visible", torch.ones(images.shape[0], 1, *mask.shape), persistent=False)
        self.register_buffer("first_bad", torch.tensor([-1.0, 0.0]), persistent=False)   # (step, loss)
        self.register_buffer("pixel_weight", residual_weight(images, self.mask, schedule.residual, albedo),
                             persistent=False)
        self.register_buffer("dark_weight", dark_weight(albedo, self.mask), persistent=False)
        self.holds_dark = schedule.dark_hold > 0 and bool(self.dark_weight.any())
        highlit = torch.full(mask.shape, -1) if highlit is None else highlit.long()
        self.register_buffer("highlit", highlit, persistent=False)
        self.holds_highlights = schedule.highlight_hold > 0 and bool((highlit >= 0).any())
        n = images.shape[0]
        self.light_offsets = torch.nn.Parameter(torch.zeros(n, 3), requires_grad=refine_lights)
        self.light_log_scales = torch.nn.Parameter(torch.zeros(n), requires_grad=refine_lights)
        self.normal_net.to(memory_format=channels_last)
        self.reflectance_net.to(memory_format=channels_last)
        self._backward, self._optimiser = Span("backward"), Span("optimiser")

    # -- the model -----------------------------------------------------------------------------

    def lights(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(n, 3) unit directions and (n,) intensity scales with geometric mean 1; with
        ``hold_light_frame`` the directions keep the given lights' frame
        (:func:`without_common_rotation`)."""
        offsets = self.light_offsets
        if self.schedule.hold_light_frame:
            offsets = without_common_rotation(offsets, self.initial_lights)
        directions = F.normalize(self.initial_lights + offsets, dim=1)
        scales = torch.exp(self.light_log_scales - self.light_log_scales.mean())
        return directions, scales

    def normals(self) -> tuple[torch.Tensor, torch.Tensor]:
        """N_o (1, 3, H, W) and the global features."""
        with self.network_precision():
            return self.normal_net(self.normal_input)

    def network_precision(self) -> torch.autocast:
        """bfloat16 autocast on the module's device with ``preset.precision=bf16-mixed``, else off."""
        return torch.autocast(self.device.type, dtype=torch.bfloat16, enabled=self.networks_in_bf16)

    def render(self, index: torch.Tensor, noise: bool = True) -> dict[str, torch.Tensor]:
        """Reconstruct images ``index``: (B,) → dict of (B, C, H, W) maps and N_o, N_ny."""
        with stage("normal network"):
            normals, features = self.normals()
        with stage("interreflection solve"):
            pseudo = self.interreflection(normals) if self.interreflection is not None else normals
        directions, scales = self.lights()
        lights = directions[index]
        observed = self.images[index]
        inputs = observed
        if noise and self.schedule.input_noise_var > 0:
            # drawn contiguous: randn_like would draw in the channels-last layout, 8× slower on CPU
            noise_draw = torch.randn(observed.shape, dtype=observed.dtype, device=observed.device)
            inputs = observed + math.sqrt(self.schedule.input_noise_var) * noise_draw
        with stage("reflectance network"):
            specular = specular_map(normals, lights)
            with self.network_precision():
                reflectance = self.reflectance_net(inputs * self.mask, specular,
                                                   self.reflectance_net.global_term(features))
        reconstruction = (scales[index, None, None, None] * self.visible[index] * reflectance
                          * shading(pseudo, lights))
        return {"normals": normals, "pseudo_normals": pseudo, "reflectance": reflectance,
                "reconstruction": reconstruction, "observed": observed, "specular": specular}

    # -- Lightning -----------------------------------------------------------------------------

    def on_train_batch_start(self, batch, batch_idx) -> None:
        if self._resumed_rng is not None:   # here, as the data loader draws from it on resume
            restore_rng(self._resumed_rng, self.device)
            self._resumed_rng = None
        updating = self.interreflection is not None or self.shadows
        if updating and self.global_step % self.schedule.update_every == 0:
            if self.global_step == 0:
                source = self.init_normals
            else:
                with torch.no_grad():
                    source = self.normals()[0]
            self._update(source[0].permute(1, 2, 0).double().cpu().numpy())

    def on_before_backward(self, loss) -> None:
        self._backward.start()

    def on_after_backward(self) -> None:
        self._backward.stop()

    def on_before_optimizer_step(self, optimizer) -> None:
        self._optimiser.start()

    def optimizer_step(self, *args, **kwargs) -> None:
        super().optimizer_step(*args, **kwargs)   # runs training_step and backward first
        self._optimiser.stop()

    def _update(self, normals: np.ndarray) -> None:
        """Refresh the interreflection solve and the cast shadows from (H, W, 3) normals, kept
        for checkpoints."""
        if self.interreflection is not None:
            with stage("interreflection update"):
                self.interreflection.update(normals, self.device)
        if self.shadows:
            with stage("cast shadows"):
                self.visible = visibility(normals, self.mask_np, self.lights()[0]).to(self.visible)
        self._update_source = normals

    def training_step(self, batch, batch_idx):
        s = self.schedule
        n = self.images.shape[0]
        count = n if s.images_per_step is None else min(s.images_per_step, n)
        index = torch.randperm(n, device=self.device)[:count]
        out = self.render(index)
        keep = self.mask * (torch.rand_like(self.mask) < s.pixel_keep)
        keep = torch.where(keep.sum() > 0, keep, self.mask)          # none kept: all (nothing waits)
        if self.usable is not None:
            keep = keep * self.usable[index]                     # (B, 1, H, W): clipped values out
        residual = reconstruction_error(out["reconstruction"], out["observed"],
                                        None if self.headroom is None else self.headroom[index])
        residual = residual * (keep * self.pixel_weight)
        loss = residual.sum() / (keep.expand(count, 1, -1, -1).sum().clamp_min(1) * 3)
        figures = {"loss/reconstruction": loss}
        if self.global_step < s.prior_steps and s.prior_weight > 0:
            prior = self.pull_toward_start(out["normals"], self.mask)
            loss = loss + s.prior_weight * prior
            figures["loss/prior"] = prior
        elif self.holds_dark:
            hold = self.pull_toward_start(out["normals"], self.dark_weight)
            loss = loss + s.dark_hold * hold
            figures["loss/dark_hold"] = hold
        if self.holds_highlights:
            hold = self.pull_toward_highlights(out["normals"])
            loss = loss + s.highlight_hold * hold
            figures["loss/highlight_hold"] = hold
        self.watch_divergence(loss)
        if self.figures_read():
            for name, value in figures.items():
                self.log(name, value)
            if self.true_normals is not None:
                self.log("mae", self.normal_mae(out["normals"].detach()))
            if self.refine_lights:
                self.log("light/offset_deg", torch.rad2deg(torch.acos(
                    (self.lights()[0] * self.initial_lights).sum(1).clamp(-1, 1))).mean())
        return loss

    def figures_read(self) -> bool:
        """Whether anything reads this step's logged figures: the logger writes every
        ``log_every`` steps, the progress line and the stall watch read every ``update_every``
        and the last. The other steps log nothing, which spares Lightning's bookkeeping of each
        figure (about a millisecond each on a CPU, a few percent of a fast-preset step)."""
        done = self.global_step + 1
        return (done % self.log_every == 0 or done % self.schedule.update_every == 0
                or done >= self.schedule.steps)

    def pull_toward_start(self, normals: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
        """Σ weight·‖N_o − N_init‖² over the pixels, divided by the object's pixel count;
        ``normals`` (1, 3, H, W) N_o, ``weight`` (1, 1, H, W)."""
        return (((normals - self.init_normals) ** 2).sum(1, keepdim=True) * weight).sum() / self.mask.sum()

    def pull_toward_highlights(self, normals: torch.Tensor) -> torch.Tensor:
        """Σ ‖N_o − h‖² over the pixels lit by a highlight, divided by the object's pixel count;
        h the half vector of the view (+z) and the current light of the pixel's highlit image
        (held fixed: the pull moves the normals, not the lights). ``normals`` (1, 3, H, W) N_o."""
        lit = self.highlit >= 0
        with torch.no_grad():
            lights = self.lights()[0][self.highlit[lit]]                              # (P, 3)
            half = F.normalize(lights + lights.new_tensor([0.0, 0.0, 1.0]), dim=-1)
        return ((normals[0][:, lit].T - half) ** 2).sum() / self.mask.sum()

    def watch_divergence(self, loss: torch.Tensor) -> None:
        """Note the first step whose loss is not finite, and stop the fit there before its next
        checkpoint. Only the steps before a checkpoint and the last read the note (on a GPU,
        reading it waits for the device; every step would keep the GPU idle between steps).

        Raises:
            Diverged: the loss was not finite at a step since the last checkpoint.
        """
        s = self.schedule
        loss = loss.detach()
        bad = ~torch.isfinite(loss) & (self.first_bad[0] < 0)
        step = torch.full_like(loss, float(self.global_step))
        self.first_bad = torch.where(bad, torch.stack([step, loss]), self.first_bad)
        if (self.global_step + 1) % s.update_every == 0 or self.global_step + 1 >= s.steps:
            first, value = self.first_bad.tolist()
            if first >= 0:
                raise Diverged(f"the loss became {value} at step {int(first)}")

    def normal_mae(self, normals: torch.Tensor) -> torch.Tensor:
        """Mean angular error (degrees) of (1, 3, H, W) normals over the mask."""
        cos = (normals * self.true_normals).sum(1, keepdim=True).clamp(-1, 1)
        return (torch.rad2deg(torch.acos(cos)) * self.mask).sum() / self.mask.sum()

    def configure_optimizers(self):
        s = self.schedule
        groups = [{"params": self.normal_net.parameters(), "lr": s.normal_lr or s.lr},
                  {"params": self.reflectance_net.parameters(), "lr": s.lr}]
        if self.refine_lights:
            groups.append({"params": [self.light_offsets, self.light_log_scales], "lr": s.lr})
        # foreach: each group's tensors updated together, the same numbers as one at a time (a CPU's
        # default) in a fifth less time
        optimiser = torch.optim.Adam(groups, foreach=True)
        drop = torch.optim.lr_scheduler.MultiStepLR(optimiser, milestones=[s.lr_drop_at], gamma=0.1)
        return {"optimizer": optimiser, "lr_scheduler": {"scheduler": drop, "interval": "step"}}

    def on_save_checkpoint(self, checkpoint: dict) -> None:
        checkpoint["unps_fingerprint"] = self.fingerprint
        checkpoint["unps_rng"] = rng_state(self.device)
        if self._update_source is not None:   # a tensor: checkpoints load weights-only
            checkpoint["unps_update_source"] = torch.from_numpy(self._update_source)
        if self.shadows:                      # cast with the lights of then, refined or not
            checkpoint["unps_visible"] = self.visible.cpu()

    def on_load_checkpoint(self, checkpoint: dict) -> None:
        """Restore the generators, the interreflection solve and the cast shadows as they were
        saved, so that a finished fit, which runs no step when resumed, reads out exactly as it
        ended."""
        self._resumed_rng = checkpoint.get("unps_rng")
        source = checkpoint.get("unps_update_source")
        if source is not None:
            self._update(source.numpy())
        if "unps_visible" in checkpoint:
            self.visible = checkpoint["unps_visible"].to(self.visible)

    def train_dataloader(self):
        return torch.utils.data.DataLoader(range(self.schedule.steps), batch_size=None)

    def transfer_batch_to_device(self, batch, device, dataloader_idx):
        """The step counter stays where it is: no step reads it, and copying it to a GPU would
        make each step wait for the one before."""
        return batch

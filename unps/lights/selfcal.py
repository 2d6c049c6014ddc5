"""Self-calibration (``light=selfcal``): the lights fitted to the images themselves.

Starting from a first guess (the light network's estimate,
:func:`unps.lightnet.estimate.network_lights`), the lights are fitted jointly with a depth map,
an RGB albedo and shared specular lobes
(:class:`unps.lights.model.SelfCalibrationModel`) so that the rendered images match the captured
ones, in the spirit of SCPS-NIR (Li & Li, ECCV 2022) but with an explicit reflectance model small
enough for a CPU:

1. the images' low-rank part gives scaled normals and per-light corrections in the frame of the
   first guess (:func:`unps.lights.factorization.aligned_factorization`);
2. on a working grid of at most ``max_pixels`` object pixels, the depth integrated from those
   normals, the albedo, lobes, one 3×3 frame and small per-light residuals are fitted with Adam
   under an L1 loss, which lets saturated pixels and interreflections go rather than drag the
   fit; the shadows that the current depth casts from the current lights are rendered, and
   marched again every ``shadows_every`` steps;
3. a shorter fit of the same model with the lights held where step 1 put them gives the loss
   the first guess can reach; a fit that ends above it, or diverges, returns the first guess
   with a warning.

Frame: x right (+col), y up (−row), z toward the camera; orthographic view along +z.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import torch

from unps.data.lights import Verdict
from unps.data.subject import Subject
from unps.errors import InputError
from unps.geometry import integrate_normals
from unps.lights import Lights, with_lights
from unps.lights.factorization import aligned_factorization, held_factorization
from unps.lights.model import SelfCalibrationModel
from unps.metrics import angular_error

log = logging.getLogger(__name__)

MIN_IMAGES = 4
START_ALBEDO = 0.6   # the images are scaled to a 99th percentile of 1


@dataclass(frozen=True)
class SelfCalibration:
    """Settings of the self-calibration fit.

    Attributes:
        steps: Adam steps of the fit.
        reference_steps: steps of the reference fit, with the lights held at the first guess
            (its per-light errors removed by the factorization).
        max_pixels: object pixels on the working grid at most (blocks are averaged).
        levels: scales of the depth pyramid.
        sharpness: the specular lobes' κ (spherical Gaussians on n·h).
        lr: learning rate of depth, albedo and lobes.
        lr_lights: learning rate of the light frame and per-light residuals.
        residual_weight: weight of the mean squared per-light residual |ε_i|².
        gbr_weight: weight of the pull of the bas-relief parameters (μ, ν, λ) toward (0, 0, 1).
        shadows_every: steps between updates of the cast shadows (which pixels the current depth
            hides from each current light); 0 renders none.
        prior_weight: weight of the pull of each fitted direction toward the first guess's,
            mean over the lights of θ_i² / (σ₀² + s_i²) (θ_i the angle between them, s_i the
            spread of the light network's passes for light i, σ₀ ``prior_floor_deg``, all in
            radians): a light moves only as far as the images pin it, and further where the
            network is unsure. 0: no pull.
        prior_floor_deg: σ₀, the first guess's error where its passes agree.
        prior_intensity: σ_e, the first guess's relative intensity error: the pull on each light's
            intensity is (log e_i − log e_i⁰)² / σ_e², with the same weight.
        start: ``factorization``: the fit starts from the lights of the images' low-rank part in
            the first guess's frame (:func:`unps.lights.factorization.aligned_factorization`);
            ``first_guess``: from the first guess itself, the surface from the low-rank part
            under it.
        gloss_per_pixel: each pixel scales the shared specular lobes by its own factor
            (:class:`unps.lights.model.SelfCalibrationModel`).
        log_every: steps between progress lines.
    """

    steps: int = 1500
    reference_steps: int = 300
    max_pixels: int = 4000
    levels: int = 4
    sharpness: tuple[float, ...] = (10.0, 30.0, 100.0, 300.0)
    lr: float = 0.01
    lr_lights: float = 0.003
    residual_weight: float = 0.1
    gbr_weight: float = 0.003
    shadows_every: int = 100
    prior_weight: float = 0.0
    prior_floor_deg: float = 3.0
    prior_intensity: float = 0.1
    start: str = "factorization"
    gloss_per_pixel: bool = False
    log_every: int = 500

    name: ClassVar[str] = "selfcal"

    def __call__(self, subject: Subject, lights: Lights) -> tuple[Lights, Verdict]:
        """The light stage: :func:`self_calibrate` with these settings."""
        return self_calibrate(subject, lights, self)


def self_calibrate(subject: Subject, lights: Lights,
                   settings: SelfCalibration = SelfCalibration()) -> tuple[Lights, Verdict]:
    """The lights that best explain the subject's captured images, starting from ``lights``.

    Args:
        subject: its captured images (``observed_images()``) and mask are used.
        lights: the first guess, (n, 3) unit directions and (n, 3) intensities (or None: 1).

    Raises:
        InputError: fewer than 4 images, or no light reaching the object in any image.

    Returns:
        Lights with (n, 3) unit directions and (n, 3) intensities (the first guess's RGB
        intensities times one fitted scale per image; geometric mean of the scales 1), or
        ``lights`` itself when the fit does not explain the images better; and the verdict.
    """
    if settings.shadows_every < 0 or int(settings.shadows_every) != settings.shadows_every:
        raise InputError(f"light.selfcal.shadows_every must be a whole number of steps >= 0 (0: no "
                         f"cast shadows), got {settings.shadows_every}")
    if subject.n_images < MIN_IMAGES:
        raise InputError(f"self-calibration needs at least {MIN_IMAGES} images, "
                         f"{subject.name!r} has {subject.n_images}: use light=estimated (the "
                         f"network's lights) or light=gt")
    start = time.perf_counter()
    observed = with_lights(subject, lights)
    gray = observed.images[:, subject.mask].mean(-1).T.astype(np.float64)       # (m, n)
    if not np.any(gray > 0):
        raise InputError(f"self-calibration of {subject.name!r}: every image is black on the "
                         f"object, so the images say nothing about the lights")
    if settings.start == "factorization":
        scaled_normals, scaled_lights = aligned_factorization(gray, lights.directions)
    elif settings.start == "first_guess":              # the images are divided by its intensities
        scaled_lights = lights.directions.astype(np.float64)
        scaled_normals = held_factorization(gray, scaled_lights)
    else:
        raise InputError(f"light.selfcal.start must be factorization or first_guess, got "
                         f"{settings.start!r}")
    grid = working_grid(observed, scaled_normals, settings.max_pixels)
    target = torch.as_tensor(grid.images[:, grid.mask]).permute(1, 0, 2).float()  # (m, n, 3)
    target = target / torch.quantile(target.flatten()[::7], 0.99).clamp_min(1e-12)
    reference = initial_model(grid, target, scaled_lights, settings)
    reachable = fit(reference, target, settings, settings.reference_steps, lights_free=False)
    model = initial_model(grid, target, scaled_lights, settings)
    final = fit(model, target, settings, settings.steps, pull=first_guess_pull(lights, settings))
    directions, scales = (t.detach().numpy().astype(np.float64) for t in model.lights())
    moved = float(angular_error(directions, lights.directions).mean())
    evidence = {"loss": final, "reference_loss": reachable, "moved_deg": moved}
    if not (np.isfinite(final) and final < reachable and np.all(np.isfinite(directions))):
        log.warning("self-calibration of %s did not explain the images better than its first "
                    "guess (loss %.4g against %.4g); keeping the first guess", subject.name, final,
                    reachable)
        return lights, Verdict(settings.name, "declined", f"the fit did not explain the images "
                               f"better than its first guess (loss {final:.4g} against "
                               f"{reachable:.4g})", evidence)
    log.info("self-calibrated %d lights on %d pixels in %.1f s: loss %.4g (first guess %.4g), "
             "directions moved %.2f° on average", subject.n_images, int(grid.mask.sum()),
             time.perf_counter() - start, final, reachable, moved)
    intensities = lights.intensities if lights.intensities is not None else np.ones((len(scales), 3))
    intensities = intensities * scales[:, None]
    intensities = intensities / np.exp(np.log(intensities.mean(1)).mean())
    fitted = Lights(directions.astype(np.float32), intensities.astype(np.float32), "selfcal",
                    spread_deg=lights.spread_deg)
    return fitted, Verdict(settings.name, "changed", f"fitted to the images: loss {final:.4g} against "
                           f"{reachable:.4g} with the first guess; directions moved {moved:.2f}° on "
                           f"average", evidence)


def working_grid(observed: Subject, scaled_normals: np.ndarray, max_pixels: int) -> Subject:
    """The subject cropped to its mask and block-averaged to at most ``max_pixels`` object pixels,
    with the unit normals of ``scaled_normals`` (m, 3) in place of its own."""
    normals = np.zeros((*observed.mask.shape, 3), np.float32)
    normals[observed.mask] = scaled_normals
    factor = max(1, int(np.ceil(np.sqrt(observed.mask.sum() / max_pixels))))
    grid = observed.replace(normals=normals, depth=None).crop_to_mask(1).downsample(factor)
    while grid.mask.sum() > max_pixels:        # half-covered blocks can tip the count over
        factor += 1
        grid = observed.replace(normals=normals, depth=None).crop_to_mask(1).downsample(factor)
    return grid


def initial_model(grid: Subject, target: torch.Tensor, scaled_lights: np.ndarray,
                  settings: SelfCalibration) -> SelfCalibrationModel:
    """The model at its start: depth integrated from the grid's normals, a uniform mid-grey
    albedo, lobes nearly off.

    A uniform start lets shading, not albedo, explain the images first; a start at the per-pixel
    least-squares albedo, which has absorbed the first guess's errors, settles nearly flat
    subjects (Tablet2) around those errors (``experiments/self_calibration/README.md``).

    Args:
        grid: working grid whose ``normals`` are the robust initialisation's.
        target: (m, n, 3) the images at the grid's object pixels, 99th percentile 1.
        scaled_lights: (n, 3) the factorization's lights.
    """
    depth = np.nan_to_num(integrate_normals(grid.normals, grid.mask))
    lights = torch.as_tensor(scaled_lights).float()
    uniform = torch.full((target.shape[0], 3), START_ALBEDO)
    return SelfCalibrationModel(lights, torch.as_tensor(depth), torch.as_tensor(grid.mask),
                                uniform, tuple(settings.sharpness), settings.levels,
                                settings.gloss_per_pixel)


def first_guess_pull(lights: Lights, settings: SelfCalibration) -> Pull | None:
    """The pull toward the first guess (:attr:`SelfCalibration.prior_weight`); None without one."""
    if settings.prior_weight <= 0:
        return None
    spread = lights.spread_deg if lights.spread_deg is not None else np.zeros(len(lights.directions))
    variance = np.radians(settings.prior_floor_deg) ** 2 + np.radians(spread.astype(np.float64)) ** 2
    return Pull(torch.as_tensor(lights.directions, dtype=torch.float32),
                torch.as_tensor(1 / variance, dtype=torch.float32))


@dataclass(frozen=True)
class Pull:
    """Where the first guess holds the lights: (n, 3) unit directions and (n,) weights
    1 / (σ₀² + s_i²) in rad⁻²; its intensities are 1 (the images are divided by them)."""

    directions: torch.Tensor
    weights: torch.Tensor


def objective(model: SelfCalibrationModel, target: torch.Tensor, settings: SelfCalibration,
              visible: torch.Tensor | None = None,
              pull: Pull | None = None) -> torch.Tensor:
    """Mean absolute image error (cast shadows where ``visible`` (m, n) is 0) plus the pulls on
    the per-light residuals and the bas-relief, and toward the first guess (``pull``, from
    :func:`first_guess_pull`)."""
    mu, nu, lam = model.gbr
    loss = ((model(visible) - target).abs().mean()
            + settings.residual_weight * model.light_residual.pow(2).sum(1).mean()
            + settings.gbr_weight * (mu ** 2 + nu ** 2 + (lam - 1) ** 2))
    if pull is not None:
        directions, intensities = model.lights()
        squared_angle = 2 * (1 - (directions * pull.directions).sum(-1))          # ≈ θ² for small θ
        loss = loss + settings.prior_weight * (
            (pull.weights * squared_angle).mean()
            + intensities.log().pow(2).mean() / settings.prior_intensity ** 2)
    return loss


def fit(model: SelfCalibrationModel, target: torch.Tensor, settings: SelfCalibration,
        steps: int, lights_free: bool = True,
        pull: Pull | None = None) -> float:
    """Adam on the model's unknowns (the lights' only when ``lights_free``), the cast shadows
    marched again every ``settings.shadows_every`` steps; stops early on a non-finite loss.

    Returns:
        The objective at the end, with the shadows of the final depth and lights.
    """
    every = settings.shadows_every
    visible = None
    light_parameters = [model.columns, model.gbr, model.light_residual]
    surface_parameters = [model.log_albedo, model.lobe_logits, *model.depth.parameters()]
    if model.log_gloss is not None:
        surface_parameters.append(model.log_gloss)
    groups = [dict(params=surface_parameters, lr=settings.lr)]
    if lights_free:
        groups.append(dict(params=light_parameters, lr=settings.lr_lights))
    optimiser = torch.optim.Adam(groups)
    for step in range(steps):
        if every and step % every == 0:
            visible = model.visibility()
        loss = objective(model, target, settings, visible, pull)
        if not torch.isfinite(loss):
            return loss.item()
        if lights_free and step % settings.log_every == 0:
            log.info("self-calibration step %d/%d: loss %.4g", step, steps, loss.item())
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    with torch.no_grad():
        return objective(model, target, settings, model.visibility() if every else None, pull).item()

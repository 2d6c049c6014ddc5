"""Self-calibration (``light=selfcal``): the lights fitted to the images themselves.

Starting from a first guess (the light network's estimate,
:func:`unps.lightnet.estimate.network_lights`), the lights are fitted jointly with a depth map,
an RGB albedo and shared specular lobes
(:class:`unps.lights.model.SelfCalibrationModel`) so that the rendered images match the captured
ones, in the spirit of SCPS-NIR (Li & Li, ECCV 2022) but with an explicit reflectance model small
enough for a CPU:

1. the images' low-rank part gives scaled normals under the first guess
   (:func:`unps.lights.factorization.normals_under`);
2. on a working grid of at most ``max_pixels`` object pixels, the depth integrated from those
   normals, the albedo, lobes, one 3×3 frame and small per-light residuals are fitted with Adam
   under an L1 loss, which lets saturated pixels and interreflections go rather than drag the
   fit (a value of 0 holds the rendering only below the images' first quantisation level), each
   pixel weighed down the further the model misses it beyond most pixels (:func:`pixel_weights`:
   a material no lobe renders bends the lights less); the
   shadows that the current depth casts from the current lights are rendered, and marched again
   every ``shadows_every`` steps;
3. the lights are fitted first with that frame held (each light moves by its own residual
   alone, as far as the images pin it); only where that fit is declined are they fitted again
   with the frame free and held near the first guess instead, each as far as the light network
   was sure of it (:mod:`unps.lights.prior`, :func:`frame_held_then_pulled`). A fit that
   diverges is declined, and so is one that leaves the lights nearer the view axis than the
   first guess (:func:`flattening`); where both are declined the first guess is returned. One
   that moved the lights far from it warns;
4. held light by light near the first guess, one fit undoes a transform that the network's
   lights share (a turn, a shear of the set) only in part; where the fitted lobes or the
   surface's interreflections render enough of the light to pin the lights (shading alone
   leaves them a bas-relief), the frame-held fit is made again from where
   the last one ended, up to ``rounds`` fits in all, none kept that would take the lights past
   the limit on flattening from the first guess (:func:`fitted_again`);
5. where the reversal test warned that the first guess may read the surface inside out
   (:func:`warned_inside_out`), or the light network's passes disagree on it
   (:attr:`unps.data.lights.Lights.unsure`) and no stage turned it, the frame-held fit is made
   from the first guess and from its half turn about the view (:func:`both_readings`): the two
   render the same shading and highlights, and differ in the cast shadows their depths throw.
   Under the warning the half turn is kept unless the first guess's fit explains the images
   clearly better; where the network is only unsure, only if its own fit does
   (:func:`half_turn_kept`). The reading kept is fitted on.

Frame: x right (+col), y up (−row), z toward the camera; orthographic view along +z.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np
import torch
import torch.nn.functional as F
from scipy.cluster.vq import kmeans2
from scipy.optimize import nnls

from unps.data.checks import black_everywhere, zero_ceiling
from unps.data.lights import Verdict
from unps.data.subject import Subject
from unps.device import resolve_device
from unps.errors import InputError
from unps.geometry import integrate_normals
from unps.lights import Lights, with_lights
from unps.lights.factorization import normals_under
from unps.lights.model import MIN_EXPONENT, VIEW, SelfCalibrationModel, normals_from_depth
from unps.lights.prior import NetworkPrior, network_prior
from unps.lights.reversal import half_turned
from unps.metrics import angular_error, light_slant_bias

log = logging.getLogger(__name__)

MIN_IMAGES = 4
MIN_START_REFLECTANCE = 1e-3   # the start's albedo and lobe weights at least (images: 99th pct 1)
MOVED_WARNING = 5.0  # degrees, mean over the lights: the images and the network disagree
CHECK_EVERY = 100    # steps between reads of the loss (on a GPU each read waits for the device)
AS_READ_MARGIN = 0.05    # under a warning, the half turn is kept unless its fit ends this share above
HALF_TURN_MARGIN = 0.01  # the fit as read's; without one, only if it ends this share below
MAX_FACETS = 1000      # blocks of the working grid the interreflection kernel joins at most
MIN_HIGHLIGHT_SHARE = 0.005  # the least share of the light the lobes render for the fit to be made again,
MIN_BOUNCE_SHARE = 0.05      # or the bounce of interreflection does
GREY_SPREAD = 1e-6      # chromaticities within this of one another: one material
SWITCHES = ("skip_black", "censor_black", "hold_frame", "frame_held_first", "fit_colour",
            "turn_inside_out", "decline_inside_out",
            "interreflection")   # the settings that are true or false


@dataclass(frozen=True)
class SelfCalibration:
    """Settings of the self-calibration fit.

    Attributes:
        steps: Adam steps of the fit at most.
        settle_deg: stop before ``steps`` once the lights' directions have moved no more than
            this (degrees, on average over the lights) in the last :data:`CHECK_EVERY` steps; 0:
            always run every step. 0.1 (0.05 until 2026-12-03): on the light benchmark the final
            lights are those of 0.05 to 0.02° in each group's mean, with 4 % fewer steps there and
            14–29 % fewer on DiLiGenT's three (``experiments/light_benchmark/README.md``, "How
            many steps the two fits need").
        max_pixels: object pixels on the working grid at most (blocks are averaged).
        levels: scales of the depth pyramid.
        sharpness: the specular lobes' κ (spherical Gaussians on n·h).
        skip_black: leave out of the loss the pixels black in every image
            (:func:`unps.data.checks.black_everywhere`: they hold no shading, so any light and
            normal explain them); the depth still runs across them and casts their shadows.
            Off: on the light benchmark it helped 8-bit objects with dark materials by up to
            0.7° and cost a nearly flat one 2.3° (``experiments/light_benchmark/README.md``).
        censor_black: a value of 0 in the images says only that the light there was below the
            stack's first quantisation level (:func:`unps.data.checks.zero_ceiling`: where the
            encoder's rounding or truncation switches to it): the loss charges a rendering only
            for what it puts above that light, not for any light at all. Matters on 8-bit
            captures, whose dark materials and grazing lights read 0: on the light benchmark it
            gained up to 0.4° there and cost no case more than 0.08°
            (``experiments/light_benchmark/README.md``).
        hold_frame: keep the 3×3 frame A that all the lights share at the identity, so that each
            light moves only by its own residual ε_i. A fit that renders what it cannot match
            buys its loss with a transform of the whole set (a rotation, a bas-relief, a stretch
            of the elevations): on the light benchmark one such transform came within 0.5° of
            a drifted free fit's lights (``experiments/light_benchmark/free_fits.py``).
        frame_held_first: fit first with the shared frame held and no pull toward the first
            guess (``hold_frame=True, prior_weight=0``: each light moves by its own residual
            alone), keep that fit unless it is declined (it flattened the lights more than
            ``max_flattening_deg``, or diverged), and only then fit as the other settings say.
            Held only by its frame, the fit moves a light as far as the images pin it; where it
            flattens the set instead, the pulled fit takes over. On the light benchmark (24
            objects under 96, 20 and 12 lights) it took the final lights from 8.02 / 9.84 /
            9.25° to 7.89 / 9.31 / 8.76°, better on each of DiLiGenT's nine cases, with one
            raise above 1° (``experiments/light_benchmark/README.md``, "The frame held first").
            False: the pulled fit alone (the default until 2026-12-02).
        fit_colour: fit each light's colour (an RGB scale per image, :meth:`SelfCalibrationModel.tints`),
            not only its intensity: the light network's colours can be off by tens of percent
            per channel, and a fit that cannot correct them moves the directions to absorb what
            it cannot render (a matte sphere's 12 network lights: moved 1.03° and 2.56° →
            2.82° off with one scale per image).
        lr: learning rate of depth, albedo and lobes. 0.02 (0.01 until 2026-12-03): the lights
            move as fast as the surface under them settles, and at twice the surface's step the
            fits settle in a sixth to a quarter fewer steps nearer the truth: on the light
            benchmark 7.89 / 9.33 / 8.76° → 7.60 / 8.96 / 8.61° under 96 / 20 / 12 lights, no
            case raised by more than 1° (the tablet under 20 lights had been, +1.81°), DiLiGenT's
            three 0.05–0.09° further off (``experiments/light_benchmark/README.md``, "A larger
            step for the surface").
        lr_lights: learning rate of the light frame and per-light residuals.
        residual_weight: weight of the mean squared per-light residual |ε_i|². 0.07 (0.1 until
            2026-12-07, when the reflectance began at each material's own level; with it the limit
            on flattening went from 1.5° to 2°): on the light benchmark 5.24 / 6.64 / 7.77° →
            5.08 / 6.36 / 7.58° under 96 / 20 / 12 lights (0.59 / 0.47 / 0.60× the network's),
            DiLiGenT's three 2.09 / 3.05 / 3.29° → 2.00 / 2.85 / 3.08°, no case raised by more
            than 1°. Looser still (0.05) gains more on the means but moves a matte sphere's
            12 lights more than 1° from the network's and raises blob07 in nickel under
            DiLiGenT's rig by 4° (``experiments/light_benchmark/README.md``, "A looser hold on
            each light").
        outlier_scale: a pixel whose mean absolute error is this many times the median pixel's
            weighs half in the loss, one further off less (:func:`pixel_weights`); None: every
            pixel alike (the default until 2026-12-07). A region the model cannot render (nickel,
            whose reflection no set of lobes matches; a cavity's interreflections) no longer
            bends the lights to explain it: on the light benchmark 8 took blob07 (nickel, PVC and
            yellow paint) under DiLiGenT's dome from 2.42 / 1.57 / 3.11° above the network's
            error to 0.36 / 0.11 / −0.14° under 96 / 20 / 12 lights, left no case of the 216
            raised by more than 1° (4 before) and none under 12 lights above the network's
            reading on the drawn domes (2 before), for 5.08 / 6.36 / 7.58° → 5.17 / 6.33 /
            7.51° there and DiLiGenT's three 2.00 / 2.85 / 3.08° → 1.96 / 2.82 / 3.08°. 3 and 5
            held more back (5.24 / 6.56 / 7.67° at 3); weights scaled so that the weighted error
            keeps the plain one's size (instead of a mean of 1) let the lights move further, and
            raised the tablet under DiLiGenT's dome and 12 lights by 4.4° (``experiments/
            light_benchmark/README.md``, "Pixels the model cannot render, weighed down").
        gbr_weight: weight of the pull of the bas-relief parameters (μ, ν, λ) toward (0, 0, 1).
        shadows_every: steps between updates of the cast shadows (which pixels the current depth
            hides from each current light); 0 renders none.
        prior_weight: weight of the pull of the lights toward the first guess
            (:mod:`unps.lights.prior`); 0: none.
        prior_floor_deg: σ₀, the first guess's error where the network's passes agree.
        prior_intensity: σ_e, the first guess's relative intensity error.
        max_flattening_deg: decline the fit (keep the first guess) when it leaves the lights
            nearer the view axis than the first guess by more than this (degrees, mean over the
            lights, :func:`flattening`); None: never. The light network already reads lights
            nearer the view axis than they are, never further on the whole, so a fit that
            flattens them further may have bought its loss along the bas-relief the images pin
            least. On the light benchmark and its objects in one material, each fit flattening
            them past 1° that raised the error by more than 1° had flattened them by 1.62° or
            more (the rose, vase-b, the ring, the pits), while the held fits that flattened them
            by 1.02–1.48° gained on 10 cases of 11 (a turn about the view axis counts toward
            it); 1° until 2026-12-03, 1.5° until 2026-12-07: with the reflectance's start (and
            the residual weight of 0.1) the held fits that flattened them by 1.5–2° gained on 7
            of 9 cases over the benchmark, its objects in one material and under DiLiGenT's rig
            (lost 0.80° and 0.14° on the other two), while those past 2.4° raised vase-b, the pits
            and the tablet by 2.8–7.4°; 2° until 2026-12-07, late morning: with the pixels the
            model cannot render weighed down (``outlier_scale``) the held fits that flatten them
            by 2–2.5° gain 1.0–6.3° on 4 of 5 cases (goblet-a in one material under 20 lights
            10.08° → 3.81°, unps's Vase 12.08° → 9.42°; the rose, fitted both ways, loses 1.3°),
            and the first that raises a case flattens them by 2.82° (the pits in one material
            under 12 lights) (``experiments/light_benchmark/README.md``, "Lights the fit
            flattens", "A looser hold on each light", "Pixels the model cannot render, weighed
            down").
        rounds: fits in all: after the first, the frame-held fit is made again from where the
            last one ended (:func:`fitted_again`), so that a transform the first guess's lights
            share, which one fit held light by light undoes only in part, is undone further;
            a round that would leave the lights more than ``max_flattening_deg`` nearer the view
            axis than the first guess is not kept, and none is made where the first fit's lobes
            render under :data:`MIN_HIGHLIGHT_SHARE` of the light and its bounce of
            interreflection under :data:`MIN_BOUNCE_SHARE` (a matte surface that does not see
            itself pins its lights only through a uniform albedo, which real objects need not
            have; highlights and interreflections pin the bas-relief that shading leaves). 1: one
            fit (the default until 2026-12-07, noon). On the light benchmark 3 took the final
            lights from 5.13 / 6.33 / 7.46° to 4.63 / 5.33 / 6.67° under 96 / 20 / 12 lights,
            DiLiGenT's three from 1.96 / 2.82 / 3.08° to 1.68 / 2.06 / 2.19° (cat at 96 images
            3.33° → 2.02°), unps's Vase 9.42° → 6.90°, for about three times the fit's time
            (``experiments/light_benchmark/README.md``, "Fitted again from where it ended"); six
            lowered the means further but took the objects already near the truth away from it
            (DiLiGenT's pot1 at 96 images 1.80° → 2.33°, the tablet under 12 lights past the
            network's reading: "How many rounds").
        turn_inside_out: where the reversal test kept the lights but warned that they may read
            the surface inside out (:attr:`unps.lights.reversal.AttachedLight.points_to_reversal`),
            or where the light network's passes disagree on them (:attr:`Lights.unsure
            <unps.data.lights.Lights.unsure>`) and no stage turned them, fit them as read and half
            turned about the view, and keep the reading :func:`half_turn_kept` picks
            (:func:`both_readings`). On the light benchmark (``experiments/light_benchmark/
            README.md``, "Both readings fitted", "Ties go to the warning", "Readings the network
            is unsure of") it turned every warned reading inside out (unps's Rose 60.0° → 7.1°,
            the pot shard under 96 lights 42.0° → 3.7°) and none of the readings the right way
            round.
        decline_inside_out: with ``turn_inside_out`` off, keep the first guess unfitted where the
            reversal test warned: a fit of a surface read inside out moves the lights to render
            it (unps's Rose 60.0° → 67.9° off).
        materials: fit the specular lobes' weights for up to this many materials, the object's
            pixels told apart by colour (:func:`material_labels`); 1: one set of lobes for the
            whole object (the default until 2026-12-06). Objects painted in materials of
            different gloss are rendered nearer, and their lights bent less to absorb the
            difference: on the light benchmark 2 took the final lights from 5.45 / 7.19 /
            8.18° to 5.40 / 6.93 / 8.08° under 96 / 20 / 12 lights (the face under 20 lights
            2.83° → 1.06°), DiLiGenT's three within 0.06° (``experiments/light_benchmark/
            README.md``, "Lobes per material").
        interreflection: render the light each pixel receives from the rest of the object too:
            one bounce of diffuse light through Nayar's kernel between blocks of the working grid
            (at most :data:`MAX_FACETS`, :func:`unps.lights.model.facet_kernel`), the kernel made
            again from the current depth whenever the cast shadows are (every 100 steps without
            them), and a fitted share of
            the albedo reflecting it (the default since 2026-12-07; false: none). A cavity's
            interreflections no longer bend the lights to explain them: a bowl lit by one bounce
            and fitted from its true lights keeps them within 1.5° (more than 4° off without);
            on DiLiGenT's ball, cat and pot1 the final lights went from 1.68 / 2.06 / 2.19° to
            1.53 / 1.91 / 1.93° under 96 / 20 / 12 images (pot1 at 96 2.14° → 1.80°), on the
            light benchmark 4.63 / 5.33 / 6.67° → 4.57 / 5.26 / 6.56°, no case raised by more
            than 1°; a convex surface, whose blocks see none of each other, is fitted as before
            (``experiments/light_benchmark/README.md``, "Interreflections in the self-calibration").
        log_every: steps between progress lines.
        device: where the fit runs (the run's ``device=``, :func:`unps.device.resolve_device`).
    """

    steps: int = 1000
    settle_deg: float = 0.1
    max_pixels: int = 4000
    levels: int = 4
    sharpness: tuple[float, ...] = (10.0, 30.0, 100.0, 300.0)
    skip_black: bool = False
    censor_black: bool = True
    hold_frame: bool = False
    frame_held_first: bool = True
    fit_colour: bool = True
    lr: float = 0.02
    lr_lights: float = 0.003
    residual_weight: float = 0.07
    outlier_scale: float | None = 8.0
    gbr_weight: float = 0.003
    shadows_every: int = 100
    prior_weight: float = 0.003
    prior_floor_deg: float = 3.0
    prior_intensity: float = 0.1
    max_flattening_deg: float | None = 2.5
    rounds: int = 3
    turn_inside_out: bool = True
    decline_inside_out: bool = True
    materials: int = 2
    interreflection: bool = True
    log_every: int = 500
    device: str = "auto"

    name: ClassVar[str] = "selfcal"

    def __call__(self, subject: Subject, lights: Lights) -> tuple[Lights, Verdict]:
        """The light stage: :func:`self_calibrate` with these settings."""
        return self_calibrate(subject, lights, self)


def self_calibrate(subject: Subject, lights: Lights, settings: SelfCalibration = SelfCalibration(),
                   observe: Callable[[int, np.ndarray], None] | None = None) -> tuple[Lights, Verdict]:
    """The lights that best explain the subject's captured images, starting from ``lights``.

    Args:
        subject: its captured images (``observed_images()``) and mask are used.
        lights: the first guess, (n, 3) unit directions and (n, 3) intensities (or None: 1).
        observe: called as the fit goes (:func:`fit`) with the step and the (n, 3) directions the
            fit would return if it stopped there; with ``settings.frame_held_first``, by each fit
            in turn (the pulled fit's steps start again at 0).

    Raises:
        InputError: fewer than 4 images, or no light reaching the object in any image.

    Returns:
        Lights with (n, 3) unit directions and (n, 3) intensities (the first guess's RGB
        intensities times one fitted scale per image; geometric mean of the scales 1), or
        ``lights`` itself when the fit diverges; and the verdict.
    """
    for name in SWITCHES:
        if not isinstance(getattr(settings, name), bool):
            raise InputError(f"light.selfcal.{name} must be true or false, got {getattr(settings, name)!r}")
    if not settings.settle_deg >= 0:
        raise InputError(f"light.selfcal.settle_deg must be a number of degrees >= 0 (0: run every "
                         f"step), got {settings.settle_deg}")
    if settings.outlier_scale is not None and not settings.outlier_scale > 0:
        raise InputError(f"light.selfcal.outlier_scale must be a number > 0 (a multiple of the median "
                         f"pixel's error), or null (every pixel weighs alike), got {settings.outlier_scale}")
    if settings.max_flattening_deg is not None and not settings.max_flattening_deg >= 0:
        raise InputError(f"light.selfcal.max_flattening_deg must be a number of degrees >= 0, or null "
                         f"(never decline), got {settings.max_flattening_deg}")
    require_count("rounds", settings.rounds, "one fit from the first guess")
    require_count("materials", settings.materials, "one set of specular lobes for the whole object")
    if settings.shadows_every < 0 or int(settings.shadows_every) != settings.shadows_every:
        raise InputError(f"light.selfcal.shadows_every must be a whole number of steps >= 0 (0: no "
                         f"cast shadows), got {settings.shadows_every}")
    if subject.n_images < MIN_IMAGES:
        raise InputError(f"self-calibration needs at least {MIN_IMAGES} images, "
                         f"{subject.name!r} has {subject.n_images}: use light=estimated (the "
                         f"network's lights) or light=gt")
    warned = warned_inside_out(lights)
    if settings.turn_inside_out and (warned or unsure_reading(lights)):
        fitted, verdict = both_readings(subject, lights, settings, observe, warned)
    elif warned and settings.decline_inside_out:
        log.warning("self-calibration of %s skipped: the reversal test warned that the lights may "
                    "read the surface inside out, and a fit of that surface would move the lights "
                    "to render it; keeping them", subject.name)
        return lights, Verdict(settings.name, "declined", "the reversal test warned that the lights "
                               "may read the surface inside out (light.selfcal.decline_inside_out)")
    else:
        fitted, verdict = fit_as_set(working_images(subject, lights, settings), lights, settings, observe)
    if verdict.outcome == "changed" and settings.rounds > 1:
        started = half_turned(lights) if verdict.evidence.get("half_turned") else lights
        fitted, verdict = fitted_again(subject, started, fitted, verdict, settings, observe)
    if verdict.outcome == "declined":
        log.warning("self-calibration of %s declined: %s; keeping the lights it started from",
                    subject.name, verdict.reason)
    elif verdict.evidence.get("moved_deg", 0.0) > MOVED_WARNING:
        start = "the half turn of " if verdict.evidence.get("half_turned") else ""
        log.warning("self-calibration moved the lights %.1f° on average from %sthe light network's "
                    "estimate: the images and the network disagree, and either may be wrong; check "
                    "lights.png, and calibrate the lights (light=gt) if you can",
                    verdict.evidence["moved_deg"], start)
    return fitted, verdict


def require_count(name: str, value, one: str) -> None:
    """Refuse ``light.selfcal.<name>`` unless it is a whole number ≥ 1 (``one``: what 1 means).

    Raises:
        InputError: naming the setting and the value.
    """
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise InputError(f"light.selfcal.{name} must be a whole number >= 1 (1: {one}), got {value!r}")


@dataclass(frozen=True)
class WorkingImages:
    """What every fit of one self-calibration fits to: the images on the working grid, divided by
    the first guess's intensities and scaled to a 99th percentile of 1.

    Attributes:
        grid: the subject cropped to its mask and block-averaged (:func:`working_grid`), with the
            normals the images' low-rank part gives under the first guess.
        target: (m, n, 3) its object pixels' values.
        ceiling: (n, 3) the most light a 0 in each image and channel stands for, in the target's
            units (:func:`black_ceiling`); None with ``censor_black`` off or no first level.
        weight: (m,) each pixel's share of pixels not black in every image (:func:`lit_share`);
            None with ``skip_black`` off or no such pixel.
    """

    grid: Subject
    target: torch.Tensor
    ceiling: torch.Tensor | None
    weight: torch.Tensor | None


def working_images(subject: Subject, lights: Lights, settings: SelfCalibration) -> WorkingImages:
    """The subject's images as the fits see them, from the first guess ``lights``.

    Raises:
        InputError: every image is black on the object.
    """
    subject = subject.crop_to_mask(1)              # the working grid's crop: the same pixels, less to divide
    observed = with_lights(subject, lights)              # divided by the first guess's intensities
    gray = observed.images[:, subject.mask].mean(-1).T.astype(np.float64)       # (m, n)
    if not np.any(gray > 0):
        raise InputError(f"self-calibration of {subject.name!r}: every image is black on the "
                         f"object, so the images say nothing about the lights")
    grid = working_grid(observed, normals_under(gray, lights.directions.astype(np.float64)),
                        settings.max_pixels)
    target = torch.as_tensor(grid.images[:, grid.mask]).permute(1, 0, 2).float()  # (m, n, 3)
    white = torch.quantile(target.flatten()[::7], 0.99).clamp_min(1e-12)
    return WorkingImages(grid, target / white,
                         black_ceiling(subject, lights, float(white)) if settings.censor_black else None,
                         lit_share(subject, settings.max_pixels) if settings.skip_black else None)


def fit_once(images: WorkingImages, lights: Lights, settings: SelfCalibration,
             observe: Callable[[int, np.ndarray], None] | None = None) -> tuple[Lights, Verdict]:
    """One fit of the lights as ``settings`` say (``frame_held_first`` aside), from ``lights``;
    ``lights`` themselves with a declined verdict where it diverged or flattened them more than
    ``settings.max_flattening_deg`` (:func:`self_calibrate` has checked the subject and settings)."""
    start = time.perf_counter()
    grid, target, ceiling, weight = images.grid, images.target, images.ceiling, images.weight
    device = resolve_device(settings.device)
    model = initial_model(grid, target, lights.directions.astype(np.float64), settings).to(device)
    prior = network_prior(lights, settings.prior_weight, settings.prior_floor_deg,
                          settings.prior_intensity)
    loss, pull, steps = fit(model, target.to(device), settings,
                            None if prior is None else prior.to(device),
                            None if weight is None else weight.to(device),
                            None if ceiling is None else ceiling.to(device), observe)
    directions, scales = (t.detach().cpu().numpy().astype(np.float64) for t in model.lights())
    if not (np.isfinite(loss) and np.all(np.isfinite(directions))):
        return lights, Verdict(settings.name, "declined", "the fit diverged",
                               {"loss": loss, "steps": steps})
    moved = float(angular_error(directions, lights.directions).mean())
    flattened = flattening(directions, lights.directions)
    evidence = {"loss": loss, "prior": pull, "moved_deg": moved, "flattened_deg": flattened,
                "steps": steps, "materials": len(model.lobe_logits),
                "highlight_share": model.highlight_share()}
    if weight is not None:
        evidence["black_share"] = float(1 - weight.mean())
    if model.max_facets is not None:
        evidence.update(bounce_scale=float(model.bounce_scale().detach()), bounce_share=model.bounce_share())
    log.info("self-calibrated %d lights on %d pixels in %d steps (%.1f s): loss %.4g, pull toward "
             "the first guess %.4g; directions moved %.2f° on average, %.2f° %s the view axis",
             grid.n_images, int(grid.mask.sum()), steps, time.perf_counter() - start, loss, pull,
             moved, abs(flattened), "nearer" if flattened >= 0 else "farther from")
    if settings.max_flattening_deg is not None and flattened > settings.max_flattening_deg:
        limit = f"light.selfcal.max_flattening_deg={settings.max_flattening_deg:g}°"
        return lights, Verdict(settings.name, "declined",
                               f"the fit took the lights {flattened:.2f}° nearer the view axis on average "
                               f"(more than {limit}), along the bas-relief the images pin least "
                               f"(directions moved {moved:.2f}°)", evidence)
    intensities = lights.intensities if lights.intensities is not None else np.ones((len(scales), 3))
    intensities = intensities * scales[:, None] * model.tints().detach().cpu().numpy()
    intensities = intensities / np.exp(np.log(intensities.mean(1)).mean())
    fitted = Lights(directions.astype(np.float32), intensities.astype(np.float32), "selfcal",
                    spread_deg=lights.spread_deg)
    how = f", settled after {steps} steps" if steps < settings.steps else f" in {steps} steps"
    return fitted, Verdict(settings.name, "changed", f"fitted to the images{how} (loss {loss:.4g}, "
                           f"pull toward the first guess {pull:.4g}); directions moved {moved:.2f}° "
                           f"on average", evidence)


def fit_as_set(images: WorkingImages, lights: Lights, settings: SelfCalibration,
               observe: Callable[[int, np.ndarray], None] | None = None,
               held: tuple[Lights, Verdict] | None = None) -> tuple[Lights, Verdict]:
    """The fit ``settings`` describe from ``lights``: :func:`frame_held_then_pulled` with
    ``frame_held_first`` (its first fit ``held`` where already made), else :func:`fit_once`."""
    if settings.frame_held_first:
        return frame_held_then_pulled(images, lights, settings, observe, held)
    return fit_once(images, lights, settings, observe)


def fitted_again(subject: Subject, first_guess: Lights, fitted: Lights, verdict: Verdict,
                 settings: SelfCalibration,
                 observe: Callable[[int, np.ndarray], None] | None = None) -> tuple[Lights, Verdict]:
    """Rounds 2 … ``settings.rounds`` of the self-calibration: the frame-held fit made again from
    the lights the round before ended at, its working images, depth and reflectance started anew
    under them, so that each light is held near where the last round left it rather than near
    ``first_guess``, the reading the first fit started from (the half turn of the network's
    lights where :func:`both_readings` kept it). Stops early once a round moves the lights no
    more than ``settings.settle_deg`` on average, or diverges, or would leave them more than
    ``settings.max_flattening_deg`` nearer the view axis than ``first_guess`` (:func:`flattening`;
    that round's lights are not kept). None is made where the first fit's lobes render under
    :data:`MIN_HIGHLIGHT_SHARE` of the light and its bounce of interreflection under
    :data:`MIN_BOUNCE_SHARE` (its evidence's ``highlight_share`` and ``bounce_share``).

    Returns:
        The last lights kept and ``verdict`` (that of the first round, ``changed``) with the
        rounds made: ``rounds`` and ``loss``, ``moved_deg`` and ``flattened_deg`` counted from
        ``first_guess``, in its evidence, and why it stopped in its reason.
    """
    share = verdict.evidence.get("highlight_share")
    if share is None:                 # a half turn kept unfitted: its fit was declined
        return fitted, verdict
    bounce = verdict.evidence.get("bounce_share", 0.0)
    if share < MIN_HIGHLIGHT_SHARE and bounce < MIN_BOUNCE_SHARE:
        return fitted, replace(verdict, reason=f"{verdict.reason}; not fitted again: its lobes render "
                                               f"{100 * share:.2f} % of the light and its interreflections "
                                               f"{100 * bounce:.1f} %, too little to pin the lights",
                               evidence={**verdict.evidence, "rounds": 1})
    each_round = replace(frame_held(settings), max_flattening_deg=None)
    made, stop = 1, f"{settings.rounds} fits in all"
    evidence = dict(verdict.evidence)
    while made < settings.rounds:
        again, step = fit_once(working_images(subject, fitted, settings), fitted, each_round, observe)
        if step.outcome != "changed":
            stop = f"round {made + 1} diverged"
            break
        flattened = flattening(again.directions, first_guess.directions)
        if settings.max_flattening_deg is not None and flattened > settings.max_flattening_deg:
            stop = (f"round {made + 1} would have taken the lights {flattened:.2f}° nearer the view "
                    f"axis than the first guess (light.selfcal.max_flattening_deg="
                    f"{settings.max_flattening_deg:g}°)")
            break
        fitted, made = again, made + 1
        evidence.update(loss=step.evidence["loss"], flattened_deg=flattened, steps=step.evidence["steps"],
                        moved_deg=float(angular_error(fitted.directions, first_guess.directions).mean()))
        if step.evidence["moved_deg"] <= settings.settle_deg:
            stop = f"round {made} moved them {step.evidence['moved_deg']:.2f}°"
            break
    evidence["rounds"] = made
    if made == 1:
        return fitted, replace(verdict, reason=f"{verdict.reason}; not fitted again: {stop}",
                               evidence=evidence)
    return fitted, replace(verdict, reason=f"{verdict.reason}; fitted again from where it ended "
                                           f"{made - 1} time{'s' if made > 2 else ''} ({stop}): "
                                           f"moved {evidence['moved_deg']:.2f}° from the first guess "
                                           f"in all", evidence=evidence)


def frame_held(settings: SelfCalibration) -> SelfCalibration:
    """``settings`` for the fit with the lights' shared frame held and no pull."""
    return replace(settings, hold_frame=True, prior_weight=0.0)


def both_readings(subject: Subject, lights: Lights, settings: SelfCalibration,
                  observe: Callable[[int, np.ndarray], None] | None, warned: bool
                  ) -> tuple[Lights, Verdict]:
    """Where the reversal test ``warned`` that ``lights`` may read the surface inside out, or the
    light network is unsure of them: the frame-held fit from ``lights`` and from their half turn
    about the view (the same shading and highlights, the reverse depth and its cast shadows);
    the reading :func:`half_turn_kept` picks by those fits' losses, fitted on as ``settings`` say.

    Returns:
        The lights and the verdict, whose evidence holds both fits' losses
        (``as_read_loss``, ``half_turn_loss``; left out where a fit diverged) and ``half_turned``
        (1 where the half turn was kept, else 0). A half turn whose
        fits are all declined is returned unfitted, the verdict ``changed`` all the same.
    """
    why = ("the reversal test warned that the lights may read the surface inside out" if warned else
           f"the light network's passes disagree on the lights by {np.median(lights.spread_deg):.1f}° "
           f"(median over the lights)")
    readings = {"as read": lights, "half turn": half_turned(lights)}
    images = {name: working_images(subject, start, settings) for name, start in readings.items()}
    held = {name: fit_once(images[name], start, frame_held(settings), observe)
            for name, start in readings.items()}
    loss = {name: float(verdict.evidence.get("loss", np.nan)) for name, (_, verdict) in held.items()}
    turned = half_turn_kept(loss["as read"], loss["half turn"], warned)
    compared = {f"{name.replace(' ', '_')}_loss": value for name, value in loss.items() if np.isfinite(value)}
    compared["half_turned"] = float(turned)
    both = (f"{why}; fitted as read and half turned about the view, the lights explain the images "
            f"to a loss of {loss['as read']:.4g} and {loss['half turn']:.4g}")
    if turned:
        log.warning("self-calibration of %s: %s: turned them half a turn about the view axis; if "
                    "shape.png shows the object hollow where it bulges, rerun with "
                    "light.selfcal.turn_inside_out=false", subject.name, both)
        fitted, verdict = fit_as_set(images["half turn"], readings["half turn"], settings, observe,
                                     held["half turn"] if settings.frame_held_first else None)
        if verdict.outcome == "declined":        # the half turn itself, unfitted
            return fitted, Verdict(settings.name, "changed", f"turned the lights half a turn about "
                                   f"the view: {both}; the fit of the half turn was declined: "
                                   f"{verdict.reason}", {**{f"half_turn_{k}": v for k, v in
                                                            verdict.evidence.items()}, **compared})
        return fitted, replace(verdict, reason=f"turned the lights half a turn about the view: {both}; "
                                               f"then {verdict.reason}",
                               evidence={**verdict.evidence, **compared})
    log.info("self-calibration of %s: %s: they are kept as read", subject.name, both)
    fitted, verdict = fit_as_set(images["as read"], lights, settings, observe,
                                 held["as read"] if settings.frame_held_first else None)
    return fitted, replace(verdict, reason=f"kept the lights as read: {both}; then {verdict.reason}",
                           evidence={**verdict.evidence, **compared})


def half_turn_kept(as_read_loss: float, half_turn_loss: float, warned: bool) -> bool:
    """Whether a reading is turned, by the losses its frame-held fits end at as read and half
    turned (NaN: that fit diverged). Where the reversal test ``warned``, unless the half turn's
    ends more than :data:`AS_READ_MARGIN` above the fit as read: ties go to the warning, evidence
    of its own (the light in attached shadows reads as the half turn's interreflections), and
    where neither depth throws a shadow the images show, the fits cannot tell the readings apart.
    Without a warning (the network unsure alone), only where the half turn's ends more than
    :data:`HALF_TURN_MARGIN` below. On the light benchmark the fits of readings inside out ended
    −7.6 % to +1.1 % from the fit as read; those the right way round +1.5 % to +564 % under 96
    lights, +22 % to +184 % where warned, +0.2 % at the nearest (the face under 12 lights and a
    room's light, neither warned of nor unsure) (``experiments/light_benchmark/both_readings.py``).

    >>> half_turn_kept(0.0130, 0.0131, warned=True), half_turn_kept(0.0130, 0.0131, warned=False)
    (True, False)
    >>> half_turn_kept(0.0130, 0.0300, warned=True), half_turn_kept(0.0130, 0.0120, warned=False)
    (False, True)
    """
    if not np.isfinite(half_turn_loss):
        return False
    if not np.isfinite(as_read_loss):
        return True
    if warned:
        return half_turn_loss <= (1 + AS_READ_MARGIN) * as_read_loss
    return half_turn_loss < (1 - HALF_TURN_MARGIN) * as_read_loss


def frame_held_then_pulled(images: WorkingImages, lights: Lights, settings: SelfCalibration,
                           observe: Callable[[int, np.ndarray], None] | None = None,
                           held: tuple[Lights, Verdict] | None = None) -> tuple[Lights, Verdict]:
    """``settings.frame_held_first``: the fit with the shared frame held and no pull (``held``
    where already made), kept unless declined; where declined, the fit the other settings
    describe, its verdict saying why."""
    fitted, verdict = held if held is not None else fit_once(images, lights, frame_held(settings), observe)
    if verdict.outcome != "declined":
        return fitted, replace(verdict, reason=f"with the shared frame held: {verdict.reason}")
    log.info("the fit with the shared frame held was declined (%s); fitting pulled toward the "
             "first guess instead", verdict.reason)
    fitted, pulled = fit_once(images, lights, settings, observe)
    evidence = {**pulled.evidence, **{f"frame_held_{k}": v for k, v in verdict.evidence.items()}}
    return fitted, replace(pulled, reason=f"{pulled.reason} (the fit with the shared frame held was "
                                          f"declined: {verdict.reason})", evidence=evidence)


def warned_inside_out(lights: Lights) -> bool:
    """Whether the reversal test kept ``lights`` but warned that they may read the surface
    inside out (its verdict's ``attached_points_to_reversal``)."""
    return any(v.stage == "reversal" and v.outcome == "kept"
               and bool(v.evidence.get("attached_points_to_reversal")) for v in lights.verdicts)


def unsure_reading(lights: Lights) -> bool:
    """Whether the light network is unsure of ``lights`` (:attr:`unps.data.lights.Lights.unsure`)
    and no reversal test turned them (where one did, the shadows decided the reading)."""
    return lights.unsure and not any(v.stage == "reversal" and v.outcome == "changed"
                                     for v in lights.verdicts)


def flattening(directions: np.ndarray, first_guess: np.ndarray) -> float:
    """How much nearer the view axis +z the fitted lights are than the first guess: minus the mean
    signed change of their angle from the view axis (:func:`unps.metrics.light_slant_bias` of the
    fit read against the first guess), in degrees; < 0 where the fit steepened them.

    Args:
        directions, first_guess: (n, 3) directions of the same lights.

    >>> guess = np.array([[np.sin(np.radians(30)), 0.0, np.cos(np.radians(30))]])
    >>> round(flattening(np.array([[np.sin(np.radians(27)), 0.0, np.cos(np.radians(27))]]), guess), 6)
    3.0
    """
    return -light_slant_bias(directions, first_guess)


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


def lit_share(subject: Subject, max_pixels: int) -> torch.Tensor | None:
    """(m,) the share of each object pixel of the working grid (:func:`working_grid`) whose
    pixels are not black in every image, or None when no pixel of the subject is.

    Raises:
        InputError: every object pixel is black in every image.
    """
    black = black_everywhere(subject.images, subject.mask)
    if not black.any():
        return None
    if black[subject.mask].all():
        raise InputError(f"self-calibration of {subject.name!r} with light.selfcal.skip_black=true: "
                         f"every object pixel is black in every image, so no pixel is left to fit")
    lit = np.repeat((~black).astype(np.float32)[None, ..., None], 3, -1)
    grid = working_grid(subject.select([0]).replace(images=lit),
                        np.zeros((int(subject.mask.sum()), 3)), max_pixels)
    return torch.as_tensor(grid.images[0][grid.mask][:, 0])


def black_ceiling(subject: Subject, lights: Lights, white: float) -> torch.Tensor | None:
    """(n, 3) what a value of 0 in image i and channel c of the self-calibration's target stands
    for at most: the light at which the captured stack's first quantisation level begins
    (:func:`unps.data.checks.zero_ceiling`, as the fit's ``preset.censor_black``), divided as the
    target is by the first guess's intensity and the target's ``white`` level; None without a
    first level."""
    ceiling = zero_ceiling(subject.observed_images(), subject.mask)
    if ceiling is None:
        return None
    intensities = lights.intensities if lights.intensities is not None else np.ones((subject.n_images, 3))
    return torch.as_tensor(ceiling / (intensities * white), dtype=torch.float32)


def initial_model(grid: Subject, target: torch.Tensor, scaled_lights: np.ndarray,
                  settings: SelfCalibration) -> SelfCalibrationModel:
    """The model at its start: depth integrated from the grid's normals, one albedo and one set of
    lobe weights per material, those that render the images best under the first guess
    (:func:`start_reflectance`).

    A uniform start lets shading, not albedo, explain the images first; a start at the per-pixel
    least-squares albedo, which has absorbed the first guess's errors, settles nearly flat
    subjects (Tablet2) around those errors (``experiments/self_calibration/README.md``). Started
    at one grey for every object with the lobes nearly off (until 2026-12-07), the fit spent its
    first steps bringing the albedo to the object's own level and colour and the lobes to its
    gloss, one step of the learning rate at a time, while the lights bent to make up the
    difference: on the light benchmark each material's own start took the final lights from
    5.40 / 6.93 / 8.08° to 5.24 / 6.64 / 7.77° under 96 / 20 / 12 lights in a sixth fewer steps,
    DiLiGenT's three within 0.04° (``experiments/light_benchmark/README.md``, "The reflectance's
    start").

    Args:
        grid: working grid whose ``normals`` are those under the first guess.
        target: (m, n, 3) the images at the grid's object pixels, 99th percentile 1.
        scaled_lights: (n, 3) the first guess's directions (the images are divided by its
            intensities).
    """
    depth = torch.as_tensor(np.nan_to_num(integrate_normals(grid.normals, grid.mask)))
    mask = torch.as_tensor(grid.mask)
    lights = torch.as_tensor(scaled_lights).float()
    materials = material_labels(target, settings.materials)
    sharpness = tuple(settings.sharpness)
    normals = normals_from_depth(depth.float(), mask)
    directions = F.normalize(lights, dim=-1)
    halfway = F.normalize(directions + torch.tensor(VIEW), dim=-1)
    albedo, lobes = start_reflectance(target, (normals @ directions.T).clamp_min(0),
                                      (normals @ halfway.T).clamp(max=1), materials, sharpness)
    return SelfCalibrationModel(lights, depth, mask, albedo, sharpness, settings.levels, materials, lobes,
                                MAX_FACETS if settings.interreflection else None)


def start_reflectance(target: torch.Tensor, shading: torch.Tensor, cosine: torch.Tensor,
                      materials: torch.Tensor, sharpness: tuple[float, ...]
                      ) -> tuple[torch.Tensor, torch.Tensor]:
    """Each material's one RGB albedo ρ_j and white lobe weights w_jk ≥ 0 that render the images
    best as shading · (ρ_j + Σ_k w_jk exp(κ_k (cosine − 1))), in non-negative least squares
    over the material's pixels, every image and the three channels; each at least
    :data:`MIN_START_REFLECTANCE`.

    Args:
        target: (m, n, 3) the images at the object pixels.
        shading: (m, n) max(n_p · l_i, 0) under the lights.
        cosine: (m, n) n_p · h_i, h_i the half vector of light i and the view.
        materials: (m,) each pixel's material, 0 … J − 1.
        sharpness: the lobes' κ_k (K of them).

    Returns:
        (m, 3) each pixel's material's albedo and (J, K) the lobes' weights.

    >>> shading, cosine = torch.rand(6, 40), 1 - torch.rand(6, 40) ** 2 / 4
    >>> lobe = torch.exp(30 * (cosine - 1))
    >>> albedo = torch.tensor([[0.5, 0.4, 0.3]] * 3 + [[0.2, 0.2, 0.9]] * 3)
    >>> gloss = torch.tensor([0.0] * 3 + [0.6] * 3)[:, None, None]
    >>> images = shading[..., None] * (albedo[:, None, :] + gloss * lobe[..., None])
    >>> start, lobes = start_reflectance(images, shading, cosine, torch.tensor([0] * 3 + [1] * 3), (30.0,))
    >>> start[2:4], lobes
    (tensor([[0.5000, 0.4000, 0.3000],
            [0.2000, 0.2000, 0.9000]]), tensor([[0.0010],
            [0.6000]]))
    """
    count = int(materials.max()) + 1 if len(materials) else 1
    kappa = torch.tensor(sharpness, dtype=torch.float64)[:, None, None]
    albedo, lobes = np.empty((count, 3)), np.empty((count, len(sharpness)))
    for j in range(count):
        on = materials == j
        s, t = shading[on].double(), target[on].double()                      # (mj, n), (mj, n, 3)
        g = (kappa * (cosine[on].double() - 1)).clamp_min(MIN_EXPONENT).exp() * s          # (K, mj, n)
        parts = torch.cat([s[None], g])                                                    # (1 + K, mj, n)
        gram = torch.einsum("kmn,lmn->kl", parts, parts)
        products = torch.einsum("kmn,mnc->kc", parts, t)                                   # (1 + K, 3)
        normal = torch.block_diag(*[gram[:1, :1]] * 3)      # unknowns: ρ_r, ρ_g, ρ_b, w_1 … w_K
        normal = torch.cat([torch.cat([normal, gram[:1, 1:].repeat(3, 1)], 1),
                            torch.cat([gram[1:, :1].repeat(1, 3), 3 * gram[1:, 1:]], 1)])
        right = torch.cat([products[0], products[1:].sum(1)])
        albedo[j], lobes[j] = np.split(nonnegative_solve(normal.numpy(), right.numpy()), [3])
    floor = MIN_START_REFLECTANCE
    return (torch.as_tensor(albedo, dtype=torch.float32).clamp_min(floor)[materials],
            torch.as_tensor(lobes, dtype=torch.float32).clamp_min(floor))


def nonnegative_solve(normal: np.ndarray, right: np.ndarray) -> np.ndarray:
    """(k,) x ≥ 0 minimising |A x − b|² given its normal equations A^T A = ``normal`` (k, k),
    A^T b = ``right`` (k,): the non-negative least squares of L^T x ≈ L⁻¹ A^T b, L L^T the
    Cholesky factor of ``normal`` (lifted by 10⁻⁹ of its trace, at least of 1, so a column of
    zeros is solved: x = 0 there).

    >>> nonnegative_solve(np.zeros((2, 2)), np.zeros(2))
    array([0., 0.])
    """
    lifted = normal + np.eye(len(normal)) * 1e-9 * max(np.trace(normal), 1.0)
    factor = np.linalg.cholesky(lifted)
    return nnls(factor.T, np.linalg.solve(factor, right))[0]


def material_labels(target: torch.Tensor, count: int, seed: int = 0) -> torch.Tensor:
    """(m,) each pixel's material, 0 … J − 1 (J ≤ ``count``): k-means of the pixels' chromaticity,
    their (m, n, 3) values in ``target`` summed over the images (under lights of one colour,
    shading scales a pixel's three channels alike). Pixels black in every image join material 0;
    grey images, or fewer lit pixels than ``count``, make one material.

    >>> red, blue = torch.tensor([0.8, 0.2, 0.1]), torch.tensor([0.1, 0.3, 0.9])
    >>> target = torch.stack([red, red, blue, red, blue])[:, None, :] * torch.rand(5, 4, 1)
    >>> material_labels(target, 2).tolist() in ([0, 0, 1, 0, 1], [1, 1, 0, 1, 0])
    True
    """
    total = target.sum(1).double().cpu().numpy()
    lit = total.sum(1) > 0
    chroma = total[lit, :2] / total[lit].sum(1, keepdims=True)
    if count <= 1 or lit.sum() < count or np.ptp(chroma, 0).max() < GREY_SPREAD:
        return torch.zeros(len(total), dtype=torch.long)
    _, labels = kmeans2(chroma, count, seed=seed, minit="++")
    found = np.zeros(len(total), np.int64)
    found[lit] = labels
    return torch.as_tensor(np.unique(found, return_inverse=True)[1].reshape(-1))


@dataclass(frozen=True)
class BlackValues:
    """The values of a (m, n, 3) target that are 0, and what each stands for at most.

    Attributes:
        index: (k,) their positions in the flattened target.
        ceiling: (k,) the ceiling at each (:func:`black_ceiling`'s for its image and channel).
    """

    index: torch.Tensor
    ceiling: torch.Tensor

    @classmethod
    def of(cls, target: torch.Tensor, ceiling: torch.Tensor) -> BlackValues:
        """The black values of ``target`` (m, n, 3) under the (n, 3) ``ceiling``."""
        index = (target == 0).flatten().nonzero()[:, 0]
        return cls(index, ceiling.expand_as(target).flatten()[index])


def objective(model: SelfCalibrationModel, target: torch.Tensor, settings: SelfCalibration,
              visible: torch.Tensor | None = None, weight: torch.Tensor | None = None,
              black: BlackValues | None = None) -> torch.Tensor:
    """Mean absolute image error (cast shadows where ``visible`` (m, n) is 0; at the target's
    ``black`` values, where given, only what the rendering puts above their ceiling), each pixel
    weighted as :func:`pixel_weights` says from its own error and ``weight`` (m,), plus the
    pulls on the per-light residuals and the bas-relief.

    At a black value the error |r − 0| − min(r, ceiling) = max(r − ceiling, 0), the rendering r
    being ≥ 0: the censoring costs a pass over the black values alone, and its gradient is the
    clamp's, value for value (1 at r = ceiling too).
    """
    mu, nu, lam = model.gbr
    rendered = model(visible)
    per_pixel = (rendered - target).abs().sum((1, 2))                          # (m,)
    if black is not None:
        at = rendered.flatten()[black.index]
        held = torch.where(at < black.ceiling, at, black.ceiling)     # min; slope 0 at a tie
        pixel = black.index // (rendered.shape[1] * rendered.shape[2])
        per_pixel = per_pixel.index_add(0, pixel, -held)
    per_pixel = per_pixel / (rendered.shape[1] * rendered.shape[2])
    weights = pixel_weights(per_pixel.detach(), weight, settings.outlier_scale)
    return ((per_pixel * weights).mean()
            + settings.residual_weight * model.light_residual.pow(2).sum(1).mean()
            + settings.gbr_weight * (mu ** 2 + nu ** 2 + (lam - 1) ** 2))


def pixel_weights(error: torch.Tensor, share: torch.Tensor | None,
                  outlier_scale: float | None) -> torch.Tensor:
    """(m,) weights of the pixels in the loss, mean 1: each pixel's ``share`` (m,) where given
    (:func:`lit_share`), times 1 / (1 + (E_p / (``outlier_scale`` · median E))²) for its mean
    absolute error E_p (m,) over the images and channels, the median over the pixels with a
    share (None: that factor left out).

    A pixel the model renders as well as most weighs nearly fully; one it misses by far more
    than most (a material no set of lobes renders, interreflections in a cavity) weighs the
    less the further it is off, so that the lights are fitted to what the model can render
    instead of being bent to explain the rest. Read again at every step from the current error
    (no gradient flows through the weights), as in iteratively reweighted least squares.

    >>> pixel_weights(torch.tensor([1.0, 1.0, 1.0, 9.0]), None, 3.0)
    tensor([1.2857, 1.2857, 1.2857, 0.1429])
    """
    weights = torch.ones_like(error) if share is None else share
    if outlier_scale is not None:
        counted = error if share is None else error[share > 0]
        typical = outlier_scale * counted.median().clamp_min(1e-12)
        weights = weights / (1 + (error / typical) ** 2)
    return weights / weights.mean()


def fit(model: SelfCalibrationModel, target: torch.Tensor, settings: SelfCalibration,
        prior: NetworkPrior | None = None, weight: torch.Tensor | None = None,
        ceiling: torch.Tensor | None = None,
        observe: Callable[[int, np.ndarray], None] | None = None) -> tuple[float, float, int]:
    """Adam on every unknown of the model (the shared frame held where ``settings.hold_frame``)
    for ``settings.steps`` steps, the cast shadows marched again every ``settings.shadows_every``
    steps (and the light the surface sends itself found again with them, every
    :data:`CHECK_EVERY` steps without them, where the model renders it), the pixels weighted by
    ``weight`` (m,) and the black values held only to ``ceiling`` (n, 3) where given
    (:func:`objective`); stops early on a non-finite loss, read every
    :data:`CHECK_EVERY` steps (a loss that is not finite leaves the parameters so, and the final
    loss with them), and once the lights have settled: their directions moved no more than
    ``settings.settle_deg`` on average since the last read. No step depends on how many there
    will be, so a fit that settles at step S ends where ``steps=S`` would.
    ``observe(step, directions)``, where given, sees the lights' (n, 3) unit directions before
    every :data:`CHECK_EVERY`-th step and after the last.

    Returns:
        The objective and the prior's pull at the end, with the shadows of the final depth and
        lights (and the received light of the last update, which the fitted scale was fitted
        to), and the steps taken.
    """
    every = settings.shadows_every
    visible = None
    surface_parameters = [model.log_albedo, model.lobe_logits, model.bounce_logit, *model.depth.parameters()]
    light_parameters = [model.light_residual] if settings.hold_frame else [
        model.columns, model.gbr, model.light_residual]
    if settings.fit_colour:
        light_parameters.append(model.log_tint)
    optimiser = torch.optim.Adam([
        dict(params=surface_parameters, lr=settings.lr),
        dict(params=light_parameters, lr=settings.lr_lights)])

    black = None if ceiling is None else BlackValues.of(target, ceiling)

    def total(visible: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor]:
        pull = prior.cost(*model.lights()) if prior is not None else torch.zeros((), device=target.device)
        return objective(model, target, settings, visible, weight, black) + pull, pull

    read, step = None, 0
    while step < settings.steps:
        checking = step % CHECK_EVERY == 0
        if checking:
            last, read = read, directions_of(model)
            if settings.settle_deg and last is not None and \
                    angular_error(read, last).mean() <= settings.settle_deg:
                break
        if every and step % every == 0:
            visible = model.visibility()
        if step % (every or CHECK_EVERY) == 0:
            model.update_received(visible)
        loss, _ = total(visible)
        if checking and not torch.isfinite(loss):
            return loss.item(), float("nan"), step
        if checking and observe is not None:
            observe(step, read)
        if step % settings.log_every == 0:
            log.info("self-calibration step %d/%d: loss %.4g", step, settings.steps, loss.item())
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        step += 1
    if observe is not None:
        observe(step, directions_of(model))
    with torch.no_grad():
        visible = model.visibility() if every else None
        loss, pull = total(visible)
        return loss.item(), pull.item(), step


def directions_of(model: SelfCalibrationModel) -> np.ndarray:
    """(n, 3) float64 unit directions of the model's lights, on the CPU."""
    return model.lights()[0].detach().cpu().numpy().astype(np.float64)

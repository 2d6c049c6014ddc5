"""``method=unps``: the paper's per-subject neural inverse rendering, end to end.

    python -m unps.fit method=unps                          # preset=fast, interreflection=nayar
    python -m unps.fit method=unps preset=paper light=gt
    python -m unps.fit method=unps interreflection=off light=refine

The subject is cropped to its mask (and, when the preset caps the pixel count, block-averaged
to a working grid); the initialisation (``preset.init``: robust by default) gives N_init and the
albedo P; the networks are fitted for ``steps`` Adam steps
(:class:`unps.inverse.system.InverseRendering`); the normals come back on the subject's own grid
(from a working grid with the initialisation's finer detail added,
:func:`unps.inverse.grids.upsample_with_detail`, then each pixel's solved from its own images under
the fitted reflectance, :func:`unps.inverse.pixels.refine_pixel_normals`, then the pixels their
images pin poorly given highlights' half vectors or the surface around them,
:func:`with_read_out_rules`). With an output folder,
checkpoints land in ``checkpoints/`` every ``update_every`` steps and a rerun in the same folder resumes.
"""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path

import numpy as np
import torch

from unps.data.checks import (FAINT_LEVELS, FAINT_SHARE, black_everywhere, clipped_values, faintly_lit,
                               zero_ceiling)
from unps.data.estimate import Estimate, Rendering
from unps.data.subject import Subject
from unps.device import native_bfloat16, resolve_device
from unps.errors import InputError
from unps.geometry import continue_surface, outline_distance
from unps.inverse.control import fingerprint, train
from unps.inverse.grids import (black_headroom, on_subject_grid, unclipped, upsample_map,
                               upsample_with_detail, working_factor)
from unps.inverse.highlights import highlight_normals, lambertian_misfit
from unps.inverse.interreflection import Interreflection
from unps.inverse.networks import NormalNet, ReflectanceNet
from unps.inverse.pixels import NOISE_LIMIT, neighbour_pairs, noise_level, refine_pixel_normals
from unps.inverse.settings import READ_OUT_FIELDS, InterreflectionModel, Preset
from unps.inverse.system import DARK_SHARE, InverseRendering
from unps.metrics import angular_error
from unps.solvers.nayar import reflectance_scale
from unps.solvers.rpca import robust_init
from unps.solvers.woodham import woodham
from unps.timing import stage

log = logging.getLogger(__name__)

CROP_MARGIN = 4   # pixels of background kept around the object so convolutions see its edge
HELD_FROM_SOLVE = 0.5   # a pixel held this hard toward N_init keeps the upsampled fit (held_from_solve)
FAR_FROM_START_DEG = 20.0   # a fit that ends this far from its start, on average, is reported


FAINT_MISFIT = 0.3
"""The Lambertian misfit above which a faintly lit pixel's values hold no shading (:func:`unshaded`).
Without the test DiLiGenT's pot1 lost most of a degree on its dark glaze; at 0.3 it loses 0.06°,
and the light benchmark keeps its gain (``experiments/light_benchmark``, "Pixels nearly black")."""


def neural_inverse_rendering(subject: Subject, light_directions: np.ndarray, preset: Preset,
                             interreflection: InterreflectionModel, refine_lights: bool = False,
                             output_dir: str | Path | None = None, device: str = "auto") -> Estimate:
    """Fit the inverse-rendering networks to one subject.

    Args:
        subject: images divided by their intensities.
        light_directions: (n, 3) unit, surface to light (estimated or calibrated).
        preset: sizes and schedule.
        interreflection: the interreflection model.
        refine_lights: learn the lights jointly, starting from ``light_directions``.
        output_dir: run folder for checkpoints (resumed from when present; a finished fit's is
            read out again, under read-out settings that may differ from its own:
            :data:`unps.inverse.settings.READ_OUT_FIELDS`) and TensorBoard; None keeps everything
            in memory.
        device: where the fit runs, its robust initialisation and interreflection updates included
            (:func:`unps.device.resolve_device`).

    Returns:
        Normals and albedo on the subject's grid, the refined lights when ``refine_lights``, the
        per-image maps on the working grid and the fit's figures in ``info``.
    """
    settings = {"preset": preset.fit_fields(), "interreflection": dataclasses.asdict(interreflection),
                "refine_lights": refine_lights}
    schedule = preset.schedule
    device = resolve_device(device)
    cropped = subject.crop_to_mask(CROP_MARGIN)
    factor = working_factor(int(cropped.mask.sum()), preset.max_pixels)
    work = cropped.downsample(factor)
    h, w = work.resolution
    log.info("unps (%s preset): working grid %d×%d (%d object pixels, ×%d coarser than the subject), "
             "%d images", preset.name, w, h, work.mask.sum(), factor, work.n_images)

    values = values_read(cropped, work.mask, factor, schedule.censor_black)
    with stage("system assembly"):
        system, scale = build_system(work, light_directions, preset, interreflection, refine_lights,
                                     fingerprint(work, light_directions, settings), values.usable,
                                     values.headroom, device)
    solver = system.interreflection
    dark_share = float((system.dark_weight > 0).sum() / system.mask.sum()) if schedule.dark_hold > 0 else None
    if dark_share:
        log.info("%.1f%% of the object is of a dark material (albedo under %.0f%% of its median): held "
                 "toward the initialisation after the prior (preset.dark_hold=%g)",
                 100 * dark_share, 100 * DARK_SHARE, schedule.dark_hold)
    parameters = sum(p.numel() for p in system.parameters() if p.requires_grad)
    precision = "bf16-mixed" if system.networks_in_bf16 else "32-true"
    log.info("networks: %.2f M parameters, %s; %d steps", parameters / 1e6, precision, schedule.steps)

    with stage("steps"):
        seconds, resumed_from = train(system, schedule, output_dir, subject.name, device)
    steps_run = schedule.steps - resumed_from
    if steps_run == 0:
        log.info("the fit's %d steps were run before in %s: its normals are read out again, with the "
                 "read-out settings given now (preset.%s)", schedule.steps, output_dir,
                 ", preset.".join(READ_OUT_FIELDS))
    else:
        log.info("fitted %d steps in %.1f s (%.3f s/step)", steps_run, seconds, seconds / steps_run)

    with stage("read-out"):
        rendering = final_rendering(system, schedule.images_per_step or 16, scale)
        normals, pseudo_normals = rendering.pop("normals"), rendering.pop("pseudo_normals")
        bend = interreflection_bend(normals, pseudo_normals, work.mask) if solver else None
        coarse_init = system.init_normals[0].permute(1, 2, 0).cpu().numpy()
        moved = distance_from_start(normals, coarse_init, work.mask, preset.init)
        directions, scales = rendering["light_directions"], rendering["light_scales"]
        image_noise = None
        held = held_from_solve(system, work.mask, cropped.mask.shape, factor)
        fitted = normals                                         # N_o on the working grid
        if factor > 1:
            fine_init = initial_estimate(cropped, light_directions, preset.init, device).normals
            normals = upsample_with_detail(fitted, coarse_init, fine_init, work.mask, factor)
        if preset.refine_pixels:
            interreflected = upsample_map(pseudo_normals - fitted, work.mask, cropped.mask.shape, factor)
            normals, image_noise = solved_per_pixel(cropped, normals, interreflected,
                                                    rendering["reflectance"], directions, scales,
                                                    work.mask, factor, ~values.clipped, held)
        normals, shares = with_read_out_rules(cropped, normals, directions, scales, preset, values.black,
                                              values.faint, held)
        normals, albedo = on_subject_grid(normals, cropped, subject, directions, scales)
    if bend is not None:
        log.info("interreflections bend the rendered normals by %.2f° on average (%.2f° at most)",
                 bend["mean"], bend["max"])
    info = {"fit_resolution": [h, w], "fit_downsample": factor, "fit_steps": schedule.steps,
            "fit_s_per_step": seconds / max(steps_run, 1), "resumed_from_step": resumed_from,
            "parameters": parameters, "network_precision": precision,
            "facets": solver.n_facets if solver else 0, "preset": preset.name,
            "interreflection": interreflection.enabled,
            "facet_downsample": solver.factor if solver else None,
            "interreflection_bend_deg": bend["mean"] if bend else None, "moved_from_start_deg": moved,
            "image_noise": image_noise, "dark_share": dark_share, "censored_share": values.censored_share,
            **shares}
    rendering = Rendering(work.mask, work.images, rendering["reconstruction"], rendering["reflectance"])
    return Estimate(normals, albedo, light_directions=directions if refine_lights else None,
                    light_scales=scales if refine_lights else None, rendering=rendering, info=info)


@dataclasses.dataclass(frozen=True)
class ValuesRead:
    """What a crop's values as captured say before the fit (:func:`values_read`).

    Attributes:
        clipped: (n, H, W) bool on the crop, the values the camera clipped
            (:func:`unps.data.checks.clipped_values`).
        black, faint: (H, W) bool on the crop, the pixels black in every image and the faintly lit
            ones (:func:`unps.data.checks.black_everywhere`, :func:`unps.data.checks.faintly_lit`).
        usable: (n, h, w) float32 on the working grid, 0 where a value holds a clipped pixel; None
            when none does (:func:`unps.inverse.grids.unclipped`).
        headroom: (n, h, w, 3) float32 on the working grid, how much brighter than read each value
            may be (:func:`unps.inverse.grids.black_headroom`); None when nothing is censored.
        censored_share: the share of the working grid's object values with headroom; None when
            nothing is censored.
    """

    clipped: np.ndarray
    black: np.ndarray
    faint: np.ndarray
    usable: np.ndarray | None
    headroom: np.ndarray | None
    censored_share: float | None


def values_read(cropped: Subject, work_mask: np.ndarray, factor: int, censor_black: bool) -> ValuesRead:
    """Read the crop's values as captured once (the stack before its division by the
    intensities), for the fit (clipped and censored values) and its read-out (black and faint
    pixels); the log says what the fit leaves out and what it bounds.

    Args:
        cropped: the subject's crop; work_mask: (h, w) its object on the working grid, ``factor``
            times coarser.
        censor_black: bound the values read as 0 by the light below the first level
            (``preset.censor_black``; :func:`unps.data.checks.zero_ceiling`).
    """
    observed = cropped.observed_images()
    clipped = clipped_values(observed, cropped.mask)
    black = black_everywhere(observed, cropped.mask)
    faint = faintly_lit(observed, cropped.mask)
    ceiling = zero_ceiling(observed, cropped.mask) if censor_black else None
    headroom = (None if ceiling is None else
                black_headroom(observed, cropped.mask, factor, ceiling, cropped.light_intensities))
    del observed
    censored_share = None if headroom is None else float((headroom[:, work_mask] > 0).mean())
    if censored_share:
        log.info("%.1f%% of the values on the working grid hold pixels read as 0, which stand for any "
                 "light below the first level (%.2g of full scale): the loss charges a rendering there "
                 "only for what it puts above that (preset.censor_black)", 100 * censored_share, ceiling)
    usable = unclipped(clipped, cropped.mask, factor)
    if usable is not None:
        log.info("%d of %d values on the working grid hold clipped pixels and are left out of the fit",
                 int((usable[:, work_mask] == 0).sum()), usable[:, work_mask].size)
    return ValuesRead(clipped, black, faint, usable, headroom, censored_share)


def held_from_solve(system: InverseRendering, work_mask: np.ndarray, shape: tuple[int, int],
                    factor: int) -> np.ndarray | None:
    """(H, W) bool on the subject's crop: the pixels of a dark material that the fit held toward
    N_init (``preset.dark_hold``; their upsampled hold weight above :data:`HELD_FROM_SOLVE`), which
    keep the upsampled fit instead of being solved from their own images — images that pin a dark
    pixel's normal no better than they pinned it in the fit. None when the fit held no pixel.

    Args:
        system: the fitted system, its ``dark_weight`` (1, 1, h, w) on the working grid ``work_mask``,
            ``factor`` times coarser than the crop's ``shape``.
    """
    if not system.holds_dark:
        return None
    weight = system.dark_weight[0].permute(1, 2, 0).cpu().numpy()
    return upsample_map(weight, work_mask, shape, factor)[..., 0] > HELD_FROM_SOLVE


def solved_per_pixel(cropped: Subject, normals: np.ndarray, interreflected: np.ndarray,
                     reflectance: np.ndarray, directions: np.ndarray, scales: np.ndarray,
                     work_mask: np.ndarray, factor: int, usable: np.ndarray,
                     held: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """The fit's normals with each pixel's solved from its own images
    (:func:`unps.inverse.pixels.refine_pixel_normals`) under the fitted reflectance, upsampled
    (``factor`` 1: the fit's own grid).

    The fit renders with the interreflected normals N_ny, not N_o: each pixel is solved for its
    N_ny, starting from the upsampled N_o moved by the fit's N_ny − N_o there, and that offset is
    taken off again (on BrokenPot, whose interreflections bend N_o by 2.6°, solving for N_o
    directly cost 1.5°).

    Args:
        cropped: the subject's crop, (H, W) grid; normals: (H, W, 3) the upsampled fit there.
        interreflected: (H, W, 3) the fit's N_ny − N_o, upsampled (zero without interreflections).
        reflectance: (n, h, w, 3) the fitted reflectance R on the working grid (``work_mask``,
            ``factor`` times coarser), in the subject's units; directions: (n, 3) and scales: (n,)
            the lights the fit rendered with.
        usable: (n, H, W) bool, False for the clipped values the fit left out.
        held: (H, W) bool, pixels that keep ``normals`` (:func:`held_from_solve`); None: none.

    Returns:
        (H, W, 3) unit normals on the crop's object — pixels the solve leaves out (a specular
        lobe among them) keep ``normals``, and all of them do where the images' noise is above
        :data:`unps.inverse.pixels.NOISE_LIMIT` — and that noise (σ, a share of the images' 99th
        percentile; :func:`unps.inverse.pixels.noise_level`).
    """
    mask = cropped.mask
    colour = np.stack([upsample_map(r, work_mask, mask.shape, factor)[mask] for r in reflectance])
    colour *= scales[:, None, None]
    images, start, offset = cropped.images[:, mask], normals[mask], interreflected[mask]
    solved, ok, used, lobed = refine_pixel_normals(images, colour, unit(start + offset), directions,
                                                   usable[:, mask])
    white = float(np.percentile(images, 99))
    noise = noise_level(images, colour, solved, directions, used, neighbour_pairs(mask)) / max(white, 1e-12)
    if noise > NOISE_LIMIT:
        log.warning("the images' noise is %.2f of their 99th percentile (above %.2f): each pixel's own "
                    "images hold more noise than detail, so the normals are the fit's (upsampled from its "
                    "working grid; preset.refine_pixels solves each pixel only where the noise allows)",
                    noise, NOISE_LIMIT)
        return normals, noise
    if held is not None:
        ok &= ~held[mask]
    solved = np.where(ok[:, None], unit(solved - offset), start)
    log.info("each pixel's normal solved from its own images under the fitted reflectance: %d of %d "
             "pixels, %.2f° from the fit on average (image noise %.3f of the 99th "
             "percentile; %d whose fitted reflectance has a specular lobe keep the fit%s)", ok.sum(), ok.size,
             float(angular_error(solved, start).mean()), noise, int(lobed.sum()),
             "" if held is None else f"; {int(held[mask].sum())} of a dark material keep the fit")
    refined = normals.copy()
    refined[mask] = solved
    return refined, noise


def with_highlights(cropped: Subject, normals: np.ndarray, directions: np.ndarray, scales: np.ndarray,
                    black: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``normals`` (H, W, 3) on the crop with the pixels lit by a specular highlight given the
    highlight's half vector (:func:`unps.inverse.highlights.highlight_normals`), and (H, W) bool,
    those pixels.

    Args:
        directions: (n, 3) and scales: (n,) the lights the fit rendered with; black: (H, W) the
            pixels black in every image (they hold no highlight).
    """
    mask = cropped.mask & ~black
    shading = cropped.images[:, mask].mean(-1) / scales[:, None]
    half, lit = highlight_normals(shading, directions)
    fitted = normals[mask]
    share = float(lit.sum() / cropped.mask.sum())
    if lit.any():
        log.info("%.1f%% of the object is lit by a specular highlight the fit's loss leaves out: "
                 "there the normal is the highlight's half vector, %.1f° from the fit's on average",
                 100 * share, float(angular_error(half[lit], fitted[lit]).mean()))
    shown = normals.copy()
    shown[mask] = np.where(lit[:, None], half, fitted)
    highlit = np.zeros_like(mask)
    highlit[mask] = lit
    return shown, highlit


def with_read_out_rules(cropped: Subject, normals: np.ndarray, directions: np.ndarray, scales: np.ndarray,
                        preset: Preset, black: np.ndarray, faint: np.ndarray,
                        held: np.ndarray | None) -> tuple[np.ndarray, dict]:
    """The read-out's rules for the pixels whose own images pin their normals poorly (beyond the
    paper): those lit by a specular highlight take its half vector (``preset.highlights``); the
    surface is continued across the black ones and the faintly lit ones whose values hold no
    shading (``preset.continue_black``); the dark ones the fit held go ``preset.continue_held`` of
    the way to it.

    Args:
        cropped: the subject's crop, (H, W) grid; normals: (H, W, 3) the fit's there.
        directions: (n, 3) and scales: (n,) the lights the fit rendered with.
        preset: its read-out fields above and ``continue_outline``.
        black, faint: (H, W) bool, the pixels black in every image and the faintly lit ones
            (:func:`unps.data.checks.black_everywhere`, :func:`unps.data.checks.faintly_lit`).
        held: (H, W) bool, the pixels the fit held (:func:`held_from_solve`); None: none.

    Returns:
        (H, W, 3) normals, and the shares of the object black in every image, faintly lit (no
        highlight lights them, their values hold no shading: :func:`unshaded`), lit by a highlight
        and held and moved (the last two None where their rule is off), keyed as in
        ``metrics.json``.
    """
    mask = cropped.mask
    highlight_share, highlit = None, np.zeros_like(black)
    if preset.highlights:
        normals, highlit = with_highlights(cropped, normals, directions, scales, black)
        highlight_share = float(highlit.sum() / mask.sum())
    none = np.zeros_like(black)
    continuing = held is not None and preset.continue_held > 0
    faint = faint & ~highlit
    if faint.any():
        faint[faint] = unshaded(cropped.images[:, faint].mean(-1) / scales[:, None], directions)
    unlit_held = held & mask & ~highlit & ~black & ~faint if continuing else none
    held_share = float(unlit_held.sum() / mask.sum()) if continuing else None
    if unlit_held.any():
        log.info("%.1f%% of the object is of a dark material the fit held and no highlight lights: "
                 "its normals are taken %.0f%% of the way to the surface continued from the pixels "
                 "around it (preset.continue_held)", 100 * held_share, 100 * preset.continue_held)
    unlit = black | faint if preset.continue_black else none
    normals = with_surface_continued(normals, mask, unlit, unlit_held, preset.continue_held,
                                     preset.continue_outline)
    black_share, faint_share = float(black.sum() / mask.sum()), float(faint.sum() / mask.sum())
    if black.any():
        log.info("%.1f%% of the object is black in every image (no value above its two lowest "
                 "levels): its normals are %s", 100 * black_share,
                 "the surface continued from the pixels around it" if preset.continue_black else
                 "the normal network's guess (preset.continue_black=false)")
    if faint.any():
        log.info("%.1f%% of the object is faintly lit (no value above its %d lowest levels, more than the "
                 "first in at most %.0f%% of the images, not following Lambert's cosine) and no "
                 "highlight lights it: its normals are %s",
                 100 * faint_share, FAINT_LEVELS, 100 * FAINT_SHARE,
                 "the surface continued from the pixels around it" if preset.continue_black else
                 "the fit's (preset.continue_black=false)")
    return normals, {"black_share": black_share, "faint_share": faint_share,
                     "highlight_share": highlight_share, "continued_held_share": held_share}


def unshaded(shading: np.ndarray, lights: np.ndarray) -> np.ndarray:
    """(P,) bool, the pixels whose values do not follow Lambert's cosine: the relative residual of
    their Lambertian fit above :data:`FAINT_MISFIT` (:func:`unps.inverse.highlights.lambertian_misfit`),
    or too few lit values to tell. A dark diffuse material's few levels still carry its shading,
    and the fit reads it (DiLiGenT pot1's dark glaze); a dark glossy one's speckle does not (the
    light benchmark's dark metals and phenolics, ``experiments/light_benchmark/faint_pixels.txt``).

    Args:
        shading: (n, P) faintly lit pixels' values (channels averaged) divided by the light
            intensities; lights: (n, 3) unit directions.
    """
    return lambertian_misfit(shading, lights) > FAINT_MISFIT


def with_surface_continued(normals: np.ndarray, mask: np.ndarray, black: np.ndarray, held: np.ndarray,
                           share: float, outline: bool = True) -> np.ndarray:
    """``normals`` (H, W, 3) with the surface continued (:func:`unps.geometry.continue_surface`)
    across the ``black`` pixels, and the ``held`` ones taken ``share`` of the way from their
    normals to the surface continued across ``held | black`` (the normalised blend).

    The black pixels' continuation keeps the held ones among its anchors, with their own normals:
    without them it cost the light benchmark's golf ball 1.7° (``experiments/light_benchmark``).

    Args:
        mask, black, held: (H, W) bool; ``black`` and ``held`` inside ``mask`` and apart.
        share: in [0, 1].
        outline: the continued surface turns away at the object's outline as the seen outline
            does (``preset.continue_outline``; :func:`unps.geometry.outline_normals`).
    """
    out = continue_surface(normals, mask, black, outline=outline) if black.any() else normals.copy()
    if held.any() and share > 0:
        surface = continue_surface(normals, mask, held | black, outline=outline)[held]
        out[held] = unit((1 - share) * normals[held] + share * surface)
    return out


def unit(vectors: np.ndarray) -> np.ndarray:
    """(…, 3) vectors scaled to unit length."""
    return vectors / np.maximum(np.linalg.norm(vectors, axis=-1, keepdims=True), 1e-12)


def build_system(work: Subject, light_directions: np.ndarray, preset: Preset,
                 interreflection: InterreflectionModel,
                 refine_lights: bool, run_fingerprint: str, usable: np.ndarray | None = None,
                 headroom: np.ndarray | None = None,
                 device: torch.device = torch.device("cpu")) -> tuple[InverseRendering, float]:
    """The initialisation, the networks and the interreflection solve for the working grid,
    around one :class:`InverseRendering`; also the white level the images were divided by.
    ``usable``: (n, h, w) 1 for values the loss may use (:func:`unclipped`), None for all;
    ``headroom``: (n, h, w, 3) what each value may stand for above its reading, in the units of
    ``work.images`` (:func:`black_headroom`), None for none; ``device``: where the
    initialisation runs.

    Raises:
        InputError: the images are black on the object.
    """
    init = initial_estimate(work, light_directions, preset.init, device)
    mask = work.mask
    scale = float(np.percentile(work.images[:, mask], 99))    # the white level: images in [0, ~1]
    if not scale > 0:
        raise InputError(f"subject {work.name!r}: the images are black on the object (99th "
                         f"percentile {scale}); nothing to fit")
    images = torch.as_tensor(work.images / scale).permute(0, 3, 1, 2).contiguous()

    solver = None
    if interreflection.enabled:
        stated = interreflection.albedo
        albedo = init.albedo.mean(-1)
        albedo = albedo * reflectance_scale(albedo[mask], stated)
        solver = Interreflection(mask, albedo, interreflection.downsample, interreflection.occlusion)
        log.info("interreflections: %d facets (×%d), median reflectance %.3f (%s)", solver.n_facets,
                 solver.factor, float(solver.albedo.median()),
                 "the robust initialisation's albedo" if stated is None
                 else f"interreflection.albedo={stated}")

    precision = preset.network_precision(device)
    if precision == "bf16-mixed" and device.type != "cuda":
        if native_bfloat16(device):
            log.info("preset.precision=%s on a CPU with bfloat16 instructions (AMX or AVX512-BF16): the "
                     "networks' convolutions in bfloat16, faster here than in float32 "
                     "(preset.precision=32-true keeps float32)", preset.precision)
        else:
            log.warning("preset.precision=bf16-mixed on %s: this CPU has no bfloat16 instructions (AMX, "
                        "AVX512-BF16), so its bfloat16 convolutions may run several times slower than "
                        "float32", device)
    normal_net = NormalNet(work.n_images, preset.width, preset.depth, preset.first_kernel, preset.batch_norm)
    reflectance_net = ReflectanceNet(preset.width, preset.reflectance_width, preset.reflectance_depth,
                                     preset.batch_norm, preset.reflectance_branch, preset.feature_scale())
    true_normals = (None if work.normals is None
                    else torch.as_tensor(work.normals).permute(2, 0, 1).contiguous())
    system = InverseRendering(
        normal_net, reflectance_net, images, mask, torch.as_tensor(light_directions, dtype=torch.float32),
        torch.as_tensor(init.normals).permute(2, 0, 1).contiguous(), solver, preset.schedule,
        refine_lights=refine_lights, true_normals=true_normals, fingerprint=run_fingerprint,
        usable=None if usable is None else torch.as_tensor(usable)[:, None],
        shadows=preset.cast_shadows, precision=precision,
        headroom=None if headroom is None else torch.as_tensor(headroom / scale).permute(0, 3, 1, 2),
        highlit=(torch.as_tensor(highlit_images(work, light_directions))
                 if preset.schedule.highlight_hold > 0 else None),
        albedo=torch.as_tensor(init.albedo.mean(-1), dtype=torch.float32)[None, None])
    return system, scale


HIGHLIGHT_OUTLINE_GAP = 4.0
"""Pixels nearer than this to the object's outline, in pixels of a grid of
:data:`GAP_REFERENCE_PIXELS` object pixels (the fast preset's working grid; on a larger grid the
gap grows with the object's width), are not held toward a highlight's half vector: there the
surface turns away from the view further than any light of a dome can show a highlight on it, and
the pixels that pass the highlight test are something else (DiLiGenT pot1's, 1-3 pixels from its
outline on its ×4 grid: 58° from the truth; the light benchmark's, 1-2 pixels from it: 8-45°,
against 1-5° further in)."""
GAP_REFERENCE_PIXELS = 4000


def highlit_images(work: Subject, light_directions: np.ndarray) -> np.ndarray:
    """(H, W) int64 on the working grid: the image whose light shows each pixel a specular
    highlight (:func:`unps.inverse.highlights.highlight_normals`, on the grid's block-averaged
    values), −1 where none does or the pixel lies within the outline's gap
    (:data:`HIGHLIGHT_OUTLINE_GAP`)."""
    shading = work.images[:, work.mask].mean(-1)
    _, lit = highlight_normals(shading, light_directions)
    gap = HIGHLIGHT_OUTLINE_GAP * np.sqrt(max(work.mask.sum() / GAP_REFERENCE_PIXELS, 1.0))
    lit &= outline_distance(work.mask)[work.mask] >= gap
    index = np.full(work.mask.shape, -1, np.int64)
    index[work.mask] = np.where(lit, shading.argmax(0), -1)
    if lit.any():
        log.info("%.1f%% of the working grid is lit by a specular highlight: pulled toward its half vector "
                 "in every step (preset.highlight_hold)", 100 * lit.mean())
    return index


def initial_estimate(subject: Subject, light_directions: np.ndarray, init: str,
                     device: torch.device) -> Estimate:
    """N_init and the albedo P (``preset.init``): the robust low-rank initialisation or
    Woodham's least squares on every pixel."""
    if init == "least_squares":
        return woodham(subject, light_directions)
    return robust_init(subject, light_directions, device=device)


def distance_from_start(normals: np.ndarray, start: np.ndarray, mask: np.ndarray, init: str) -> float:
    """The mean angle in degrees between the fitted normals and the fit's start N_init, (h, w, 3)
    unit each, over the (h, w) ``mask``; a warning when it exceeds :data:`FAR_FROM_START_DEG`
    (``init``: ``preset.init``, named in it). Where the images hardly pin the normals (dark or
    glossy materials, wrong lights) a fit can drift far from its start while its loss still falls."""
    moved = float(angular_error(normals, start)[mask].mean())
    if moved > FAR_FROM_START_DEG:
        log.warning("the fit ended %.1f° on average from its start, the %s initialisation (more than "
                    "%.0f°): where the images hardly pin the normals (dark or glossy materials, wrong "
                    "lights) it can drift; compare with method=rpca, or try preset.residual=relative",
                    moved, init.replace("_", " "), FAR_FROM_START_DEG)
    return moved


def interreflection_bend(normals: np.ndarray, pseudo_normals: np.ndarray, mask: np.ndarray) -> dict:
    """How far ξ_n2 turns the fitted normals: the angle between N_o and N_ny, (h, w, 3) unit
    each, over the (h, w) ``mask``, as ``mean`` and ``max`` in degrees. It says how much the
    interreflection model explains on a subject (0 on convex shapes, whose facets see nothing)."""
    bend = angular_error(normals, pseudo_normals)[mask]
    return {"mean": float(bend.mean()), "max": float(bend.max())}


@torch.no_grad()
def final_rendering(system: InverseRendering, chunk: int, scale: float) -> dict:
    """Normals N_o and N_ny (the rendered, interreflected ones; N_o without interreflections),
    reflectance maps and reconstructions of every image, without input noise.

    Returns numpy arrays on the working grid; images are multiplied by ``scale`` (the factor
    they were normalised by) to come back in the subject's units.
    """
    system.eval()
    n = system.images.shape[0]
    reflectance, reconstruction = [], []
    for start in range(0, n, chunk):
        out = system.render(torch.arange(start, min(start + chunk, n), device=system.device), noise=False)
        reflectance.append(out["reflectance"].cpu())
        reconstruction.append(out["reconstruction"].cpu())
    normals = out["normals"][0].permute(1, 2, 0).cpu().numpy()
    pseudo_normals = out["pseudo_normals"][0].permute(1, 2, 0).cpu().numpy()
    directions, scales = system.lights()

    def hwc(parts):
        return torch.cat(parts).permute(0, 2, 3, 1).numpy() * scale

    return {"normals": normals, "pseudo_normals": pseudo_normals, "reflectance": hwc(reflectance),
            "reconstruction": hwc(reconstruction), "light_directions": directions.cpu().numpy(),
            "light_scales": scales.cpu().numpy()}

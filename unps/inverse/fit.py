"""``method=unps``: the paper's per-subject neural inverse rendering, end to end.

    python -m unps.fit method=unps                          # preset=fast, interreflection=nayar
    python -m unps.fit method=unps preset=paper light=gt
    python -m unps.fit method=unps interreflection=off light=refine

The subject is cropped to its mask (and, when the preset caps the pixel count, block-averaged
to a working grid); the robust initialisation gives N_init and the albedo P; the networks are
fitted for ``steps`` Adam steps (:class:`unps.inverse.system.InverseRendering`); the normals
come back on the subject's own grid (from a coarser working grid with the initialisation's
finer detail added: :func:`upsample_with_detail`). With an output folder, checkpoints land in
``checkpoints/`` every ``update_every`` steps and a rerun in the same folder resumes.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import math
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import torch
from scipy.ndimage import distance_transform_edt

from unps.data.subject import Subject
from unps.errors import Diverged, InputError
from unps.inverse.interreflection import Interreflection
from unps.inverse.networks import NormalNet, ReflectanceNet
from unps.inverse.system import InverseRendering, Schedule
from unps.metrics import angular_error
from unps.solvers.nayar import reflectance_scale
from unps.solvers.rpca import robust_init
from unps.solvers.woodham import Estimate, rgb_albedo
from unps.timing import stage

log = logging.getLogger(__name__)

# Lightning warnings that do not apply to a one-subject fit: the "data loader" is a step counter
# whose random draws the checkpoints restore, and a deprecation inside Lightning itself.
LIGHTNING_NOISE = (".*dataloader is not resumable.*", ".*does not have many workers.*",
                   ".*LeafSpec.*is deprecated.*")
CROP_MARGIN = 4   # pixels of background kept around the object so convolutions see its edge


@dataclass(frozen=True)
class Preset:
    """Network sizes, working resolution and schedule (``preset=fast|paper``).

    Attributes:
        name: label.
        width, depth, first_kernel: the normal network (:class:`NormalNet`).
        reflectance_width, reflectance_depth: f_sp (:class:`ReflectanceNet`).
        max_pixels: object pixels on the working grid; larger subjects are block-averaged by the
            smallest whole factor that fits, and the normals upsampled back. None = full resolution.
        schedule: the optimisation's :class:`Schedule`.
    """

    name: str = "paper"
    width: int = 384
    depth: int = 4
    first_kernel: int = 3
    reflectance_width: int = 16
    reflectance_depth: int = 3
    max_pixels: int | None = None
    schedule: Schedule = Schedule()

    @classmethod
    def from_config(cls, fields: dict) -> Preset:
        """From the flat ``preset`` config node: :class:`Schedule`'s keys go to ``schedule``."""
        timing = {f.name for f in dataclasses.fields(Schedule)}
        return cls(**{k: v for k, v in fields.items() if k not in timing},
                   schedule=Schedule(**{k: v for k, v in fields.items() if k in timing}))


@dataclass(frozen=True)
class Rendering:
    """What the inverse renderer explains, on its working grid (h, w).

    Attributes:
        mask: (h, w) bool.
        observed, reconstruction, reflectance: (n, h, w, 3) float32, the images divided by their
            intensities, the model's X̃_i, and f_sp's ρ_i.
        light_directions: (n, 3) the directions used at the end (refined or as given).
        light_scales: (n,) intensity corrections (all 1 unless refined).
        info: counts and settings for metrics.json.
    """

    mask: np.ndarray
    observed: np.ndarray
    reconstruction: np.ndarray
    reflectance: np.ndarray
    light_directions: np.ndarray
    light_scales: np.ndarray
    info: dict


def working_factor(object_pixels: int, max_pixels: int | None) -> int:
    """The smallest whole factor f with object_pixels / f² ≤ max_pixels (1 when uncapped)."""
    if max_pixels is None or object_pixels <= max_pixels:
        return 1
    return math.ceil(math.sqrt(object_pixels / max_pixels))


def upsample_normals(normals: np.ndarray, mask: np.ndarray, shape: tuple[int, int],
                     factor: int) -> np.ndarray:
    """(h, w, 3) normals of a grid ``factor`` times coarser → (H, W, 3) unit normals.

    Values off the coarse mask are first filled from the nearest object pixel, so the bilinear
    interpolation near the silhouette mixes only object normals.
    """
    _, (rows, cols) = distance_transform_edt(~mask, return_indices=True)
    filled = normals[rows, cols].astype(np.float32)
    size = (mask.shape[1] * factor, mask.shape[0] * factor)
    up = cv2.resize(filled, size, interpolation=cv2.INTER_LINEAR)[: shape[0], : shape[1]]
    return up / np.maximum(np.linalg.norm(up, axis=-1, keepdims=True), 1e-12)


def fingerprint(subject: Subject, light_directions: np.ndarray, settings: dict) -> str:
    """SHA-256 of the working data and settings: a checkpoint resumes only the run it came from."""
    digest = hashlib.sha256()
    for array in (subject.images, subject.mask, light_directions):
        digest.update(np.ascontiguousarray(array).tobytes())
    digest.update(json.dumps(settings, sort_keys=True, default=lambda v: np.asarray(v).tolist()).encode())
    return digest.hexdigest()


def neural_inverse_rendering(subject: Subject, light_directions: np.ndarray, preset: dict,
                             interreflection: dict, refine_lights: bool = False,
                             output_dir: str | Path | None = None) -> Estimate:
    """Fit the inverse-rendering networks to one subject.

    Args:
        subject: images divided by their intensities.
        light_directions: (n, 3) unit, surface to light (estimated or calibrated).
        preset: :class:`Preset` fields.
        interreflection: ``enabled`` (bool), ``downsample`` (facet grid factor), ``occlusion``.
        refine_lights: learn the lights jointly, starting from ``light_directions``.
        output_dir: run folder for checkpoints (resumed from when present) and TensorBoard;
            None keeps everything in memory.

    Returns:
        Normals and albedo on the subject's grid, with the :class:`Rendering` in ``rendering``.
    """
    settings = {"preset": dict(preset), "interreflection": dict(interreflection),
                "refine_lights": refine_lights}
    preset = Preset.from_config(preset)
    schedule = preset.schedule
    cropped = subject.crop_to_mask(CROP_MARGIN)
    factor = working_factor(int(cropped.mask.sum()), preset.max_pixels)
    work = cropped.downsample(factor)
    h, w = work.resolution
    log.info("unps (%s preset): working grid %d×%d (%d object pixels, ×%d coarser than the subject), "
             "%d images", preset.name, w, h, work.mask.sum(), factor, work.n_images)

    with stage("system assembly"):
        system, scale = build_system(work, light_directions, preset, interreflection, refine_lights,
                                     fingerprint(work, light_directions, settings))
    solver = system.interreflection
    parameters = sum(p.numel() for p in system.parameters() if p.requires_grad)
    log.info("networks: %.2f M parameters; %d steps", parameters / 1e6, schedule.steps)

    with stage("steps"):
        seconds, resumed_from = train(system, schedule, output_dir, subject.name)
    steps_run = schedule.steps - resumed_from
    log.info("fitted %d steps in %.1f s (%.3f s/step)", steps_run, seconds, seconds / max(steps_run, 1))

    with stage("read-out"):
        rendering = final_rendering(system, schedule.images_per_step or 16, scale)
        normals, pseudo_normals = rendering.pop("normals"), rendering.pop("pseudo_normals")
        bend = interreflection_bend(normals, pseudo_normals, work.mask) if solver else None
        if factor > 1:
            coarse_init = system.init_normals[0].permute(1, 2, 0).cpu().numpy()
            normals = upsample_with_detail(normals, coarse_init, robust_init(cropped, light_directions).normals,
                                           work.mask, factor)
        normals, albedo = on_subject_grid(normals, cropped, subject, rendering["light_directions"],
                                          rendering["light_scales"])
    if bend is not None:
        log.info("interreflections bend the rendered normals by %.2f° on average (%.2f° at most)",
                 bend["mean"], bend["max"])
    info = {"fit_resolution": [h, w], "fit_downsample": factor, "fit_steps": schedule.steps,
            "fit_s_per_step": seconds / max(steps_run, 1), "resumed_from_step": resumed_from,
            "parameters": parameters, "facets": solver.n_facets if solver else 0, "preset": preset.name,
            "interreflection": bool(interreflection["enabled"]),
            "facet_downsample": solver.factor if solver else None,
            "interreflection_bend_deg": bend["mean"] if bend else None}
    return Estimate(normals, albedo,
                    rendering=Rendering(mask=work.mask, observed=work.images, info=info, **rendering))


def build_system(work: Subject, light_directions: np.ndarray, preset: Preset, interreflection: dict,
                 refine_lights: bool, run_fingerprint: str) -> tuple[InverseRendering, float]:
    """The robust initialisation, the networks and the interreflection solve for the working grid,
    around one :class:`InverseRendering`; also the white level the images were divided by.

    Raises:
        InputError: the images are black on the object.
    """
    init = robust_init(work, light_directions)
    mask = work.mask
    scale = float(np.percentile(work.images[:, mask], 99))    # the white level: images in [0, ~1]
    if not scale > 0:
        raise InputError(f"subject {work.name!r}: the images are black on the object (99th "
                         f"percentile {scale}); nothing to fit")
    images = torch.as_tensor(work.images / scale).permute(0, 3, 1, 2).contiguous()

    solver = None
    if interreflection["enabled"]:
        stated = interreflection["albedo"]
        albedo = init.albedo.mean(-1)
        albedo = albedo * reflectance_scale(albedo[mask], stated)
        solver = Interreflection(mask, albedo, interreflection["downsample"],
                                 interreflection["occlusion"])
        log.info("interreflections: %d facets (×%d), median reflectance %.3f (%s)", solver.n_facets,
                 solver.factor, float(solver.albedo.median()),
                 "the robust initialisation's albedo" if stated is None
                 else f"interreflection.albedo={stated}")

    normal_net = NormalNet(work.n_images, preset.width, preset.depth, preset.first_kernel)
    reflectance_net = ReflectanceNet(preset.width, preset.reflectance_width, preset.reflectance_depth)
    true_normals = (None if work.normals is None
                    else torch.as_tensor(work.normals).permute(2, 0, 1).contiguous())
    system = InverseRendering(
        normal_net, reflectance_net, images, mask, torch.as_tensor(light_directions, dtype=torch.float32),
        torch.as_tensor(init.normals).permute(2, 0, 1).contiguous(), solver, preset.schedule,
        refine_lights=refine_lights, true_normals=true_normals, fingerprint=run_fingerprint)
    return system, scale


def interreflection_bend(normals: np.ndarray, pseudo_normals: np.ndarray, mask: np.ndarray) -> dict:
    """How far ξ_n2 turns the fitted normals: the angle between N_o and N_ny, (h, w, 3) unit
    each, over the (h, w) ``mask``, as ``mean`` and ``max`` in degrees. It says how much the
    interreflection model explains on a subject (0 on convex shapes, whose facets see nothing)."""
    bend = angular_error(normals, pseudo_normals)[mask]
    return {"mean": float(bend.mean()), "max": float(bend.max())}


def upsample_with_detail(normals: np.ndarray, coarse_init: np.ndarray, fine_init: np.ndarray,
                         mask: np.ndarray, factor: int) -> np.ndarray:
    """Fitted (h, w, 3) normals on a grid ``factor`` times coarser (object ``mask``) → (H, W, 3)
    unit normals on the fine grid, with the detail the coarse grid cannot hold put back.

    The detail is what the robust initialisation has on the fine grid and loses on the coarse
    one: fine_init − upsampled coarse_init. It is added to the upsampled fit before normalising,
    so the fit decides the shape at its own scale and the initialisation only adds the finer
    scales (on DiLiGenT at ×2 this lowers the MAE by 0.4–0.6° on pot1 and 0.1–0.2° on cat).

    Args:
        normals: (h, w, 3) fitted unit normals.
        coarse_init: (h, w, 3) robust initialisation on the coarse grid.
        fine_init: (H, W, 3) robust initialisation on the fine grid, with H ≤ h·factor, W ≤ w·factor.
        mask: (h, w) bool, the coarse grid's object.

    Returns:
        (H, W, 3) unit normals on the fine grid's object (where fine_init is nonzero); off it the
        values are not normals and the caller masks them (:func:`uncrop` does).
    """
    shape = fine_init.shape[:2]
    detail = fine_init - upsample_normals(coarse_init, mask, shape, factor)
    combined = upsample_normals(normals, mask, shape, factor) + detail
    return combined / np.maximum(np.linalg.norm(combined, axis=-1, keepdims=True), 1e-12)


def on_subject_grid(normals: np.ndarray, cropped: Subject, subject: Subject,
                    light_directions: np.ndarray, light_scales: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(h, w, 3) unit normals on ``cropped``'s grid (a crop of ``subject``) → (H, W, 3) unit
    normals on the subject's grid, and the RGB albedo there by least squares under the lights used
    (directions (n, 3), intensity scales (n,)).
    """
    full_normals = uncrop(normals, cropped, subject)
    pixels = subject.images[:, subject.mask] / light_scales[:, None, None]
    albedo = np.zeros_like(full_normals)
    albedo[subject.mask] = rgb_albedo(pixels, full_normals[subject.mask], light_directions)
    return full_normals, albedo


def train(system: InverseRendering, schedule: Schedule, output_dir: str | Path | None,
          name: str) -> tuple[float, int]:
    """Run the schedule with Lightning, resuming from ``<output_dir>/checkpoints/last.ckpt`` when
    it holds this run (same fingerprint); returns the seconds spent and the step resumed from.

    Raises:
        InputError: the checkpoint belongs to another run.
        Diverged: the loss stopped being finite; the message names the last good checkpoint.
    """
    import lightning as L
    from lightning.pytorch.callbacks import ModelCheckpoint
    from lightning.pytorch.loggers import TensorBoardLogger

    from unps.inverse.callbacks import FitPictures, ProgressLog

    ckpt_path, resumed_from = None, 0
    progress = ProgressLog(every=schedule.update_every)
    options: dict = dict(logger=False, enable_checkpointing=False, callbacks=[progress])
    if output_dir is not None:
        out = Path(output_dir)
        last = out / "checkpoints" / "last.ckpt"
        if last.is_file():
            saved = torch.load(last, map_location="cpu", weights_only=False)
            if saved.get("unps_fingerprint") != system.fingerprint:
                raise InputError(f"{last}: this checkpoint belongs to another run (different images, "
                                 f"lights or settings); choose a new hydra.run.dir or delete it")
            ckpt_path, resumed_from = str(last), int(saved["global_step"])
            log.info("resuming from %s at step %d", last, resumed_from)
        options = dict(
            logger=TensorBoardLogger(str(out), name="tensorboard", version=""),
            callbacks=[ModelCheckpoint(dirpath=out / "checkpoints", save_last=True, save_top_k=0,
                                       every_n_train_steps=schedule.update_every),
                       FitPictures(every=schedule.update_every), progress])
    trainer = L.Trainer(max_steps=schedule.steps, accelerator="auto", devices=1, log_every_n_steps=10,
                        enable_model_summary=False, enable_progress_bar=False, num_sanity_val_steps=0,
                        **options)
    start = time.perf_counter()
    try:
        with warnings.catch_warnings():
            for message in LIGHTNING_NOISE:
                warnings.filterwarnings("ignore", message=message)
            trainer.fit(system, ckpt_path=ckpt_path)
    except Diverged as e:
        kept = (f"; the last good state (step {schedule.update_every}·k) is kept in "
                f"{Path(output_dir) / 'checkpoints' / 'last.ckpt'}" if output_dir is not None else "")
        raise Diverged(f"unps diverged on {name!r}: {e}{kept}; try a lower preset.lr") from None
    if trainer.global_step < schedule.steps:
        raise RuntimeError(f"the fit stopped at step {trainer.global_step} of {schedule.steps}; "
                           f"rerun in the same folder to resume")
    return time.perf_counter() - start, resumed_from


def uncrop(normals: np.ndarray, cropped: Subject, subject: Subject) -> np.ndarray:
    """(h, w, 3) normals on ``cropped``'s grid (a crop of ``subject``) → (H, W, 3) on the
    subject's, zero off its mask."""
    full = np.zeros(subject.resolution + (3,), np.float32)
    top = cropped.frame.top - subject.frame.top
    left = cropped.frame.left - subject.frame.left
    h, w = cropped.resolution
    full[top: top + h, left: left + w] = normals
    full[~subject.mask] = 0
    return full


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

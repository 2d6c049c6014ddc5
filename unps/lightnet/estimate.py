"""Estimating a subject's lights with the trained network (``light=estimated``)."""

from __future__ import annotations

import dataclasses
import logging

import numpy as np
import torch
import torch.nn.functional as F

from unps.data.subject import Subject
from unps.errors import InputError
from unps.lightnet.bins import decode_lights
from unps.lightnet.symmetry import SYMMETRIES, frame_matrix, mean_direction, transform_images
from unps.lightnet.system import load_lightnet
from unps.lights import Lights, light_errors
from unps.lights.contour import align_to_contour
from unps.lights.reversal import resolve_reversal
from unps.lights.selfcal import SelfCalibration, self_calibrate
from unps.timing import stage

log = logging.getLogger(__name__)

SPREAD_WARNING = 10.0   # degrees; the shipped weights stay under 4.1° on every subject measured
                        # (experiments/light_estimation/README.md), flipped ones included


def network_input(images: np.ndarray, mask: np.ndarray, resolution: int
                  ) -> tuple[torch.Tensor, torch.Tensor]:
    """Crop to the mask's bounding square and resize to the network's resolution.

    Only the network sees this; every other step uses the full-resolution images.

    Args:
        images: (n, H, W, 3) captured images (not divided by intensities).
        mask: (H, W) bool.

    Returns:
        images (1, n, 3, R, R) and mask (1, 1, R, R), float32.
    """
    rows, cols = np.nonzero(mask)
    centre_r, centre_c = (rows.min() + rows.max()) / 2, (cols.min() + cols.max()) / 2
    half = max(rows.max() - rows.min(), cols.max() - cols.min()) / 2 + 1
    top, left = int(np.floor(centre_r - half)), int(np.floor(centre_c - half))
    side = int(np.ceil(2 * half))
    pad = [(max(0, -top), max(0, top + side - mask.shape[0])),
           (max(0, -left), max(0, left + side - mask.shape[1]))]
    window = (slice(top + pad[0][0], top + pad[0][0] + side),
              slice(left + pad[1][0], left + pad[1][0] + side))
    m = np.pad(mask, pad)[window].astype(np.float32)
    x = np.pad(images * mask[..., None], [(0, 0), *pad, (0, 0)])[:, window[0], window[1]]
    x = torch.as_tensor(np.ascontiguousarray(x)).permute(0, 3, 1, 2)
    x = F.interpolate(x, size=(resolution, resolution), mode="area")
    m = F.interpolate(torch.as_tensor(m)[None, None], size=(resolution, resolution), mode="area")
    return x[None], (m > 0.5).float()


def estimate_lights(subject: Subject, checkpoint: str | None = None, soft_decode: bool = True,
                    symmetric: bool = True, reversal: str | None = "shadows",
                    align: str | None = None, selfcal: SelfCalibration | None = None) -> Lights:
    """Directions and relative intensities of every image, from the captured images alone.

    Args:
        subject: its captured images (``observed_images()``) are used; known lights are not.
        checkpoint: weights to use; default: the weights shipped with unps.
        soft_decode: soft-arg-max decoding of the bins (else arg-max).
        symmetric: average the network's estimates under the eight symmetries of the square
            (:mod:`unps.lightnet.symmetry`; beyond the paper) and warn when they disagree by more
            than :data:`SPREAD_WARNING` (median over the lights); False runs the network once.
        reversal: ``"shadows"`` turns the network's directions half a turn about the view axis
            when the shadows they cast over the reversed surface match the images better
            (:func:`unps.lights.reversal.resolve_reversal`; beyond the paper), None keeps them.
        align: ``"contour"`` rotates the network's directions so that the occluding contour's
            normals face sideways (:func:`unps.lights.contour.align_to_contour`; beyond the
            paper), None keeps them as the network gave them.
        selfcal: settings of the self-calibration that then fits the lights to the images
            (:func:`unps.lights.selfcal.self_calibrate`; beyond the paper), None skips it.

    Raises:
        InputError: another ``reversal`` or ``align``.

    Returns:
        Lights with (n, 3) unit directions and (n, 3) intensities (one value per image,
        repeated for RGB; mean 1 over the images), and the network's ``spread_deg``.
    """
    if reversal not in (None, "shadows"):
        raise InputError(f"light.reversal must be shadows or null, got {reversal!r}")
    if align not in (None, "contour"):
        raise InputError(f"light.align must be contour or null, got {align!r}")
    with stage("light network"):
        lights = network_estimate(subject, checkpoint, soft_decode, symmetric)
    weights = checkpoint or "shipped weights"
    log_stage(f"network ({weights}, mean of 8 symmetries)" if symmetric else f"network ({weights})",
              lights, subject)
    spread = lights.spread_deg
    if spread is not None:
        warn_if_uncertain(spread)
    normals = None          # the robust initialisation's with the lights, shared by the next two
    if reversal == "shadows":
        with stage("reversal test"):
            lights, normals = resolve_reversal(subject, lights)
        log_stage("reversal test", lights, subject)
    if align == "contour":
        with stage("contour alignment"):
            lights = align_to_contour(subject, lights, normals)
        log_stage("contour alignment", lights, subject)
    if selfcal is not None:
        with stage("self-calibration"):
            lights = self_calibrate(subject, lights, selfcal)
        log_stage("self-calibration", lights, subject)
    return dataclasses.replace(lights, spread_deg=spread)


def warn_if_uncertain(spread: np.ndarray) -> None:
    """Log the spread of the symmetric estimates; a warning when its median is large."""
    median = float(np.median(spread))
    log.info("the light network's estimates under the 8 symmetries of the image disagree by %.1f° "
             "(median over the lights; %.1f° at most)", median, float(spread.max()))
    if median > SPREAD_WARNING:
        log.warning("the estimated lights are uncertain: the light network's estimates under the 8 "
                    "symmetries of the image disagree by %.1f° (median over the lights, above %.0f°); "
                    "expect light errors of tens of degrees — use light=gt if the lights are known, "
                    "or check light=selfcal against a calibration shot", median, SPREAD_WARNING)


@torch.no_grad()
def network_estimate(subject: Subject, checkpoint: str | None, soft_decode: bool,
                     symmetric: bool = False) -> Lights:
    """The light network's directions and intensities (mean 1, repeated for RGB).

    With ``symmetric``, the mean of its estimates under the eight symmetries of the square
    (:mod:`unps.lightnet.symmetry`), each mapped back, with their spread in ``spread_deg``.
    """
    net, config = load_lightnet(checkpoint)
    resolution = config["recipe"]["resolution"]
    images, mask = network_input(subject.observed_images(), subject.mask, resolution)

    def estimate(turns: int, mirror: bool) -> tuple[torch.Tensor, torch.Tensor]:
        logits = net(transform_images(images, turns, mirror), transform_images(mask, turns, mirror))
        seen, relative = decode_lights(logits["azimuth"], logits["elevation"], logits["intensity"],
                                       soft_decode)
        return seen[0] @ frame_matrix(turns, mirror), relative[0] / relative[0].mean()   # Mᵀ·l per row

    spread = None
    if symmetric:
        directions, intensities = map(torch.stack, zip(*(estimate(*g) for g in SYMMETRIES)))
        directions, spread = mean_direction(directions)
        intensities = intensities.mean(0) / intensities.mean()
    else:
        directions, intensities = estimate(0, False)
    return Lights(directions.numpy().astype(np.float32),
                  intensities[:, None].repeat(1, 3).numpy().astype(np.float32), "estimated",
                  spread_deg=None if spread is None else spread.numpy())


def log_stage(name: str, lights: Lights, subject: Subject) -> None:
    """One log line per estimation stage, with its error where the subject's lights are known."""
    errors = light_errors(lights, subject)
    known = "".join(f", {label} {errors[key]:.{digits}f}{unit}" for key, label, digits, unit in
                    (("light_dir_mae", "direction error", 2, "°"),
                     ("light_int_err", "intensity error", 3, "")) if key in errors)
    log.info("lights of %d images after %s%s", subject.n_images, name, known)

"""The trained network's estimate of a subject's lights: the first stage of ``light=estimated``."""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np
import torch
import torch.nn.functional as F

from unps.data.lights import UNSURE_SPREAD_DEG, Verdict
from unps.data.subject import Subject
from unps.device import resolve_device
from unps.errors import InputError
from unps.lightnet.bins import decode_lights
from unps.lightnet.symmetry import SYMMETRIES, frame_matrix, mean_direction, transform_images
from unps.lightnet.system import load_lightnet
from unps.lights import Lights

log = logging.getLogger(__name__)

FRAMINGS = (1.0, 0.9, 0.8, 0.7)
"""How much of the network's input the object fills in its passes (``light.framings``): training
shapes fill 0.4-1.0 of it, a capture cropped to its object all of it, and the network's answers
at these four framings point different ways, so their mean beats most of them
(``experiments/light_estimation/README.md``)."""


def network_input(images: np.ndarray, mask: np.ndarray, resolution: int, fill: float = 1.0
                  ) -> tuple[torch.Tensor, torch.Tensor]:
    """Crop a square around the mask's bounding box and resize it to the network's resolution.

    Only the network sees this; every other step uses the full-resolution images. The camera is
    orthographic, so a smaller ``fill`` shows the same scene, smaller: the lights are unchanged.

    Args:
        images: (n, H, W, 3) captured images (not divided by intensities).
        mask: (H, W) bool.
        fill: the bounding box's longer side as a share of the square's, in (0, 1]; the rest is
            empty margin, zero beyond the image.

    Returns:
        images (1, n, 3, R, R) and mask (1, 1, R, R), float32.
    """
    rows, cols = np.nonzero(mask)
    centre_r, centre_c = (rows.min() + rows.max()) / 2, (cols.min() + cols.max()) / 2
    half = (max(rows.max() - rows.min(), cols.max() - cols.min()) / 2 + 1) / fill
    top, left = int(np.floor(centre_r - half)), int(np.floor(centre_c - half))
    side = int(np.ceil(2 * half))
    size = (resolution, resolution)
    m = F.interpolate(_square(mask[..., None], top, left, side), size, mode="area")
    x = torch.cat([F.interpolate(_square(image * mask[..., None], top, left, side), size, mode="area")
                   for image in images])                      # image by image: no copy of the stack
    return x[None], (m > 0.5).float()


def _square(values: np.ndarray, top: int, left: int, side: int) -> torch.Tensor:
    """(1, C, side, side) float32, channels last in memory: the window of (H, W, C) ``values``
    whose top left corner is (``top``, ``left``), zero where it lies beyond them."""
    square = np.zeros((side, side, values.shape[-1]), np.float32)
    r0, r1 = max(top, 0), min(top + side, values.shape[0])
    c0, c1 = max(left, 0), min(left + side, values.shape[1])
    square[r0 - top:r1 - top, c0 - left:c1 - left] = values[r0:r1, c0:c1]
    return torch.as_tensor(square)[None].permute(0, 3, 1, 2)


def network_lights(subject: Subject, checkpoint: str | None = None, soft_decode: bool = True,
                   symmetric: bool = True, framings: Sequence[float] = FRAMINGS,
                   device: str | torch.device = "auto") -> tuple[Lights, Verdict]:
    """Directions and relative intensities of every image from the captured images alone: the
    first light stage of ``light=estimated`` (the others: :mod:`unps.lights.stages`).

    Args:
        subject: its captured images (``observed_images()``) are used; known lights are not.
        checkpoint: weights to use; default: the weights shipped with unps.
        soft_decode: soft-arg-max decoding of the bins (else arg-max).
        symmetric: average the network's estimates under the eight symmetries of the square
            (:mod:`unps.lightnet.symmetry`; beyond the paper) and warn when they disagree by more
            than :data:`unps.data.lights.UNSURE_SPREAD_DEG` (median over the lights); False runs
            it once per framing.
        framings: how much of the network's square input the object fills (:func:`network_input`;
            beyond the paper), taken in turn with the symmetries (:func:`paired`) and averaged:
            the network is not scale-invariant, and its estimates at nearby scales err apart.
        device: where the network runs (:func:`unps.device.resolve_device`).

    Raises:
        InputError: no ``framings``, or one outside (0, 1].

    Returns:
        Lights with (n, 3) unit directions and (n, 3) intensities (one value per image,
        repeated for RGB; mean 1 over the images) and the network's ``spread_deg``; and the
        network's verdict (``changed``: it replaces whatever lights the subject had).
    """
    framings = checked_framings(framings)
    lights = network_estimate(subject, checkpoint, soft_decode, symmetric, framings,
                              resolve_device(device))
    passes = describe_passes(symmetric, framings)
    evidence = {}
    if lights.spread_deg is not None:
        warn_if_uncertain(lights.spread_deg)
        evidence = {"spread_median_deg": float(np.median(lights.spread_deg)),
                    "spread_max_deg": float(lights.spread_deg.max())}
    return lights, Verdict("network", "changed", f"{checkpoint or 'shipped weights'}, {passes}",
                           evidence)


def checked_framings(framings: Sequence[float] | float) -> tuple[float, ...]:
    """``light.framings`` as a tuple; one number is one framing.

    Raises:
        InputError: no framings, or one that is not a number in (0, 1].

    >>> checked_framings(0.8), checked_framings([1, 0.9])
    ((0.8,), (1.0, 0.9))
    """
    if isinstance(framings, (int, float)):
        framings = [framings]
    try:
        values = tuple(float(f) for f in framings)
    except (TypeError, ValueError):
        raise InputError(f"light.framings: a list of numbers in (0, 1], got {framings!r}") from None
    if not values or not all(0 < f <= 1 for f in values):
        raise InputError(f"light.framings: shares of the network's input the object fills, each in "
                         f"(0, 1]; got {list(values)}")
    return values


def describe_passes(symmetric: bool, framings: Sequence[float]) -> str:
    """The network's passes, for the log.

    >>> describe_passes(True, (1.0, 0.9, 0.8, 0.7))
    'mean of 8 passes: the 8 symmetries, framings 1, 0.9, 0.8, 0.7 in turn'
    >>> describe_passes(False, (1.0,))
    'one pass'
    """
    count = max(8 if symmetric else 1, len(framings))
    if count == 1:
        return "one pass"
    parts = (["the 8 symmetries"] if symmetric else []) + (
        ["framings " + ", ".join(f"{f:g}" for f in framings)] if len(framings) > 1 else [])
    return f"mean of {count} passes: " + ", ".join(parts) + (" in turn" if len(parts) > 1 else "")


def warn_if_uncertain(spread: np.ndarray) -> None:
    """Log the spread of the network's passes; a warning when its median is large."""
    median = float(np.median(spread))
    log.info("the light network's passes (symmetries and framings of the image) disagree by %.1f° "
             "(median over the lights; %.1f° at most)", median, float(spread.max()))
    if median > UNSURE_SPREAD_DEG:
        log.warning("the estimated lights are uncertain: the light network's passes over the "
                    "symmetries and framings of the image disagree by %.1f° (median over the lights, "
                    "above %.0f°); "
                    "expect light errors of tens of degrees, often a surface read inside out (the "
                    "self-calibration, light=selfcal, fits both readings) — use light=gt if the "
                    "lights are known, and check shape.png", median, UNSURE_SPREAD_DEG)


@torch.no_grad()
def network_estimate(subject: Subject, checkpoint: str | None, soft_decode: bool,
                     symmetric: bool = False, framings: Sequence[float] = (1.0,),
                     device: torch.device = torch.device("cpu")) -> Lights:
    """The light network's directions and intensities (mean 1, repeated for RGB).

    Passes over the framings (:func:`network_input`'s ``fill``) and, with ``symmetric``, the
    eight symmetries of the square (:mod:`unps.lightnet.symmetry`, each answer mapped back),
    taken in turn (:func:`paired`); more than one pass gives their mean, and their spread in
    ``spread_deg``. The passes run on ``device``.
    """
    net, config = load_lightnet(checkpoint)
    net = net.to(device)
    resolution = config["recipe"]["resolution"]
    observed = subject.observed_images()
    frames = SYMMETRIES if symmetric else ((0, False),)
    inputs = {fill: [t.to(device) for t in network_input(observed, subject.mask, resolution, fill)]
              for fill in framings}
    estimates = [network_pass(net, *inputs[fill], *frame, soft_decode=soft_decode)
                 for fill, frame in paired(framings, frames)]
    spread = None
    if len(estimates) > 1:
        directions, intensities = map(torch.stack, zip(*estimates))
        directions, spread = mean_direction(directions)
        intensities = intensities.mean(0) / intensities.mean()
    else:
        (directions, intensities), = estimates
    return Lights(directions.cpu().numpy().astype(np.float32),
                  intensities[:, None].repeat(1, 3).cpu().numpy().astype(np.float32), "estimated",
                  spread_deg=None if spread is None else spread.cpu().numpy())


@torch.no_grad()
def network_pass(net: torch.nn.Module, images: torch.Tensor, mask: torch.Tensor, turns: int = 0,
                 mirror: bool = False, soft_decode: bool = True) -> tuple[torch.Tensor, torch.Tensor]:
    """One pass of the network over one stack shown under one symmetry of the square, mapped back.

    Args:
        images: (1, n, 3, R, R) and mask (1, 1, R, R), as :func:`network_input` gives them.

    Returns:
        (n, 3) unit directions in the stack's own frame (x right, y up, z toward the camera) and
        (n,) relative intensities, mean 1.
    """
    logits, frame = pass_logits(net, images, mask, turns, mirror)
    seen, relative = decode_lights(logits["azimuth"], logits["elevation"], logits["intensity"],
                                   soft_decode)
    return seen[0] @ frame.to(seen), relative[0] / relative[0].mean()   # Mᵀ·l per row


@torch.no_grad()
def pass_logits(net: torch.nn.Module, images: torch.Tensor, mask: torch.Tensor, turns: int = 0,
                mirror: bool = False) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
    """The network's logits for one stack shown under one symmetry of the square, undecoded.

    Args:
        images: (1, n, 3, R, R) and mask (1, 1, R, R), as :func:`network_input` gives them.

    Returns:
        The logits by name (``azimuth``, ``elevation``: (1, n, bins); ``intensity``), read in the
        transformed frame, and the (3, 3) frame matrix M that maps a direction read there back to
        the stack's own frame (l = l_seen·M, one row per light).
    """
    logits = net(transform_images(images, turns, mirror), transform_images(mask, turns, mirror))
    return logits, frame_matrix(turns, mirror)


def paired(framings: Sequence[float], frames: Sequence) -> list[tuple[float, object]]:
    """The network's passes: each symmetry and each framing in turn, as many passes as the longer
    list (not every pair: eight passes take most of what the 32 pairs of 8 symmetries and 4
    framings give, ``experiments/light_estimation/README.md``).

    >>> paired([1.0, 0.8], ["a", "b", "c"])
    [(1.0, 'a'), (0.8, 'b'), (1.0, 'c')]
    """
    count = max(len(framings), len(frames))
    return [(framings[k % len(framings)], frames[k % len(frames)]) for k in range(count)]

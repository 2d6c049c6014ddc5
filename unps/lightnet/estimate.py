"""Estimating a subject's lights with the trained network (``light=estimated``)."""

from __future__ import annotations

import logging

import numpy as np
import torch
import torch.nn.functional as F

from unps.data.subject import Subject
from unps.lightnet.bins import decode_lights
from unps.lightnet.system import load_lightnet
from unps.lights import Lights
from unps.solvers.contour import align_to_contour

log = logging.getLogger(__name__)


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


@torch.no_grad()
def estimate_lights(subject: Subject, checkpoint: str | None = None, soft_decode: bool = True,
                    align: str | None = "contour") -> Lights:
    """Directions and relative intensities of every image, from the captured images alone.

    Args:
        subject: its captured images (``observed_images()``) are used; known lights are not.
        checkpoint: weights to use; default: the weights shipped with unps.
        soft_decode: soft-arg-max decoding of the bins (else arg-max).
        align: ``"contour"`` rotates the network's directions so that the occluding contour's
            normals face sideways (:func:`unps.solvers.contour.align_to_contour`; beyond the
            paper), None keeps them as the network gave them.

    Raises:
        ValueError: another ``align``.

    Returns:
        Lights with (n, 3) unit directions and (n, 3) intensities (one value per image,
        repeated for RGB; mean 1 over the images).
    """
    if align not in (None, "contour"):
        raise ValueError(f"light.align must be contour or null, got {align!r}")
    net, config = load_lightnet(checkpoint)
    resolution = config["recipe"]["resolution"]
    images, mask = network_input(subject.observed_images(), subject.mask, resolution)
    logits = net(images, mask)
    directions, intensities = decode_lights(logits["azimuth"], logits["elevation"],
                                            logits["intensity"], soft_decode)
    intensities = intensities[0] / intensities[0].mean()
    log.info("estimated %d lights with %s", subject.n_images, checkpoint or "the shipped weights")
    lights = Lights(directions[0].numpy().astype(np.float32),
                    intensities[:, None].repeat(1, 3).numpy().astype(np.float32), "estimated")
    return align_to_contour(subject, lights) if align == "contour" else lights

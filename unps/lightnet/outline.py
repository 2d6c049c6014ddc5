"""Outlines as captures draw them: a training-time change of the object's outline in the light
network's input (``data.outline_jitter``).

The training data are rendered at the network's resolution with the mask of the pixels the shape
covers, so their outline is exact and its pixels as bright as the surface. A capture's is not: its
mask was drawn by someone, or found from the images (:mod:`unps.data.automask`, which misses the
rims no light reaches), and shrinking it to the network's resolution dims the pixels the object
covers only in part. The shipped network reads the outline closely: one pixel more or less around a
benchmark object moves its lights by about a degree on average, more on bowls
(``experiments/light_benchmark/mask_outline.py``). This perturbs, on a share of the samples, the
outline the network sees: one pixel layer of it is taken away or added at random places, and its
pixels are dimmed as partly covered ones are.

Frame: (row, col) images, row 0 at the top.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

DIMMED_DOWN_TO = 0.5
"""An outline pixel the mask keeps covers at least half of it (the network's input keeps the
pixels whose area-averaged mask exceeds 0.5): its brightness is scaled by U(0.5, 1)."""


def outline_rings(mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The object's pixels that touch the background and the background's that touch the object
    (8-neighbourhoods; beyond the image's edge counts as background).

    Args:
        mask: (B, 1, H, W) float, 1 on the object.

    Returns:
        Two (B, 1, H, W) bool: the inner ring and the outer ring.

    >>> mask = torch.zeros(1, 1, 5, 5); mask[..., 1:4, 1:4] = 1
    >>> inner, outer = outline_rings(mask)
    >>> int(inner.sum()), int(outer.sum())    # the 3×3 square less its centre; the 5×5 frame
    (8, 16)
    """
    on = mask > 0.5
    grown = F.max_pool2d(mask, 3, 1, 1) > 0.5
    shrunk = -F.max_pool2d(-mask, 3, 1, 1) > 0.5
    edge = torch.ones_like(mask, dtype=torch.bool)
    edge[..., 1:-1, 1:-1] = False
    return on & ~(shrunk & ~edge), grown & ~on


def jittered_outlines(images: torch.Tensor, mask: torch.Tensor, share: float,
                      generator: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """A share of a batch's samples with their outline perturbed (module docstring): half of them
    lose each inner-ring pixel with probability ½, the other half gain each outer-ring pixel with
    probability ½ (black: the background's value); the pixels on the new outline are then dimmed
    by U(:data:`DIMMED_DOWN_TO`, 1) each. The other samples are returned as they are.

    Args:
        images: (B, n, 3, H, W), zero off the object.
        mask: (B, 1, H, W) float, 1 on the object.
        share: the chance a sample is perturbed, in [0, 1].
        generator: draws every random number, on the batch's device.

    Returns:
        The images and the mask, new tensors where any sample was perturbed.
    """
    if share <= 0:
        return images, mask
    device = mask.device
    b = mask.shape[0]
    picked = (torch.rand(b, generator=generator, device=device) < share).view(b, 1, 1, 1)
    eroding = (torch.rand(b, generator=generator, device=device) < 0.5).view(b, 1, 1, 1)
    coin = torch.rand(mask.shape, generator=generator, device=device) < 0.5
    dim = torch.empty(mask.shape, device=device).uniform_(DIMMED_DOWN_TO, 1.0, generator=generator)
    inner, outer = outline_rings(mask)
    on = mask > 0.5
    dropped = picked & eroding & inner & coin
    added = picked & ~eroding & outer & coin
    jittered = (on & ~dropped) | added
    new_inner, _ = outline_rings(jittered.float())
    scale = torch.where(picked & new_inner, dim, 1.0) * jittered
    return images * scale.unsqueeze(2), jittered.float()

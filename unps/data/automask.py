"""A mask from the images themselves, for captures that come without one (``subject.mask=auto``).

The object is where the images change with the light; the background stays dark, or as it is,
whatever the light. Per pixel, the spread of its brightness over the stack (95th percentile less
5th, so a highlight or a hot pixel does not count) is split in two by Otsu's threshold on its
logarithm; the largest connected region is the object, each of its holes is filled when it
changes more with the light than the background does (a dark patch on the object changes little,
but more than the background seen through a handle), and its outline against the background
(not the frame's edge) loses one pixel: those
pixels are partly background, and the light network, which sees the mask, reads the lights several
degrees differently with them (``experiments/automask/README.md``).

Frame: (row, col) images, row 0 at the top.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from unps.errors import InputError

FLOOR = 1e-4          # spreads below this (in units of the stack's 99th percentile) are noise
EDGE = 1              # pixels taken off the outline: partly object, partly background


@dataclass(frozen=True)
class AutoMask:
    """The automatic mask and what it rests on.

    Attributes:
        mask: (H, W) bool.
        threshold: the spread (relative to the stack's 99th percentile) that separates object
            from background.
        contrast: the object's median spread over the background's 99th percentile: tens to
            thousands where the background stays dark, near 1 where it changes with the light as
            much as the object does (a lit table, a bright backdrop) and the mask is a guess.
        regions: connected regions above the threshold before the largest was kept.
        at_edge: the mask's pixels on the image's edge: none where the whole object is in the
            frame against its background; many where a lit surface beside it (a table under a
            pot) joined it, or the object runs off the frame.
    """

    mask: np.ndarray
    threshold: float
    contrast: float
    regions: int
    at_edge: int


def otsu_threshold(values: np.ndarray, bins: int = 256) -> tuple[float, float]:
    """Otsu's threshold of a 1-D sample: the cut that maximises the between-class variance.

    Returns:
        The threshold and the share of the total variance between the two classes (binned).

    >>> values = np.r_[np.zeros(50), np.ones(50)]
    >>> threshold, separation = otsu_threshold(values)
    >>> 0 < threshold < 1, separation > 0.99
    (True, True)
    """
    counts, edges = np.histogram(values, bins=bins)
    centres = (edges[:-1] + edges[1:]) / 2
    weight = np.cumsum(counts).astype(np.float64)
    total = weight[-1]
    below = np.cumsum(counts * centres)
    mean_below = below / np.maximum(weight, 1)
    mean_above = (below[-1] - below) / np.maximum(total - weight, 1)
    between = weight * (total - weight) * (mean_below - mean_above) ** 2 / total ** 2
    k = int(np.argmax(between[:-1]))
    variance = values.var()
    return float(edges[k + 1]), float(between[k] / variance) if variance > 0 else 0.0


def auto_mask(images: np.ndarray) -> AutoMask:
    """The object's mask from a stack of its images under different lights.

    Args:
        images: (n, H, W, 3) linear images, n ≥ 2.

    Raises:
        InputError: fewer than two images, or images that do not change with the light.
    """
    if len(images) < 2:
        raise InputError(f"subject.mask=auto needs at least 2 images to see what changes with the "
                         f"light, got {len(images)}; give a mask.png")
    gray = images.mean(-1)
    scale = float(np.percentile(gray, 99))
    if scale <= 0:
        raise InputError("subject.mask=auto: the images are black, so nothing shows where the "
                         "object is; give a mask.png")
    gray /= scale                               # in place: a 20 MP stack's gray is a gigabyte
    low, high = np.percentile(gray, [5, 95], axis=0)
    spread = high - low
    if not np.any(spread > FLOOR):
        raise InputError("subject.mask=auto: no pixel changes with the light; give a mask.png")
    logs = np.log(np.maximum(spread, FLOOR))
    cut, _ = otsu_threshold(logs.ravel())
    above = logs > cut
    labels, regions = ndimage.label(above)
    sizes = np.bincount(labels.ravel())[1:]
    largest = labels == (int(np.argmax(sizes)) + 1)
    filled = ndimage.binary_fill_holes(largest)
    background = np.percentile(spread[~filled], 99) if (~filled).any() else 0.0
    holes, count = ndimage.label(filled & ~largest)
    kept = [k + 1 for k, median in enumerate(ndimage.median(spread, holes, range(1, count + 1)))
            if median > background]          # a hole as still as the background is background
    object_ = largest | np.isin(holes, kept)
    # the outline's pixels are mixed; the frame's edge is not an outline
    mask = ndimage.binary_erosion(object_, iterations=EDGE, border_value=1)
    if not mask.any():
        mask = object_
    contrast = np.median(spread[mask]) / max(background, FLOOR)
    return AutoMask(mask, float(np.exp(cut)), float(contrast), int(regions), pixels_at_edge(mask))


def pixels_at_edge(mask: np.ndarray) -> int:
    """How many of an (H, W) mask's pixels lie on the image's edge (corners once).

    >>> pixels_at_edge(np.pad(np.ones((2, 2), bool), 1)), pixels_at_edge(np.ones((3, 4), bool))
    (0, 10)
    """
    edge = np.ones(mask.shape, bool)
    edge[1:-1, 1:-1] = False
    return int((mask & edge).sum())

"""The user's reading options (drop, crop, downsample) and added noise, applied to a subject."""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np

from unps.data.subject import Subject
from unps.errors import InputError

log = logging.getLogger(__name__)


def parse_indices(items: Sequence[int | str], n: int, what: str) -> list[int]:
    """Expand ``[0, 3, "5-9"]`` into sorted unique 0-based indices, all in [0, n).

    A string ``"a-b"`` is the inclusive range a…b (so ``"0-19"`` is DiLiGenT bear's first 20).
    """
    out: set[int] = set()
    for item in items or ():
        try:
            if isinstance(item, str) and "-" in item.strip()[1:]:
                a, b = item.split("-", 1)
                lo, hi = int(a), int(b)
                if hi < lo:
                    raise ValueError
                out.update(range(lo, hi + 1))
            else:
                out.add(int(item))
        except ValueError:
            raise InputError(f"{what}: {item!r} is neither an index nor a range 'a-b'") from None
    bad = [i for i in out if not 0 <= i < n]
    if bad:
        raise InputError(f"{what}: index {min(bad)} is outside the {n} images (0 … {n - 1})")
    return sorted(out)


def prepare(subject: Subject, drop: Sequence[int | str] = (), crop_margin: int | None = None,
            downsample: int = 1) -> Subject:
    """Apply the user's reading options in a fixed order: drop images, crop, downsample."""
    if drop:
        dropped = set(parse_indices(drop, subject.n_images, "drop"))
        keep = [i for i in range(subject.n_images) if i not in dropped]
        if not keep:
            raise InputError(f"drop removes all {subject.n_images} images of {subject.name!r}")
        log.info("%s: dropping %d of %d images", subject.name, len(dropped), subject.n_images)
        subject = subject.select(keep)
    if crop_margin is not None:
        subject = subject.crop_to_mask(int(crop_margin))
    return subject.downsample(downsample)


def add_noise(subject: Subject, sigma: float, seed: int) -> tuple[Subject, float]:
    """Add zero-mean Gaussian noise to the captured images (supplementary case study 2).

    The standard deviation is σ times the reference level: the 99th percentile of the observed
    (not intensity-normalised) pixel values on the object, so σ = 0.05 is 5 % of a bright
    pixel whatever the exposure. Nothing is clipped: noisy values may be negative.

    Returns:
        The noisy subject (images divided by the intensities again) and the reference level.
    """
    try:
        sigma = float(sigma)
    except (TypeError, ValueError):
        raise InputError(f"noise must be a number (a standard deviation >= 0), got {sigma!r}") from None
    if not np.isfinite(sigma) or sigma < 0:
        raise InputError(f"noise must be a standard deviation >= 0, got {sigma}")
    observed = subject.observed_images()
    reference = float(np.percentile(observed[:, subject.mask], 99))
    if sigma == 0:
        return subject, reference
    rng = np.random.default_rng(seed)
    noisy = observed + np.float32(sigma * reference) * rng.standard_normal(observed.shape,
                                                                          dtype=np.float32)
    if subject.light_intensities is not None:
        noisy /= subject.light_intensities[:, None, None, :]
    return subject.replace(images=noisy), reference

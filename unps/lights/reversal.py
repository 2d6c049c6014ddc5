"""Cast shadows settle the convex/concave reversal that estimated lights leave open.

Turning every light and every normal half a turn about the view axis, l → (−l_x, −l_y, l_z)
and n → (−n_x, −n_y, n_z), leaves n·l and n·h (h the half vector to the view) as they are, and
the turned normals integrate to the reversed depth −z: a dome under one set of lights and a
bowl under the other give the same shading, highlights included. A light network can land on
the wrong one of the two (the shipped weights do on BrokenPot and Rose), and neither contour
alignment nor self-calibration can cross over. Cast shadows can: a bowl shades its own floor
where a dome casts no shadow at all.

:func:`shadow_evidence` reads both ways from the robust initialisation's normals: it integrates the
depth, casts each light's shadows over z and over −z, and counts how often the pixels that only
one reading puts in shadow are dark in the images, where the shading with the lights
says they should be lit. :func:`resolve_reversal` turns the lights when those counts make the
reversed reading far more likely (:attr:`ShadowEvidence.log_odds`).

Frame: x right (+col), y up (−row), z toward the camera; orthographic view along +z.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import torch

from unps.data.subject import Subject
from unps.geometry import cast_shadows, integrate_normals
from unps.lights import Lights, with_lights
from unps.solvers.rpca import robust_init
from unps.solvers.woodham import rgb_albedo, to_maps

log = logging.getLogger(__name__)

HALF_TURN = np.diag([-1.0, -1.0, 1.0])   # about the view axis
LIT = 0.4            # n·l above which the shading says a pixel is lit (not grazing, where a
                     # glossy or rough material falls off faster than Lambertian)
DARK = 0.25          # observed / Lambertian prediction below which a lit pixel counts as dark
HIT_RATE = 0.5       # how often a pixel that the right reading puts in shadow is dark, at least
MIN_LOG_ODDS = 100.0  # natural log of the odds for the reversal needed to turn the lights


@dataclass(frozen=True)
class ShadowEvidence:
    """What the images say about the two readings, in pairs of pixel and image.

    Attributes:
        lit_pairs, dark_pairs: pairs the shading says are lit (n·l > ``LIT``), and how many of
            them are dark in the image.
        current_pairs, current_dark: pairs that only the current reading puts in shadow, and how
            many of them are dark.
        reversed_pairs, reversed_dark: the same for the reversed reading.
    """

    lit_pairs: int
    dark_pairs: int
    current_pairs: int
    current_dark: int
    reversed_pairs: int
    reversed_dark: int

    @property
    def log_odds(self) -> float:
        """Log-likelihood ratio of the reversed reading against the current one.

        A pair that the right reading puts in shadow is dark with probability ``HIT_RATE``; one
        that only the wrong reading puts there, as often as any lit pair (the dark share,
        Laplace-smoothed). Pairs are counted as independent, which neighbouring pixels are not,
        hence the high bar of ``MIN_LOG_ODDS``. 0 when the dark share reaches ``HIT_RATE``:
        then darkness says nothing about shadows.
        """
        base = (self.dark_pairs + 1) / (self.lit_pairs + 2)
        if base >= HIT_RATE:
            return 0.0
        dark, bright = np.log(HIT_RATE / base), np.log((1 - HIT_RATE) / (1 - base))
        reversed_ = self.reversed_dark * dark + (self.reversed_pairs - self.reversed_dark) * bright
        current = self.current_dark * dark + (self.current_pairs - self.current_dark) * bright
        return float(reversed_ - current)

    @property
    def favours_reversal(self) -> bool:
        return self.log_odds > MIN_LOG_ODDS

    def describe(self) -> str:
        return (f"of the pairs of lit pixel and image, {self.current_pairs} are in shadow only as "
                f"read now ({self.current_dark} of them dark), {self.reversed_pairs} only as "
                f"reversed ({self.reversed_dark} dark), {self.dark_pairs} of all {self.lit_pairs} "
                f"lit pairs are dark: log odds for the reversal {self.log_odds:.0f}")


def shadow_evidence(subject: Subject, lights: Lights, normals: np.ndarray,
                    max_pixels: int = 4000) -> ShadowEvidence:
    """Compare the shadows cast under the lights as they are and half a turn about the view.

    The subject and the normals are cropped to its mask and block-averaged to at most
    ``max_pixels`` object pixels; the Lambertian albedo there follows from the normals, and the
    depth integrated from them (in grid pixels) casts the shadows.

    Args:
        subject: its captured images and mask.
        lights: (n, 3) unit directions and intensities (or None) to test.
        normals: (H, W, 3) unit normals estimated with ``lights`` (the robust initialisation's).
    """
    observed = with_lights(subject, lights).replace(normals=normals, depth=None)
    factor = max(1, int(np.ceil(np.sqrt(observed.mask.sum() / max_pixels))))
    grid = observed.crop_to_mask(1).downsample(factor)
    directions = lights.directions.astype(np.float64)
    albedo = to_maps(rgb_albedo(grid.images[:, grid.mask], grid.normals[grid.mask], directions),
                     grid.mask)
    shading = np.einsum("hwc,nc->nhw", grid.normals, directions)                # (n, H, W)
    lit = (shading > LIT) & grid.mask[None]
    dark = lit & (grid.images.mean(-1) < DARK * albedo.mean(-1)[None] * shading)
    depth = torch.as_tensor(np.nan_to_num(integrate_normals(grid.normals, grid.mask)))
    mask = torch.as_tensor(grid.mask)
    steps = int(np.ceil(np.hypot(*grid.mask.shape)))                          # one per pixel
    current = cast_shadows(depth, mask, torch.as_tensor(directions).float(), 1.0, steps).numpy()
    turned = torch.as_tensor(directions @ HALF_TURN).float()
    reversed_ = cast_shadows(-depth, mask, turned, 1.0, steps).numpy()
    only_current, only_reversed = lit & current & ~reversed_, lit & reversed_ & ~current
    return ShadowEvidence(int(lit.sum()), int(dark.sum()), int(only_current.sum()),
                          int(dark[only_current].sum()), int(only_reversed.sum()),
                          int(dark[only_reversed].sum()))


def resolve_reversal(subject: Subject, lights: Lights, normals: np.ndarray | None = None
                     ) -> tuple[Lights, np.ndarray]:
    """The lights, or the lights half a turn about the view axis when the shadows say so.

    Args:
        subject: its captured images and mask.
        lights: the estimate to test.
        normals: (H, W, 3) the robust initialisation's normals with ``lights``; computed when
            None.

    Returns:
        ``lights`` with directions (l_x, l_y, l_z) → (−l_x, −l_y, l_z) when
        :attr:`ShadowEvidence.favours_reversal`, else ``lights`` itself (intensities unchanged);
        and the normals with the lights returned (turned alike: the robust initialisation turns
        with its lights).
    """
    if normals is None:
        normals = robust_init(with_lights(subject, lights), lights.directions).normals
    evidence = shadow_evidence(subject, lights, normals)
    if not evidence.favours_reversal:
        log.info("cast shadows agree with the lights as estimated (%s)", evidence.describe())
        return lights, normals
    log.warning("cast shadows say the estimated lights read the surface inside out (concave for "
                "convex): turned them half a turn about the view axis (%s); if the object has no "
                "hollows that cast shadows, rerun with light.reversal=null", evidence.describe())
    directions = (lights.directions.astype(np.float64) @ HALF_TURN).astype(np.float32)
    turned = (normals @ HALF_TURN).astype(np.float32)
    return Lights(directions, lights.intensities, lights.source, spread_deg=lights.spread_deg), turned

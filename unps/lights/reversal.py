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
says they should be lit. :class:`ReversalTest` turns the lights only on positive evidence: the
reversed reading's own shadows are dark far more often than lit pixels are and than the current
reading's shadows are.

Frame: x right (+col), y up (−row), z toward the camera; orthographic view along +z.
"""

from __future__ import annotations

import logging
import dataclasses
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import torch

from unps.data.subject import Subject
from unps.geometry import cast_shadows, integrate_normals
from unps.data.lights import Verdict
from unps.device import resolve_device
from unps.lights import Lights, with_lights
from unps.solvers.rpca import robust_init
from unps.solvers.woodham import rgb_albedo, to_maps

log = logging.getLogger(__name__)

HALF_TURN = np.diag([-1.0, -1.0, 1.0])   # about the view axis
LIT = 0.4            # n·l above which the shading says a pixel is lit (not grazing, where a
                     # glossy or rough material falls off faster than Lambertian)
DARK = 0.25          # observed / Lambertian prediction below which a lit pixel counts as dark
PRIOR_PAIRS = 5.0    # pseudo-counts that pull a small count's rate or lift toward no evidence


@dataclass(frozen=True)
class ShadowEvidence:
    """What the images say about the two readings, in pairs of pixel and image.

    A pixel can be dark where no shadow falls (a dark or mirror-like material, a highlight
    elsewhere): how often each pixel is dark under the lights that neither reading shadows it
    from gives the darkness to expect of it anyway.

    Attributes:
        lit_pairs, dark_pairs: pairs the shading says are lit (n·l > ``LIT``), and how many of
            them are dark in the image.
        current_pairs, current_dark: pairs that only the current reading puts in shadow, and how
            many of them are dark.
        current_expected: how many of those pairs would be dark anyway (the sum over them of each
            pixel's dark share where neither reading casts a shadow).
        reversed_pairs, reversed_dark, reversed_expected: the same for the reversed reading.
    """

    lit_pairs: int
    dark_pairs: int
    current_pairs: int
    current_dark: int
    current_expected: float
    reversed_pairs: int
    reversed_dark: int
    reversed_expected: float

    @property
    def base_rate(self) -> float:
        """How often a lit pair is dark at all."""
        return (self.dark_pairs + 1) / (self.lit_pairs + 2)

    @property
    def reversed_rate(self) -> float:
        """How often the shadows that only the reversed reading casts are dark, smoothed toward
        the base share (which it is when that reading casts none)."""
        return (self.reversed_dark + PRIOR_PAIRS * self.base_rate) / (self.reversed_pairs + PRIOR_PAIRS)

    @property
    def current_lift(self) -> float:
        """How many times more often the current reading's own shadows are dark than their
        pixels are anyway (smoothed toward 1)."""
        return (self.current_dark + PRIOR_PAIRS) / (self.current_expected + PRIOR_PAIRS)

    @property
    def reversed_lift(self) -> float:
        """The same for the reversed reading."""
        return (self.reversed_dark + PRIOR_PAIRS) / (self.reversed_expected + PRIOR_PAIRS)

    def describe(self) -> str:
        return (f"of the pairs of lit pixel and image, {self.current_pairs} are in shadow only as "
                f"read now ({self.current_dark} of them dark, {self.current_lift:.1f}× as often as "
                f"those pixels are otherwise), {self.reversed_pairs} only as reversed "
                f"({self.reversed_dark} dark, {100 * self.reversed_rate:.0f} %, "
                f"{self.reversed_lift:.1f}× as often); {100 * self.base_rate:.1f} % of all "
                f"{self.lit_pairs} lit pairs are dark")

    def as_dict(self) -> dict[str, float]:
        return {name: float(getattr(self, name)) for name in (
            "lit_pairs", "dark_pairs", "current_pairs", "current_dark", "current_expected",
            "reversed_pairs", "reversed_dark", "reversed_expected")}


def shadow_evidence(subject: Subject, lights: Lights, normals: np.ndarray,
                    max_pixels: int = 4000, device: torch.device = torch.device("cpu")) -> ShadowEvidence:
    """Compare the shadows cast under the lights as they are and half a turn about the view.

    The subject and the normals are cropped to its mask and block-averaged to at most
    ``max_pixels`` object pixels; the Lambertian albedo there follows from the normals, and the
    depth integrated from them (in grid pixels) casts the shadows.

    Args:
        subject: its captured images and mask.
        lights: (n, 3) unit directions and intensities (or None) to test.
        normals: (H, W, 3) unit normals estimated with ``lights`` (the robust initialisation's).
        device: where the shadows are marched.
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
    depth = torch.as_tensor(np.nan_to_num(integrate_normals(grid.normals, grid.mask)), device=device)
    mask = torch.as_tensor(grid.mask, device=device)
    steps = int(np.ceil(np.hypot(*grid.mask.shape)))                          # one per pixel
    current = cast_shadows(depth, mask, torch.as_tensor(directions, device=device).float(), 1.0,
                           steps).cpu().numpy()
    turned = torch.as_tensor(directions @ HALF_TURN, device=device).float()
    reversed_ = cast_shadows(-depth, mask, turned, 1.0, steps).cpu().numpy()
    only_current, only_reversed = lit & current & ~reversed_, lit & reversed_ & ~current
    neither = lit & ~current & ~reversed_
    base = (dark.sum() + 1) / (lit.sum() + 2)
    anyway = ((dark & neither).sum(0) + PRIOR_PAIRS * base) / (neither.sum(0) + PRIOR_PAIRS)  # (H, W)
    expected = np.broadcast_to(anyway, dark.shape)
    return ShadowEvidence(int(lit.sum()), int(dark.sum()),
                          int(only_current.sum()), int(dark[only_current].sum()),
                          float(expected[only_current].sum()),
                          int(only_reversed.sum()), int(dark[only_reversed].sum()),
                          float(expected[only_reversed].sum()))


@dataclass(frozen=True)
class ReversalTest:
    """The light stage that turns the lights half a turn about the view when, and only when, the
    shadows of the reversed reading are there in the images (positive evidence).

    The shadows that only the reversed reading casts must be dark at least ``hit_rate`` of the
    time, over at least ``min_pairs`` pairs, and ``contrast`` times as often as their pixels are
    dark where neither reading shadows them, and as the current reading's own shadows are (their
    lifts, :class:`ShadowEvidence`). Where neither reading's shadows are dark, nothing is said and
    the lights stay: a reading is never turned for predicting fewer shadows (a glossy cup on a
    thin stem, 2026-11-25, was turned that way), nor for shadows that fall where a dark or
    mirror-like material is dark anyway.

    The contrast is what tells: on the light benchmark (``experiments/light_benchmark``) the
    reversed reading's shadows of a correct reading were at most 3× as often dark as expected,
    those of the three readings inside out that cast shadows 8–45× (dark in 40–57 % of their
    pairs).

    Attributes:
        hit_rate: share of the reversed reading's own shadow pairs that must be dark.
        contrast: how many times more often than expected of their pixels, and than the current
            reading's shadows, they must be dark.
        min_pairs: pairs of pixel and image in the reversed reading's own shadows, at least.
        device: where the robust initialisation and the shadows run (the run's ``device=``).
    """

    name: ClassVar[str] = "reversal"
    hit_rate: float = 0.3
    contrast: float = 4.0
    min_pairs: int = 50
    device: str = "auto"

    def favours_reversal(self, evidence: ShadowEvidence) -> bool:
        """Whether the evidence is positive for the reversed reading (see the class)."""
        lift = evidence.reversed_lift
        return (evidence.reversed_pairs >= self.min_pairs and evidence.reversed_rate >= self.hit_rate
                and lift >= self.contrast and lift >= self.contrast * evidence.current_lift)

    def __call__(self, subject: Subject, lights: Lights) -> tuple[Lights, Verdict]:
        """The lights, or the lights half a turn about the view axis when the shadows say so.

        Args:
            subject: its captured images and mask.
            lights: the estimate to test.

        Returns:
            ``lights`` with directions (l_x, l_y, l_z) → (−l_x, −l_y, l_z) when
            :meth:`favours_reversal`, else ``lights`` itself (intensities unchanged); and the
            verdict with the counts of :class:`ShadowEvidence`.
        """
        device = resolve_device(self.device)
        cropped = subject.crop_to_mask(1)         # shadow_evidence's crop: the same pixels, less to divide
        normals = robust_init(with_lights(cropped, lights), lights.directions, device=device).normals
        evidence = shadow_evidence(cropped, lights, normals, device=device)
        if not self.favours_reversal(evidence):
            return lights, Verdict(self.name, "kept", "the cast shadows do not say the lights read "
                                   "the surface inside out (" + evidence.describe() + ")",
                                   evidence.as_dict())
        log.warning("cast shadows say the estimated lights read the surface inside out (concave "
                    "for convex): turned them half a turn about the view axis (%s); if the object "
                    "has no hollows that cast shadows, rerun with light.stages without reversal",
                    evidence.describe())
        directions = (lights.directions.astype(np.float64) @ HALF_TURN).astype(np.float32)
        turned = dataclasses.replace(lights, directions=directions)
        return turned, Verdict(self.name, "changed", "turned the lights half a turn about the view: "
                               "the reversed reading's shadows are dark in the images ("
                               + evidence.describe() + ")", evidence.as_dict())

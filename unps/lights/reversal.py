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

Interreflection is the other cue a concave surface leaves: light where the shading says none
arrives (pixels facing away from a light). :func:`attached_light` reads how much of it there is
and how well each reading's one-bounce prediction accounts for it. A flat level of light (the
room's, or light scattered under the surface) is accounted for nearly as well by any positive
prediction, so this cue alone never turns the lights; where it points to the reversed reading,
the test keeps them and warns (:attr:`AttachedLight.points_to_reversal`), and
``light.reversal.force=true`` turns them.

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
from unps.errors import InputError
from unps.lights import Lights, with_lights
from unps.solvers.nayar import interreflection_kernel
from unps.solvers.rpca import robust_init
from unps.solvers.woodham import rgb_albedo, to_maps

log = logging.getLogger(__name__)

HALF_TURN = np.diag([-1.0, -1.0, 1.0])   # about the view axis
LIT = 0.4            # n·l above which the shading says a pixel is lit (not grazing, where a
                     # glossy or rough material falls off faster than Lambertian)
DARK = 0.25          # observed / Lambertian prediction below which a lit pixel counts as dark
PRIOR_PAIRS = 5.0    # pseudo-counts that pull a small count's rate or lift toward no evidence
ATTACHED = -0.05     # n·l below which a pixel is in attached shadow: no direct light reaches it


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
class AttachedLight:
    """The light seen where the shading says none arrives, and which reading accounts for it.

    Attributes:
        pairs: pairs of pixel and image in attached shadow (n·l < ``ATTACHED``; the same for both
            readings, as n·l is).
        level: their mean value, in units of the images' 99th percentile.
        current_share, reversed_share: the share of Σ value² there that each reading's one-bounce
            interreflection prediction explains with one free scale (:func:`attached_light`; nan
            where it was not predicted).
        reversed_scale: that scale for the reversed reading. The prediction is the light the
            images show arriving from the rest of the surface times the Lambertian albedo, so a
            scale near the brightest material's albedo (0.2–1) is what interreflection gives; a
            flat light explained by a concave reading's prediction mostly needs far less (0.08
            on DiLiGenT's ball, 1 % of its light in attached shadows).
    """

    pairs: int
    level: float
    current_share: float
    reversed_share: float
    reversed_scale: float

    MIN_PAIRS: ClassVar[int] = 20
    MIN_LEVEL: ClassVar[float] = 0.03
    MIN_SHARE: ClassVar[float] = 0.6
    MAX_CURRENT_SHARE: ClassVar[float] = 0.3
    SCALES: ClassVar[tuple[float, float]] = (0.2, 2.0)

    @property
    def points_to_reversal(self) -> bool:
        """Whether the light in attached shadows reads as the reversed reading's interreflections:
        at least ``MIN_LEVEL`` of the 99th percentile over ``MIN_PAIRS`` pairs, at least
        ``MIN_SHARE`` of it explained by the reversed reading at a scale within ``SCALES``, at most
        ``MAX_CURRENT_SHARE`` by the current one. On the light benchmark
        (``experiments/light_benchmark/reversal_cues.py``, 89 readings) it held on 7 of the 8
        readings inside out (not the rose under 12 lights: 7 pairs) and on none read the right
        way round; a flat light of the room's on a convex object can hold it too. A room's light
        also takes pairs away (the pot shard under 96 lights: 46 → 35 → 24 with 0.005 and 0.01 of
        it), hence a floor of 20: with it as with 40, none of those 89 readings read the right way
        round holds it without room light or at 0.005."""
        low, high = self.SCALES
        return (self.pairs >= self.MIN_PAIRS and self.level >= self.MIN_LEVEL
                and self.reversed_share >= self.MIN_SHARE
                and self.current_share <= self.MAX_CURRENT_SHARE
                and low <= self.reversed_scale <= high)

    def describe(self) -> str:
        held = (f"{self.pairs} pairs of pixel and image in attached shadow hold "
                f"{100 * self.level:.1f} % of the images' 99th percentile on average")
        if np.isnan(self.reversed_share):
            return held + ", too little to read as interreflection"
        return (f"{held}; one-bounce interreflection explains {100 * self.current_share:.0f} % of it "
                f"as read now, {100 * self.reversed_share:.0f} % as reversed (scale "
                f"{self.reversed_scale:.2f})")

    def as_dict(self) -> dict[str, float]:
        """The figures by name, those not computed (nan) left out, and
        ``attached_points_to_reversal`` (1 or 0)."""
        figures = {f"attached_{name}": float(getattr(self, name)) for name in (
            "pairs", "level", "current_share", "reversed_share", "reversed_scale")}
        return ({name: value for name, value in figures.items() if not np.isnan(value)}
                | {"attached_points_to_reversal": float(self.points_to_reversal)})


def attached_facets(subject: Subject, lights: Lights, normals: np.ndarray,
                    max_facets: int = 1500) -> tuple[Subject, dict[str, np.ndarray], np.ndarray]:
    """The light in attached shadows, on facets.

    The subject and (H, W, 3) normals are cropped to the mask and block-averaged to at most
    ``max_facets`` object pixels (facets).

    Returns:
        the facets' grid (a :class:`Subject` with the normals); the maps ``observed``, (n, m)
        grey values over the m facets in units of the images' 99th percentile, and ``attached``,
        (n, m) bool, n·l < ``ATTACHED``; and the (m,) Lambertian albedo in the same units (least
        squares with the lights as they are).
    """
    observed = with_lights(subject, lights).replace(normals=normals, depth=None)
    factor = max(1, int(np.ceil(np.sqrt(observed.mask.sum() / max_facets))))
    grid = observed.crop_to_mask(1).downsample(factor)
    gray = grid.images[:, grid.mask].mean(-1).astype(np.float64)                # (n, m)
    scale = max(float(np.quantile(gray, 0.99)), 1e-12)
    facet_normals = grid.normals[grid.mask].astype(np.float64)
    directions = lights.directions.astype(np.float64)
    albedo = rgb_albedo(grid.images[:, grid.mask], facet_normals, directions).mean(-1) / scale
    maps = {"observed": gray / scale, "attached": (facet_normals @ directions.T).T < ATTACHED}
    return grid, maps, albedo


def one_bounce(grid: Subject, observed: np.ndarray, albedo: np.ndarray) -> dict[str, np.ndarray]:
    """Each reading's one-bounce prediction, ``current`` and ``reversed``: (n, m) over the facets
    of :func:`attached_facets`.

    Each reading's depth (integrated from the normals; −depth and the half-turned normals for the
    reversed one) gives Nayar's kernel (:func:`unps.solvers.nayar.interreflection_kernel`, with
    occlusion); the light facet j sends toward facet i is its ``observed`` grey value, and facet
    i reflects it with its ``albedo``, the same for both readings. The kernels take most of the
    time: 0.6–0.7 s for both at 1500 facets on one CPU core where a hollow reading keeps most
    pairs.
    """
    depth = np.nan_to_num(integrate_normals(grid.normals, grid.mask))
    return {reading: (interreflection_kernel(z, n, grid.mask) @ observed.T).T * albedo[None]
            for reading, z, n in (("current", depth, grid.normals),
                                  ("reversed", -depth, grid.normals @ HALF_TURN))}


def attached_predictions(subject: Subject, lights: Lights, normals: np.ndarray,
                         max_facets: int = 1500) -> dict[str, np.ndarray]:
    """The light in attached shadows and each reading's one-bounce prediction of it: the maps of
    :func:`attached_facets` and :func:`one_bounce` together."""
    grid, maps, albedo = attached_facets(subject, lights, normals, max_facets)
    return maps | one_bounce(grid, maps["observed"], albedo)


def explained_share(seen: np.ndarray, predicted: np.ndarray) -> tuple[float, float]:
    """(share of Σ seen² that ``scale · predicted`` explains, the least-squares scale ≥ 0) for
    (k,) ``seen`` and ``predicted``; (0, 0) without pairs."""
    if seen.size == 0:
        return 0.0, 0.0
    scale = max(float((seen * predicted).sum() / max((predicted ** 2).sum(), 1e-12)), 0.0)
    return float(1 - ((seen - scale * predicted) ** 2).sum() / max((seen ** 2).sum(), 1e-12)), scale


def summarise_attached(maps: dict[str, np.ndarray]) -> AttachedLight:
    """:class:`AttachedLight` of :func:`attached_facets`' maps, with :func:`one_bounce`'s (the
    shares and scale nan without them)."""
    attached = maps["attached"]
    seen = maps["observed"][attached]
    current = reversed_ = scale = float("nan")
    if "current" in maps:
        current, _ = explained_share(seen, maps["current"][attached])
        reversed_, scale = explained_share(seen, maps["reversed"][attached])
    return AttachedLight(int(attached.sum()), float(seen.mean()) if seen.size else 0.0,
                         current, reversed_, scale)


def attached_light(subject: Subject, lights: Lights, normals: np.ndarray) -> AttachedLight:
    """:class:`AttachedLight` of the two readings from (H, W, 3) ``normals`` estimated with
    ``lights``; the predictions are left out (shares nan) where too little light or too few
    pairs could point to the reversal anyway."""
    grid, maps, albedo = attached_facets(subject, lights, normals)
    found = summarise_attached(maps)
    if found.pairs < AttachedLight.MIN_PAIRS or found.level < AttachedLight.MIN_LEVEL:
        return found
    return summarise_attached(maps | one_bounce(grid, maps["observed"], albedo))


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

    Where the shadows say nothing but the light in attached shadows reads as the reversed
    reading's interreflections (:attr:`AttachedLight.points_to_reversal`), the lights stay and a
    warning says so; ``force`` turns them whatever the evidence, for an object known to be
    hollow where the normals show it bulging.

    Attributes:
        hit_rate: share of the reversed reading's own shadow pairs that must be dark.
        contrast: how many times more often than expected of their pixels, and than the current
            reading's shadows, they must be dark.
        min_pairs: pairs of pixel and image in the reversed reading's own shadows, at least. The
            contrast's pseudo-counts (``PRIOR_PAIRS``) already ask for 15 dark pairs or more, so
            this is a floor under few pairs rather than the bar: at 50 it left a pot shard under
            20 lights inside out (71°) once a room's light (DiLiGenT's level) flattened the
            network's reading and its reversed shadows shrank to 35 pairs, 25 of them dark.
        force: turn the lights without reading any evidence.
        device: where the robust initialisation and the shadows run (the run's ``device=``).
    """

    name: ClassVar[str] = "reversal"
    hit_rate: float = 0.3
    contrast: float = 4.0
    min_pairs: int = 20
    force: bool = False
    device: str = "auto"

    def __post_init__(self):
        if not isinstance(self.force, bool):
            raise InputError(f"light.reversal.force must be true or false, got {self.force!r}")

    def favours_reversal(self, evidence: ShadowEvidence) -> bool:
        """Whether the evidence is positive for the reversed reading (see the class)."""
        lift = evidence.reversed_lift
        return (evidence.reversed_pairs >= self.min_pairs and evidence.reversed_rate >= self.hit_rate
                and lift >= self.contrast and lift >= self.contrast * evidence.current_lift)

    def __call__(self, subject: Subject, lights: Lights) -> tuple[Lights, Verdict]:
        """The lights, or the lights half a turn about the view axis when the shadows say so (or
        ``force``).

        Args:
            subject: its captured images and mask.
            lights: the estimate to test.

        Returns:
            ``lights`` with directions (l_x, l_y, l_z) → (−l_x, −l_y, l_z) when
            :meth:`favours_reversal` or ``force``, else ``lights`` itself (intensities
            unchanged); and the verdict with the counts of :class:`ShadowEvidence` and the
            figures of :class:`AttachedLight`.
        """
        if self.force:
            log.warning("light.reversal.force=true: turned the estimated lights half a turn about "
                        "the view axis without reading the images")
            return half_turned(lights), Verdict(self.name, "changed", "turned the lights half a turn "
                                                "about the view: light.reversal.force=true")
        device = resolve_device(self.device)
        cropped = subject.crop_to_mask(1)         # shadow_evidence's crop: the same pixels, less to divide
        normals = robust_init(with_lights(cropped, lights), lights.directions, device=device).normals
        evidence = shadow_evidence(cropped, lights, normals, device=device)
        if self.favours_reversal(evidence):
            log.warning("cast shadows say the estimated lights read the surface inside out (concave "
                        "for convex): turned them half a turn about the view axis (%s); if the object "
                        "has no hollows that cast shadows, rerun with light.stages without reversal",
                        evidence.describe())
            return half_turned(lights), Verdict(self.name, "changed", "turned the lights half a turn "
                                                "about the view: the reversed reading's shadows are "
                                                "dark in the images (" + evidence.describe() + ")",
                                                evidence.as_dict())
        attached = attached_light(cropped, lights, normals)
        reason = ("the cast shadows do not say the lights read the surface inside out ("
                  + evidence.describe() + "); " + attached.describe())
        if attached.points_to_reversal:
            log.warning("the estimated lights may read the surface inside out (concave for convex): "
                        "the light in its attached shadows reads as the interreflections of the "
                        "reversed reading (%s), though no cast shadow shows it, so the lights stay. "
                        "If shape.png shows the object bulging where it is hollow, rerun with "
                        "light.reversal.force=true; if the room's light reached it, subtract a dark "
                        "frame from the images", attached.describe())
            reason += ": as the reversed reading's interreflections, but not turned on that alone"
        return lights, Verdict(self.name, "kept", reason, evidence.as_dict() | attached.as_dict())


def half_turned(lights: Lights) -> Lights:
    """``lights`` with directions (l_x, l_y, l_z) → (−l_x, −l_y, l_z), intensities unchanged."""
    directions = (lights.directions.astype(np.float64) @ HALF_TURN).astype(np.float32)
    return dataclasses.replace(lights, directions=directions)

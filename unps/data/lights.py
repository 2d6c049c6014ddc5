"""The lights a method uses, and light arrays as they are read: shapes, finiteness, unit length."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from unps.errors import InputError

log = logging.getLogger(__name__)

UNIT_TOLERANCE = 1e-3


OUTCOMES = ("changed", "kept", "declined")
UNSURE_SPREAD_DEG = 10.0
"""The median over the lights of ``Lights.spread_deg`` above which the light network's passes are
said to disagree. With the shipped weights, on the light benchmark only the rose's readings pass
it (10.5–13.8°, each 24–60° off, inside out or nearly; every other reading stays at or below
7.8°: ``experiments/light_benchmark/README.md``, "Readings the network is unsure of")."""


@dataclass(frozen=True)
class Verdict:
    """What one light stage did with the lights it was given.

    Attributes:
        stage: the stage's name (``network``, ``reversal``, ``contour``, ``selfcal``, or ``fit``
            where the method learnt the lights further with the surface: ``light.refine``).
        outcome: ``changed`` (it returned other lights), ``kept`` (its evidence says the lights
            stand as they are) or ``declined`` (it could not decide, or its result failed its own
            check, so the lights pass through unchanged).
        reason: one sentence, for the log and ``metrics.json``.
        evidence: the figures the decision rests on, by name.
        errors: ``light_dir_mae`` and ``light_int_err`` of the lights after the stage, where the
            subject's true lights are known (filled in by the runner, never used to decide).
    """

    stage: str
    outcome: str
    reason: str
    evidence: dict[str, float] = field(default_factory=dict)
    errors: dict[str, float] = field(default_factory=dict)

    def __post_init__(self):
        if self.outcome not in OUTCOMES:
            raise ValueError(f"a stage's outcome is one of {OUTCOMES}, got {self.outcome!r}")

    def to_dict(self) -> dict:
        """A JSON-ready record: stage, outcome, reason, evidence and errors."""
        return {"stage": self.stage, "outcome": self.outcome, "reason": self.reason,
                "evidence": {k: float(v) for k, v in self.evidence.items()},
                **{k: float(v) for k, v in self.errors.items()}}


@dataclass(frozen=True)
class Lights:
    """The lights a method uses.

    Attributes:
        directions: (n, 3) float32 unit, surface to light, unps frame.
        intensities: (n, 3) float32 RGB, or None when the images are used as given.
        source: how they were obtained (``gt``, ``estimated``, …).
        spread_deg: (n,) how far the light network's estimates of each light disagree under the
            symmetries of the image (:mod:`unps.lightnet.symmetry`), in degrees; None when not
            estimated that way.
        verdicts: what each light stage that made them did, in order.
    """

    directions: np.ndarray
    intensities: np.ndarray | None
    source: str
    spread_deg: np.ndarray | None = None
    verdicts: tuple[Verdict, ...] = ()

    @property
    def unsure(self) -> bool:
        """Whether the light network's passes disagree by more than :data:`UNSURE_SPREAD_DEG`
        (median over the lights); False where no spread is known."""
        return self.spread_deg is not None and float(np.median(self.spread_deg)) > UNSURE_SPREAD_DEG


def check_light_directions(directions, n_images: int, source: str) -> np.ndarray:
    """Validate light directions and return them as unit float32 vectors.

    Args:
        directions: (n, 3) surface-to-light directions in the unps frame.
        n_images: the number of images they must match.
        source: the file or subject named in error messages.

    Returns:
        (n, 3) float32 unit vectors. Non-unit rows are normalised with a warning.

    Raises:
        InputError: wrong shape, NaN/Inf, or a zero-length direction.
    """
    d = np.asarray(directions, dtype=np.float64)
    if d.ndim == 1 and d.size == 3:
        d = d[None]
    if d.shape != (n_images, 3):
        raise InputError(f"{source}: expected {n_images} light directions of 3 values (one per "
                         f"image), got an array of shape {d.shape}")
    bad = ~np.isfinite(d).all(axis=1)
    if bad.any():
        raise InputError(f"{source}: the light direction in row {int(np.argmax(bad)) + 1} (of "
                         f"{n_images}) is not finite: {d[bad][0].tolist()}")
    norm = np.linalg.norm(d, axis=1)
    if (norm < 1e-8).any():
        raise InputError(f"{source}: the light direction in row {int(np.argmax(norm < 1e-8)) + 1} "
                         f"(of {n_images}) has zero length")
    off = np.abs(norm - 1) > UNIT_TOLERANCE
    if off.any():
        log.warning("%s: %d light directions are not unit length (e.g. row %d, |l| = %.4f); "
                    "normalising them", source, off.sum(), int(np.argmax(off)) + 1, norm[off][0])
    return (d / norm[:, None]).astype(np.float32)


def check_light_intensities(intensities, n_images: int, source: str) -> np.ndarray:
    """Validate RGB light intensities: (n, 3), or (n,) shared by RGB; finite and > 0."""
    e = np.asarray(intensities, dtype=np.float64)
    if e.ndim == 1 and e.shape == (n_images,):
        e = np.repeat(e[:, None], 3, axis=1)
    if e.shape != (n_images, 3):
        raise InputError(f"{source}: expected {n_images} light intensities of 3 (RGB) values, "
                         f"got an array of shape {e.shape}")
    bad = ~(np.isfinite(e) & (e > 0)).all(axis=1)
    if bad.any():
        raise InputError(f"{source}: light intensities must be finite and > 0; row "
                         f"{int(np.argmax(bad)) + 1} (of {n_images}) is {e[bad][0].tolist()}")
    return e.astype(np.float32)

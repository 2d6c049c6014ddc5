"""The light stages beyond the network, and the one place that runs them (``light.stages``).

A stage takes a subject and lights and returns lights with its verdict
(:class:`unps.data.lights.Verdict`): ``changed``, ``kept`` (its evidence says the lights stand) or
``declined`` (it could not decide, or its result failed its own check). A stage returns its input
unchanged unless its evidence says otherwise. The stages:

- ``reversal``: :class:`unps.lights.reversal.ReversalTest`, the convex/concave reversal settled by
  cast shadows;
- ``contour``: :class:`unps.lights.contour.ContourAlignment`, a rotation read off the occluding
  contour;
- ``selfcal``: :class:`unps.lights.selfcal.SelfCalibration`, the lights fitted to the images.

:func:`run_stages` runs them in order, logs each, times it and records its verdict in the lights
(``Lights.verdicts``), with the light error after it where the subject's own lights are known
(for the log and ``metrics.json``; never used to decide).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Mapping, Sequence
from typing import Protocol

from unps.data.lights import Lights, Verdict
from unps.data.subject import Subject
from unps.errors import InputError
from unps.lights import light_errors
from unps.timing import stage as timed

log = logging.getLogger(__name__)

STAGES = ("reversal", "contour", "selfcal")
LABELS = {"network": "light network", "reversal": "reversal test", "contour": "contour alignment",
          "selfcal": "self-calibration", "fit": "fit (light.refine)"}


class LightStage(Protocol):
    """A light stage: ``stage(subject, lights) -> (lights, verdict)``, with a ``name``."""

    name: str

    def __call__(self, subject: Subject, lights: Lights) -> tuple[Lights, Verdict]: ...


def select_stages(names: Sequence[str], available: Mapping[str, LightStage | None]) -> list[LightStage]:
    """The stages ``light.stages`` names, in its order, from their configured settings.

    Raises:
        InputError: a name that is not a stage, named twice, or whose settings are null or not
            that stage's.
    """
    if isinstance(names, str):
        names = [names]
    chosen = []
    for name in names:
        if name not in STAGES:
            raise InputError(f"light.stages: {name!r} is not a light stage; the stages are "
                             f"{', '.join(STAGES)} (e.g. light.stages=[reversal,selfcal], or [] for "
                             f"the network's lights as they are)")
        if available.get(name) is None:
            raise InputError(f"light.stages names {name!r}, but light.{name} is null: give it "
                             f"settings or leave {name} out of light.stages")
        if getattr(available[name], "name", None) != name or not callable(available[name]):
            raise InputError(f"light.{name} must hold the settings of the {name} stage, got "
                             f"{available[name]!r}")
        if available[name] in chosen:
            raise InputError(f"light.stages names {name!r} twice")
        chosen.append(available[name])
    return chosen


def record(lights: Lights, verdict: Verdict, subject: Subject) -> Lights:
    """``lights`` with ``verdict`` (and the light error where known) added to their verdicts,
    logged."""
    errors = light_errors(lights, subject)
    verdict = dataclasses.replace(verdict, errors=errors)
    known = "".join(f"; {label} {errors[key]:.{digits}f}{unit}" for key, label, digits, unit in
                    (("light_dir_mae", "direction error", 2, "°"),
                     ("light_int_err", "intensity error", 3, "")) if key in errors)
    log.info("lights of %d images after the %s: %s — %s%s", subject.n_images,
             LABELS.get(verdict.stage, verdict.stage), verdict.outcome, verdict.reason, known)
    return dataclasses.replace(lights, verdicts=(*lights.verdicts, verdict))


def run_stages(subject: Subject, lights: Lights, stages: Sequence[LightStage]) -> Lights:
    """Each stage in turn on the lights the one before returned.

    Returns:
        The last stage's lights, with every stage's verdict appended to ``lights.verdicts`` and
        the first lights' ``spread_deg`` (the network's) kept.
    """
    for light_stage in stages:
        with timed(LABELS[light_stage.name]):
            out, verdict = light_stage(subject, lights)
        out = dataclasses.replace(out, verdicts=lights.verdicts, spread_deg=lights.spread_deg)
        lights = record(out, verdict, subject)
    return lights

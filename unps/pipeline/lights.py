"""Estimated lights (``light=estimated``, ``light=selfcal``): the light network, then the light
stages that ``light.stages`` lists (:mod:`unps.lights.stages`), each kept or stepping aside by its
own evidence."""

from __future__ import annotations

from collections.abc import Sequence

from unps.data.lights import Lights
from unps.data.subject import Subject
from unps.lightnet.estimate import FRAMINGS, network_lights
from unps.lights.contour import ContourAlignment
from unps.lights.reversal import ReversalTest
from unps.lights.selfcal import SelfCalibration
from unps.lights.stages import record, run_stages, select_stages
from unps.timing import stage


def estimated_lights(subject: Subject, checkpoint: str | None = None, soft_decode: bool = True,
                     symmetric: bool = True, framings: Sequence[float] = FRAMINGS,
                     stages: Sequence[str] = ("reversal",),
                     reversal: ReversalTest | None = ReversalTest(),
                     contour: ContourAlignment | None = ContourAlignment(),
                     selfcal: SelfCalibration | None = SelfCalibration(),
                     device: str = "auto") -> Lights:
    """The network's lights (:func:`unps.lightnet.estimate.network_lights`, with ``checkpoint``,
    ``soft_decode``, ``symmetric`` and ``framings``, on ``device``), then each stage named in
    ``stages`` in turn, with the settings given for it (each its own ``device``).

    Raises:
        InputError: a stage that is unknown, named twice or without settings (before any work).

    Returns:
        The lights of the last stage, with every stage's verdict (``Lights.verdicts``).
    """
    chosen = select_stages(stages, {"reversal": reversal, "contour": contour, "selfcal": selfcal})
    with stage("light network"):
        lights, verdict = network_lights(subject, checkpoint, soft_decode, symmetric, framings, device)
    return run_stages(subject, record(lights, verdict, subject), chosen)

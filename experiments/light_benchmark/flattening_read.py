"""Which reading of "the fit flattened the lights" tracks what the fit did to their error?

    python experiments/light_benchmark/flattening_read.py                # benchmark, diligent, synthetic
    python experiments/light_benchmark/flattening_read.py --only single diligent-rig
    python experiments/light_benchmark/flattening_read.py --report   # the tables from what has run

``light.selfcal.max_flattening_deg`` declines a fit that takes the lights nearer the view axis
than it found them. :func:`unps.lights.selfcal.flattening` reads that as the signed error of
each fitted light along its first guess's own tilt (:func:`unps.metrics.light_slant_bias`), so
a turn about the view axis counts toward it, and so does every move of a light the first guess
put near the axis: carried across the axis and out, a light read 2° from it and fitted 8° from it
on the other side reads as flattened by 10°. Read as zenith angles alone (:func:`zenith_flattening`:
the mean decrease of the lights' angle from the view axis) only a move nearer the axis counts.

Each case runs the network and the reversal test as ``python -m unps.fit light=selfcal`` does,
then the self-calibration's first fit — the shared frame held, no pull — from each reading it
would fit (as read; and half turned about the view where the reversal test warned that the
reading may be inside out or the network is unsure of it), never declined, and records both
readings of the fit's flattening and what the fit did to the lights' error. None of it feeds
training. Results are kept case by case in ``--out`` (default
``<cache>/flattening_read/<tag>``); a rerun resumes.
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

from unps.lights.reversal import half_turned
from unps.lights.selfcal import (fit_once, flattening, frame_held, unsure_reading, warned_inside_out,
                                 working_images)
from unps.metrics import angular_error

sys.path.insert(0, str(Path(__file__).resolve().parent))
import benchmark  # noqa: E402
import scenes  # noqa: E402

READINGS = ("slant", "zenith")   # flattening as the rule reads it; as zenith angles alone
LIMIT = 1.5                      # light.selfcal.max_flattening_deg when it was measured (2 since 2026-12-07)


def zenith(directions: np.ndarray) -> np.ndarray:
    """(n,) angles in degrees of (n, 3) directions of any length from the view axis +z.

    >>> zenith(np.array([[0.0, 0.0, 2.0], [1.0, 0.0, 1.0]])).round(6).tolist()
    [0.0, 45.0]
    """
    d = np.asarray(directions, dtype=np.float64)
    return np.degrees(np.arccos(np.clip(d[:, 2] / np.linalg.norm(d, axis=1), -1.0, 1.0)))


def zenith_flattening(directions: np.ndarray, first_guess: np.ndarray) -> float:
    """How much nearer the view axis the fitted ``directions`` (n, 3) are than ``first_guess``:
    the mean decrease of their angle from it, in degrees; < 0 where the fit steepened them.

    >>> near = np.array([[np.sin(np.radians(2)), 0.0, np.cos(np.radians(2))]])
    >>> across = np.array([[-np.sin(np.radians(8)), 0.0, np.cos(np.radians(8))]])
    >>> round(zenith_flattening(across, near), 6), round(flattening(across, near), 6)
    (-6.0, 10.0)
    """
    return float(np.mean(zenith(first_guess) - zenith(directions)))


@cache
def reversal_source():
    """The network and the reversal test as ``light=selfcal`` builds them."""
    return benchmark.light_source(["reversal"], [])[0]


def run_case(subject, selfcal) -> dict:
    """Per reading the self-calibration would fit: the first guess's and the held fit's
    directions (n, 3), never declined; the truth's; and the seconds taken."""
    begin = time.perf_counter()
    lights = reversal_source()(subject)
    readings = {"as read": lights}
    if selfcal.turn_inside_out and (warned_inside_out(lights) or unsure_reading(lights)):
        readings["half turn"] = half_turned(lights)
    held = replace(frame_held(selfcal), max_flattening_deg=None)
    fits = {}
    for name, start in readings.items():
        fitted, _ = fit_once(working_images(subject, start, held), start, held)
        fits[name] = {"start": start.directions.tolist(), "fit": fitted.directions.tolist()}
    return {"truth": subject.light_directions.tolist(), "fits": fits,
            "seconds": time.perf_counter() - begin}


def summarise(result: dict) -> dict:
    """Per reading: the start's and the fit's mean direction error, how far the fit moved the
    lights, its flattening both ways (degrees), and the start's and the truth's mean angle
    from the view axis."""
    truth = np.asarray(result["truth"], np.float64)
    out = {}
    for name, pair in result["fits"].items():
        start, fit = (np.asarray(pair[k], np.float64) for k in ("start", "fit"))
        out[name] = {"start": float(angular_error(start, truth).mean()),
                     "fit": float(angular_error(fit, truth).mean()),
                     "moved": float(angular_error(fit, start).mean()),
                     "slant": flattening(fit, start), "zenith": zenith_flattening(fit, start),
                     "start zenith": float(zenith(start).mean()),
                     "true zenith": float(zenith(truth).mean())}
    return out


def progress(case: tuple, s: dict, result: dict) -> str:
    """The line printed when a case has run."""
    return f"{' '.join(case)}: " + "; ".join(
        f"{name} {f['start']:.2f}° → {f['fit']:.2f}°, flattened {f['slant']:+.2f}° (slant) "
        f"{f['zenith']:+.2f}° (zenith)" for name, f in s.items()) + f" ({result['seconds']:.0f} s)"


def fits_of(rows: dict) -> list[tuple[tuple, str, dict]]:
    """Every fit of ``rows``: (case, reading, its summary)."""
    return [(case, name, f) for case, s in rows.items() for name, f in s.items()]


def declined_table(fits: list, limit: float = LIMIT) -> list[str]:
    """Per reading of the flattening, the fits it declines at ``limit`` and those it keeps: how
    many, how many of them the fit raised / lowered by more than 1°, their mean change."""
    lines = [f"{'flattening read as':<20} {'at ' + format(limit, 'g') + '°':<10} {'fits':>5} "
             f"{'raised >1°':>10} {'lowered >1°':>11} {'mean change':>12}"]
    for reading in READINGS:
        for verdict, chosen in (("declines", [f for *_, f in fits if f[reading] > limit]),
                                ("keeps", [f for *_, f in fits if f[reading] <= limit])):
            change = np.array([f["fit"] - f["start"] for f in chosen]) if chosen else np.zeros(0)
            mean = f"{change.mean():+11.2f}°" if len(change) else f"{'—':>12}"
            lines.append(f"{reading:<20} {verdict:<10} {len(chosen):>5} {int((change > 1).sum()):>10} "
                         f"{int((change < -1).sum()):>11} {mean}")
    return lines


def report(rows: dict) -> str:
    """Per fit both readings of its flattening and what it did to the error; the fits each reading
    declines at the default limit; and each reading's rank correlation with the change."""
    lines = [f"{'group':<12} {'case':<12} {'set':>3} {'reading':<9} {'start':>7} {'fit':>7} {'moved':>6} "
             f"{'slant':>7} {'zenith':>7} {'start z':>7} {'true z':>7}"]
    fits = fits_of(rows)
    for (group, name, label), reading, f in fits:
        lines.append(f"{group:<12} {name:<12} {label:>3} {reading:<9} {f['start']:>6.2f}° {f['fit']:>6.2f}° "
                     f"{f['moved']:>5.2f}° {f['slant']:>+6.2f}° {f['zenith']:>+6.2f}° "
                     f"{f['start zenith']:>6.1f}° {f['true zenith']:>6.1f}°")
    lines += ["", *declined_table(fits)]
    if len(fits) > 2:
        change = [f["fit"] - f["start"] for *_, f in fits]
        lines.append("\nrank correlation with the fit's change of the error: " + ", ".join(
            f"{reading} {spearmanr([f[reading] for *_, f in fits], change).correlation:+.2f}"
            for reading in READINGS) + f" ({len(fits)} fits)")
    return "\n".join(lines)


def main():
    benchmark.selfcal_study(__doc__.split("\n")[0], "flattening_read",
                            {"scenes": scenes.SCENE_VERSION, "stages": ["reversal", "selfcal"]},
                            run_case, summarise, progress, report)


if __name__ == "__main__":
    main()

"""Keep or discard a free self-calibration? Whether free fits from different starts agree, and
whether that agreement tracks the fit's true gain.

    python experiments/light_benchmark/starts.py --only benchmark diligent synthetic --names …
    python experiments/light_benchmark/starts.py --report              # the table from what has run

Each case runs the network and the reversal test as ``python -m unps.fit light=selfcal`` does,
then the self-calibration with the lights free (``prior_weight=0``, no decline for flattening:
``--set`` changes either) from five starts: the lights after the reversal test, and those lights
turned 6° about the image's x axis, 6° about its y axis, and stretched along the bas-relief's λ
away from and toward the view axis (their z component × 0.85 and × 1.15, renormalised). Where the
images pin the lights, every start should end in the same place; where the fit spends light
error on what its model cannot render, the hope is that they scatter. The report asks whether the
scatter (the fits' mean pairwise direction difference) tells the free fits that helped from those
that hurt, and what keeping the free fit only where the starts agree would do.

Results are kept case by case in ``--out`` (default ``<cache>/starts/<tag>``); a rerun resumes.
None of it feeds training.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from itertools import combinations
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from unps.lightnet.estimate import network_lights
from unps.lights.reversal import ReversalTest
from unps.lights.selfcal import SelfCalibration
from unps.metrics import angular_error

sys.path.insert(0, str(Path(__file__).resolve().parent))
import benchmark  # noqa: E402
import scenes  # noqa: E402

TURN_DEG = 6.0
STRETCH = 0.15
SCATTER_LEVELS = (1.0, 1.5, 2.0, 3.0)   # thresholds the report tries, degrees
FREE = {"prior_weight": 0.0, "max_flattening_deg": None}


def starts(directions: np.ndarray) -> dict[str, np.ndarray]:
    """(n, 3) unit directions to start from, by name: the given ones, turned :data:`TURN_DEG`
    about the x and the y axis, and with their z component × (1 ∓ :data:`STRETCH`).

    >>> {k: np.round(v, 3).tolist() for k, v in starts(np.array([[0.0, 0.0, 1.0]])).items()}["turn x"]
    [[0.0, -0.105, 0.995]]
    """
    out = {"start": directions}
    for axis in "xy":
        out[f"turn {axis}"] = Rotation.from_euler(axis, TURN_DEG, degrees=True).apply(directions)
    for name, factor in (("steeper", 1 - STRETCH), ("flatter", 1 + STRETCH)):
        stretched = directions * np.array([1.0, 1.0, factor])
        out[name] = stretched / np.linalg.norm(stretched, axis=1, keepdims=True)
    return out


def run_case(subject, selfcal: SelfCalibration) -> dict:
    """Directions (n, 3) of the truth, the network, the reversal test and the free fit from each
    start, and the seconds taken."""
    begin = time.perf_counter()
    network, _ = network_lights(subject, device="cpu")
    reversed_, _ = ReversalTest(device="cpu")(subject, network)
    fits = {}
    for name, directions in starts(reversed_.directions.astype(np.float64)).items():
        fitted, _ = selfcal(subject, dataclasses.replace(reversed_, directions=directions.astype(np.float32)))
        fits[name] = fitted.directions.tolist()
    return {"truth": subject.light_directions.tolist(), "network": network.directions.tolist(),
            "reversal": reversed_.directions.tolist(), "fits": fits,
            "seconds": time.perf_counter() - begin}


def scatter(fits: list[np.ndarray]) -> float:
    """Mean over pairs of fits of their mean direction difference (degrees)."""
    return float(np.mean([angular_error(a, b).mean() for a, b in combinations(fits, 2)]))


def summarise(result: dict) -> dict:
    """The case's light errors (mean degrees), per start and from the first start, and the
    starts' scatter."""
    truth = np.asarray(result["truth"], np.float64)
    fits = {k: np.asarray(v, np.float64) for k, v in result["fits"].items()}
    error = {k: float(angular_error(np.asarray(result[k], np.float64), truth).mean())
             for k in ("network", "reversal")}
    return {**error, "free": float(angular_error(fits["start"], truth).mean()),
            "per_start": [float(angular_error(f, truth).mean()) for f in fits.values()],
            "scatter": scatter(list(fits.values()))}


def progress(case: tuple, s: dict, result: dict) -> str:
    """The line printed when a case has run."""
    return (f"{' '.join(case)}: start {s['reversal']:.2f}° free {s['free']:.2f}° scatter "
            f"{s['scatter']:.2f}° ({result['seconds']:.0f} s)")


def report(rows: dict) -> str:
    """Per case the errors and the scatter; over all cases the rule 'keep the free fit where the
    starts scatter less than this' against keeping none and keeping every one."""
    lines = [f"{'group':<9} {'case':<12} {'set':>3} {'network':>8} {'start':>8} {'free':>8} "
             f"{'gain':>6} {'scatter':>8}   each start's fit"]
    for (group, name, label), s in rows.items():
        lines.append(f"{group:<9} {name:<12} {label:>3} {s['network']:>7.2f}° {s['reversal']:>7.2f}° "
                     f"{s['free']:>7.2f}° {s['reversal'] - s['free']:>+6.2f} {s['scatter']:>7.2f}°   "
                     + " ".join(f"{e:6.2f}" for e in s["per_start"]))
    if len(rows) > 2:
        gains = np.array([s["reversal"] - s["free"] for s in rows.values()])
        spread = np.array([s["scatter"] for s in rows.values()])
        rank = np.corrcoef(np.argsort(np.argsort(-spread)), np.argsort(np.argsort(gains)))[0, 1]
        lines.append(f"\nrank correlation of agreement (−scatter) and gain over {len(rows)} cases: "
                     f"{rank:+.2f}; the free fit raised the error on {int((gains < 0).sum())}, by more "
                     f"than 1° on {int((gains < -1).sum())}")
        cells = []
        for level in SCATTER_LEVELS:
            kept = [s["free"] if s["scatter"] < level else s["reversal"] for s in rows.values()]
            worst = max(k - s["reversal"] for k, s in zip(kept, rows.values()))
            cells.append(f"scatter < {level:g}°: {np.mean(kept):.2f}° (worst raise {worst:+.2f}°)")
        none, every = (np.mean([s[key] for s in rows.values()]) for key in ("reversal", "free"))
        lines.append(f"mean error, keeping no free fit: {none:.2f}°; every one: {every:.2f}°; "
                     + "; ".join(cells))
    return "\n".join(lines)


def main():
    benchmark.selfcal_study(__doc__.split("\n")[0], "starts",
                            {"scenes": scenes.SCENE_VERSION, "starts": [TURN_DEG, STRETCH],
                             "stages": ["reversal", "selfcal"]},
                            run_case, summarise, progress, report, FREE)


if __name__ == "__main__":
    main()

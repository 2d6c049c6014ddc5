"""Keep or discard a self-calibration? Whether fits on halves of the images agree with the fit on
all of them, and whether that agreement tracks the fit's true gain.

    python experiments/light_benchmark/subsets.py                       # every case
    python experiments/light_benchmark/subsets.py --only benchmark --sets 96
    python experiments/light_benchmark/subsets.py --report              # the table from what has run

Each case runs the default light stages as ``python -m unps.fit light=selfcal`` does (the
network, the reversal test, the self-calibration), then the self-calibration again on each half
of the images (even and odd indices; each half starts from its own lights after the reversal
test, held near them by the same prior). A light's *move* is where a fit takes it from its
start. Where the images pin the lights, a half's fit should move each of its lights as the fit
on all images does; where the fit spends light error on what its model cannot render, or the
lights are free along the bas-relief, the halves need not agree. The report asks whether that
agreement tells the fits that helped from those that hurt, and what keeping a fit only where
its halves agree would do to the benchmark's figures.

``--set prior_weight=0.001 --tag p0.001`` runs it with other self-calibration settings.
Results are kept case by case in ``--out`` (default ``<cache>/subsets/<tag>``); a rerun resumes.
None of it feeds training.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from unps.data.lights import Lights
from unps.lightnet.estimate import network_lights
from unps.lights.reversal import ReversalTest
from unps.lights.selfcal import SelfCalibration
from unps.metrics import angular_error

sys.path.insert(0, str(Path(__file__).resolve().parent))
import benchmark  # noqa: E402
import runs  # noqa: E402
import scenes  # noqa: E402

AGREEMENT_LEVELS = (0.0, 0.25, 0.5, 0.75)   # thresholds the report tries


def halves(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Even and odd image indices."""
    return np.arange(0, n, 2), np.arange(1, n, 2)


def part(lights: Lights, indices: np.ndarray) -> Lights:
    """The lights of the images at ``indices``."""
    return Lights(lights.directions[indices],
                  None if lights.intensities is None else lights.intensities[indices],
                  lights.source, None if lights.spread_deg is None else lights.spread_deg[indices])


def run_case(subject, selfcal: SelfCalibration) -> dict:
    """Directions (n, 3) of the truth, the network, the reversal test, the fit on all images and
    the fits on the halves (each light from the half it is in), and the seconds taken."""
    start = time.perf_counter()
    network, _ = network_lights(subject, device="cpu")
    reversed_, _ = ReversalTest(device="cpu")(subject, network)
    full, _ = selfcal(subject, reversed_)
    from_halves = np.zeros_like(full.directions)
    for indices in halves(subject.n_images):
        fitted, _ = selfcal(subject.select(indices), part(reversed_, indices))
        from_halves[indices] = fitted.directions
    return {"truth": subject.light_directions.tolist(), "network": network.directions.tolist(),
            "reversal": reversed_.directions.tolist(), "full": full.directions.tolist(),
            "halves": from_halves.tolist(), "seconds": time.perf_counter() - start}


def agreement(start: np.ndarray, full: np.ndarray, from_halves: np.ndarray) -> float:
    """How far the halves' fits move the lights as the fit on all images does: Σ m_full·m_half /
    Σ |m_full|², over the lights' moves m (unit directions' differences from ``start``); 1 when
    each half repeats the full fit's moves, 0 when its moves are unrelated, negative when
    opposed."""
    moved_full, moved_half = full - start, from_halves - start
    return float((moved_full * moved_half).sum() / max((moved_full ** 2).sum(), 1e-12))


def summarise(result: dict) -> dict:
    """The case's light errors (mean degrees) and the agreement of its halves."""
    arrays = {k: np.asarray(result[k], np.float64)
              for k in ("truth", "network", "reversal", "full", "halves")}
    error = {k: float(angular_error(arrays[k], arrays["truth"]).mean()) for k in
             ("network", "reversal", "full")}
    return {**error, "moved": float(angular_error(arrays["full"], arrays["reversal"]).mean()),
            "agreement": agreement(arrays["reversal"], arrays["full"], arrays["halves"])}


def progress(case: tuple, s: dict, result: dict) -> str:
    """The line printed when a case has run."""
    return (f"{' '.join(case)}: network {s['network']:.2f}° selfcal {s['full']:.2f}° agreement "
            f"{s['agreement']:+.2f} ({result['seconds']:.0f} s)")


def report(rows: dict) -> str:
    """Per case the errors and agreement; per light count the rule 'keep the fit where the halves
    agree at least this much' against keeping every fit."""
    lines = [f"{'group':<9} {'case':<12} {'set':>3} {'network':>8} {'reversal':>8} {'selfcal':>8} "
             f"{'gain':>6} {'moved':>6} {'agree':>6}"]
    for (group, name, label), s in rows.items():
        lines.append(f"{group:<9} {name:<12} {label:>3} {s['network']:>7.2f}° {s['reversal']:>7.2f}° "
                     f"{s['full']:>7.2f}° {s['reversal'] - s['full']:>+6.2f} {s['moved']:>6.2f} "
                     f"{s['agreement']:>+6.2f}")
    gains = np.array([s["reversal"] - s["full"] for s in rows.values()])
    agree = np.array([s["agreement"] for s in rows.values()])
    if len(rows) > 2:
        order = np.argsort(np.argsort(agree)), np.argsort(np.argsort(gains))
        rank = np.corrcoef(*order)[0, 1]
        lines.append(f"\nrank correlation of agreement and gain over {len(rows)} cases: {rank:+.2f}; "
                     f"the fit raised the error on {int((gains < 0).sum())}, by more than 1° on "
                     f"{int((gains < -1).sum())}")
    storage = {obj.name: obj.storage for obj in scenes.OBJECTS}
    lines.append(f"\n{'stored as':<9} {'cases':>5} {'start':>8} {'selfcal':>8} {'raised >1°':>10}")
    for kind in scenes.FORMATS:
        chosen = [s for k, s in rows.items() if k[0] == "benchmark" and storage[k[1]] == kind]
        if chosen:
            raised = sum(s["full"] - s["reversal"] > 1 for s in chosen)
            lines.append(f"{kind:<9} {len(chosen):>5} {np.mean([s['reversal'] for s in chosen]):>7.2f}° "
                         f"{np.mean([s['full'] for s in chosen]):>7.2f}° {raised:>10}")
    lines.append(f"\n{'group':<9} {'set':>4} {'cases':>5} {'network':>8} {'keep all':>8} "
                 + " ".join(f"{f'agree≥{t:g}':>10}" for t in AGREEMENT_LEVELS)
                 + "   (mean final error / fits kept)")
    for group, label, chosen in runs.by_light_set(rows):
        cells = []
        for level in AGREEMENT_LEVELS:
            final = [s["full"] if s["agreement"] >= level else s["reversal"] for s in chosen]
            kept = sum(s["agreement"] >= level for s in chosen)
            cells.append(f"{np.mean(final):>6.2f}°/{kept:<3}")
        network, full = (np.mean([s[key] for s in chosen]) for key in ("network", "full"))
        lines.append(f"{group:<9} {label:>4} {len(chosen):>5} {network:>7.2f}° {full:>7.2f}° "
                     + " ".join(cells))
    return "\n".join(lines)


def main():
    benchmark.selfcal_study(__doc__.split("\n")[0], "subsets",
                            {"scenes": scenes.SCENE_VERSION, "halves": "even/odd",
                             "stages": ["reversal", "selfcal"]},
                            run_case, summarise, progress, report)


if __name__ == "__main__":
    main()

"""Are the light network's lights read nearer the view axis than they are, and would steepening help?

    python experiments/light_benchmark/steepened.py             # benchmark, single, DiLiGenT: ~10 min
    python experiments/light_benchmark/steepened.py --only diligent --sets 12
    python experiments/light_benchmark/steepened.py --report    # the table from what has run

Per case: the network's lights (``light=selfcal``'s first stage, eight passes, no stage after it),
their slant bias (:func:`unps.metrics.light_slant_bias`: < 0 where they are read nearer the view
axis than they are) and their direction error after every light is steepened — turned away from the
view axis, its tilt kept — by each of :data:`STEPS` degrees. Per group and light set: the mean and
median slant bias and the mean error at each step. A uniform steepening that lowers the error on
DiLiGenT's photographs and raises it on the renders marks a bias of the photographs that the renders
lack. Results are kept case by case in ``--out`` (default ``<cache>/steepened``); a rerun resumes.
None of it feeds training.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from unps.metrics import light_direction_mae, light_slant_bias

sys.path.insert(0, str(Path(__file__).resolve().parent))
import benchmark  # noqa: E402
import runs  # noqa: E402
import scenes  # noqa: E402

STEPS = (0.0, 0.5, 1.0, 1.5, 2.0, 3.0)     # degrees of steepening


def steepened(directions: np.ndarray, degrees: float) -> np.ndarray:
    """(n, 3) unit directions turned ``degrees`` away from the view axis +z (toward it where
    negative), each keeping its tilt (its azimuth about +z); the angle from +z is held within
    [0°, 90°]. A direction on the axis itself is turned toward +x.

    >>> d = steepened(np.array([[np.sin(np.radians(30)), 0.0, np.cos(np.radians(30))]]), 2.0)
    >>> round(float(np.degrees(np.arccos(d[0, 2]))), 6), float(d[0, 1])
    (32.0, 0.0)
    """
    d = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    slant = np.clip(np.arccos(np.clip(d[:, 2], -1, 1)) + np.radians(degrees), 0, np.pi / 2)
    tilt = np.arctan2(d[:, 1], d[:, 0])
    return np.stack([np.sin(slant) * np.cos(tilt), np.sin(slant) * np.sin(tilt), np.cos(slant)], 1)


def run_case(subject, network) -> dict:
    """The network's slant bias on ``subject`` and its direction error at each of :data:`STEPS`."""
    directions, truth = network(subject).directions, subject.light_directions
    return {"slant": light_slant_bias(directions, truth),
            "errors": [light_direction_mae(steepened(directions, s), truth) for s in STEPS]}


def report(rows: dict) -> str:
    """Per group and light set: cases, mean and median slant bias, and the mean direction error
    with the network's lights steepened by each of :data:`STEPS` (the lowest marked *)."""
    lines = [f"{'':<20} {'':>5} {'slant bias':>12}    mean direction error, steepened by",
             f"{'group':<9} {'set':>4} {'cases':>5} {'mean':>9} {'median':>8}  "
             + "".join(f"{f'{s:+.1f}°':>9}" for s in STEPS)]
    for group, label, chosen in runs.by_light_set(rows):
        slants = [r["slant"] for r in chosen]
        errors = np.mean([r["errors"] for r in chosen], axis=0)
        best = int(np.argmin(errors))
        lines.append(f"{group:<9} {label:>4} {len(chosen):>5} {np.mean(slants):>+8.2f}° "
                     f"{np.median(slants):>+7.2f}°  "
                     + "".join(f"{e:>8.2f}{'*' if k == best else '°'}" for k, e in enumerate(errors)))
    return "\n".join(lines)


def progress(case: tuple, row: dict, result: dict) -> str:
    """The line printed when a case has run."""
    return (f"{' '.join(case)}: slant bias {row['slant']:+.2f}°, error {row['errors'][0]:.2f}° → "
            + " ".join(f"{e:.2f}°" for e in row["errors"][1:]))


def main() -> None:
    parser = benchmark.study_parser(__doc__.split("\n")[0], "default: <cache>/steepened",
                                    groups=("benchmark", "single", "diligent"))
    args = parser.parse_args()
    out = args.out or args.cache / "steepened"
    made_with = {"scenes": scenes.SCENE_VERSION, "steps": list(STEPS)}
    benchmark.network_study(parser, args, out, made_with, run_case, report, progress)


if __name__ == "__main__":
    main()

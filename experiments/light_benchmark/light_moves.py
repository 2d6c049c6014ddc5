"""Where the fit's step on the lights goes: a common rotation of all of them, or the rest.

    python experiments/light_benchmark/light_moves.py BEFORE AFTER
    python experiments/light_benchmark/light_moves.py --selfcal [--sets 12 20] [--only benchmark]

BEFORE and AFTER are run folders of ``normals.py --light selfcal`` (one ``<object>-unps/``
folder per object): BEFORE made with ``light.refine=false`` (the self-calibrated lights as the
fit gets them), AFTER with the fit learning them (``preset.hold_light_frame=false`` to see the
rotation the fit would learn). For each object found in both: the lights' direction error before
and after, how far the fit moved them, the angle of the rotation that best carries the lights
before onto those after (Kabsch), and the error of the lights with only that rotation applied,
and with only the rest of the move. Rotating all lights and all normals together leaves the
diffuse shading unchanged, so the fit's loss hardly tells such a turn; what the images do tell
it is in the rest.

With ``--selfcal`` the same split is made of the self-calibration's move: each light benchmark case
(``benchmark.py``'s) is estimated by the network and the reversal test, then self-calibrated with
the default settings, one json per case in ``<cache>/results/selfcal_moves/`` (a rerun resumes;
``--report`` prints what has run).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from unps.lights.contour import best_rotation, rotation_angle
from unps.metrics import angular_error
from unps.report.figures import read_light_file

sys.path.insert(0, str(Path(__file__).parent))
import benchmark  # noqa: E402
import runs  # noqa: E402
import scenes  # noqa: E402


def decompose(before: np.ndarray, after: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """The move from ``before`` to ``after`` ((n, 3) unit directions) split into a common rotation
    and the rest, each applied alone, with the mean direction error against ``truth``."""
    rotation = best_rotation(before, after)
    turned = before @ rotation.T
    rest = before + (after - turned)
    rest /= np.linalg.norm(rest, axis=1, keepdims=True)

    def error(lights):
        return float(angular_error(lights, truth).mean())

    return {"before": error(before), "after": error(after),
            "moved": float(angular_error(before, after).mean()), "turn": rotation_angle(rotation),
            "turn_only": error(turned), "rest_only": error(rest)}


HEADER = f"{'object':<14}{'before':>9}{'after':>9}{'moved':>8}{'turn':>8}{'turn only':>11}{'rest only':>11}"


def line(name: str, row: dict[str, float]) -> str:
    return (f"{name:<14}{row['before']:>8.2f}°{row['after']:>8.2f}°{row['moved']:>7.2f}°"
            f"{row['turn']:>7.2f}°{row['turn_only']:>10.2f}°{row['rest_only']:>10.2f}°")


def summary(rows: list[dict[str, float]]) -> str:
    """Means over ``rows`` and how often the turn alone, and the rest alone, lowered or raised the
    error by more than 0.1°."""
    mean = {key: float(np.mean([r[key] for r in rows])) for key in rows[0]}
    counts = [sum(r[key] < r["before"] - 0.1 for r in rows) for key in ("turn_only", "rest_only")]
    raised = [sum(r[key] > r["before"] + 0.1 for r in rows) for key in ("turn_only", "rest_only")]
    return (line(f"mean ({len(rows)})", mean) + f"\n{'':<14}the turn alone lowers the error on {counts[0]}, "
            f"raises it on {raised[0]}; the rest alone lowers it on {counts[1]}, raises it on {raised[1]}")


def fit_moves(before: Path, after: Path) -> None:
    names = sorted(p.name for p in after.glob("*-unps")
                   if (before / p.name / "lights.txt").is_file() and (p / "lights.txt").is_file())
    if not names:
        sys.exit(f"no object with lights.txt in both {before} and {after}")
    print(HEADER)
    for name in names:
        row = decompose(read_light_file(before / name / "lights.txt"),
                        read_light_file(after / name / "lights.txt"),
                        read_light_file(after / name / "lights_gt.txt"))
        print(line(name.removesuffix("-unps"), row))


def selfcal_moves(args) -> None:
    """The self-calibration's move on each case, split as :func:`decompose` splits it."""
    out = args.cache / "results" / "selfcal_moves"
    runs.claim(out, {"scenes": scenes.SCENE_VERSION})
    network, _ = benchmark.light_source(["reversal"], [])
    selfcal = benchmark.instantiate_node(["fit"], ["light=selfcal"], "light.selfcal")()

    def run(subject) -> dict[str, float]:
        start = network(subject)
        fitted, _ = selfcal(subject, start)
        return decompose(start.directions.astype(np.float64), fitted.directions.astype(np.float64),
                         subject.light_directions.astype(np.float64))

    def progress(case, row, _) -> str:
        return f"{case[0]:<10}{case[2]:>4} {line(case[1], row)}"

    rows = runs.summaries(benchmark.study_cases(args), out, run, lambda row: row,
                                    progress, args.report)
    print(f"\n{'':<10}{'set':>4} {HEADER}")
    print("\n".join(progress(case, row, None) for case, row in rows.items()))
    for group, label, group_rows in runs.by_light_set(rows):
        print(f"\n{group} {label}\n{summary(group_rows)}")


def main(argv=None) -> None:
    parser = benchmark.study_parser(__doc__.split("\n")[0], "unused", groups=["benchmark"])
    parser.add_argument("before", type=Path, nargs="?", help="run folder: light.refine=false")
    parser.add_argument("after", type=Path, nargs="?", help="run folder: the fit learns the lights")
    parser.add_argument("--selfcal", action="store_true",
                        help="split the self-calibration's move on the light benchmark's cases instead")
    args = parser.parse_args(argv)
    if args.selfcal:
        selfcal_moves(args)
    elif args.before is None or args.after is None:
        parser.error("give BEFORE and AFTER run folders, or --selfcal")
    else:
        fit_moves(args.before, args.after)


if __name__ == "__main__":
    main()

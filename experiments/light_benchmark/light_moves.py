"""Where the fit's step on the lights goes: a common rotation of all of them, or the rest.

    python experiments/light_benchmark/light_moves.py BEFORE AFTER
    python experiments/light_benchmark/light_moves.py BEFORE AFTER --linear
    python experiments/light_benchmark/light_moves.py --selfcal [--sets 12 20] [--only benchmark]

BEFORE and AFTER are run folders of ``normals.py --light selfcal`` (one ``<object>-<method>/``
folder per object): BEFORE made with ``light.refine=false``, or with a method that does not learn
the lights (``--methods woodham``: the light stages alone, no fit), so that its ``lights.txt`` are
the self-calibrated lights as the fit gets them; AFTER with ``--methods unps``, the fit learning
them (``preset.hold_light_frame=false`` to see the rotation the fit would learn). For each object
found in both: the lights' direction error before and after, how far the fit moved them, the
angle of the rotation that best carries the lights before onto those after (Kabsch), and the
error of the lights with only that rotation applied, and with only the rest of the move.
Rotating all lights and all normals together leaves the diffuse shading unchanged, so the fit's
loss hardly tells such a turn; what the images do tell it is in the rest.

With ``--linear`` the common part is the 3 × 3 linear map that best carries the scaled lights
(direction × intensity) before onto those after, least squares: a fit whose normals and albedos
are free pixel by pixel absorbs any such map of the lights for diffuse shading (the rotation is
one of them), so its loss hardly pins it either.

With ``--selfcal`` the same split is made of the self-calibration's move: each light benchmark case
(``benchmark.py``'s) is estimated by the network and the reversal test, then self-calibrated with
the default settings, one json per case in ``<cache>/results/selfcal_moves/`` (a rerun resumes;
``--report`` prints what has run).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from unps.inverse.fit import unit
from unps.lights.contour import best_rotation, rotation_angle
from unps.metrics import angular_error
from unps.report.figures import read_light_file

sys.path.insert(0, str(Path(__file__).parent))
import benchmark  # noqa: E402
import normals  # noqa: E402
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


def decompose_linear(before: np.ndarray, after: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """The move from ``before`` to ``after`` ((n, 3) scaled lights: unit direction × relative
    intensity) split into the common linear map that best carries one onto the other (least
    squares) and the rest, each applied alone, with the mean direction error against ``truth``
    ((n, 3) unit); "linear" is how far the map alone moves the directions (mean, degrees)."""
    start, end = unit(before), unit(after)
    linear_map, *_ = np.linalg.lstsq(before, after, rcond=None)         # after ≈ before @ map
    mapped = unit(before @ linear_map)
    rest = unit(start + (end - mapped))

    def error(lights):
        return float(angular_error(lights, truth).mean())

    return {"before": error(start), "after": error(end), "moved": float(angular_error(start, end).mean()),
            "linear": float(angular_error(start, mapped).mean()), "linear_only": error(mapped),
            "rest_only": error(rest)}


def header(common: str = "turn") -> str:
    return (f"{'object':<14}{'before':>9}{'after':>9}{'moved':>8}{common:>8}{common + ' only':>13}"
            f"{'rest only':>11}")


def line(name: str, row: dict[str, float]) -> str:
    common = "turn" if "turn" in row else "linear"
    return (f"{name:<14}{row['before']:>8.2f}°{row['after']:>8.2f}°{row['moved']:>7.2f}°"
            f"{row[common]:>7.2f}°{row[common + '_only']:>12.2f}°{row['rest_only']:>10.2f}°")


def summary(rows: list[dict[str, float]]) -> str:
    """Means over ``rows`` and how often the common part alone (the turn, or the linear map), and
    the rest alone, lowered or raised the error by more than 0.1°, and by more than 1° and 2°."""
    common = "turn" if "turn" in rows[0] else "linear"
    mean = {key: float(np.mean([r[key] for r in rows])) for key in rows[0]}
    keys = (common + "_only", "rest_only")
    counts = [sum(r[key] < r["before"] - 0.1 for r in rows) for key in keys]
    raised = [sum(r[key] > r["before"] + 0.1 for r in rows) for key in keys]
    lines = [line(f"mean ({len(rows)})", mean),
             f"{'':<14}the {common} alone lowers the error on {counts[0]}, raises it on {raised[0]}; "
             f"the rest alone lowers it on {counts[1]}, raises it on {raised[1]}"]
    parts = (("after", "the whole move"), (keys[0], f"the {common} alone"), ("rest_only", "the rest alone"))
    for key, label in parts:
        raises = [r[key] - r["before"] for r in rows]
        lines.append(f"{'':<14}{label} raises it by more than 1° on {sum(x > 1 for x in raises)}, by more "
                     f"than 2° on {sum(x > 2 for x in raises)}; the most {max(raises):+.2f}°")
    return "\n".join(lines)


def read_scaled_lights(path: Path) -> np.ndarray:
    """(n, 3) unit directions × the mean of their RGB intensities (geometric mean 1) from a
    ``lights.txt`` (:func:`unps.lights.write_lights`); intensities 1 where it has none."""
    table = np.loadtxt(path, ndmin=2)
    intensity = table[:, 3:].mean(1) if table.shape[1] > 3 else np.ones(len(table))
    return table[:, :3] * (intensity / np.exp(np.log(intensity).mean()))[:, None]


def fit_moves(before: Path, after: Path, linear: bool = False) -> None:
    """Each object's fit move from ``before`` (any ``<object>-<method>`` folder with a
    ``lights.txt``) to ``after`` (``<object>-unps``), split by :func:`decompose` or, with
    ``linear``, :func:`decompose_linear`; then :func:`summary`."""
    pairs = {}
    for folder in sorted(after.glob("*-unps")):
        name = folder.name.removesuffix("-unps")
        starts = [before / f"{name}-{method}" / "lights.txt" for method in normals.METHODS]
        starts = [start for start in starts if start.is_file()]
        if starts and (folder / "lights.txt").is_file():
            pairs[name] = (starts[0], folder)
    if not pairs:
        sys.exit(f"no object with lights.txt in both {before} and {after}")
    print(header("linear" if linear else "turn"))
    rows = []
    for name, (start, folder) in pairs.items():
        truth = read_light_file(folder / "lights_gt.txt")
        if linear:
            row = decompose_linear(read_scaled_lights(start), read_scaled_lights(folder / "lights.txt"),
                                   truth)
        else:
            row = decompose(read_light_file(start), read_light_file(folder / "lights.txt"), truth)
        rows.append(row)
        print(line(name, row))
    print(summary(rows))


def selfcal_moves(args) -> None:
    """The self-calibration's move on each case, split as :func:`decompose` splits it."""
    out = args.cache / "results" / "selfcal_moves"
    try:
        runs.claim(out, {"scenes": scenes.SCENE_VERSION, "weights": runs.weights_digest(None),
                         **benchmark.capture_options(args)},
                   way_out="delete the folder to run the study again")
    except ValueError as e:
        sys.exit(str(e))
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
    print(f"\n{'':<10}{'set':>4} {header()}")
    print("\n".join(progress(case, row, None) for case, row in rows.items()))
    for group, label, group_rows in runs.by_light_set(rows):
        print(f"\n{group} {label}\n{summary(group_rows)}")


def main(argv=None) -> None:
    parser = benchmark.study_parser(__doc__.split("\n")[0], "unused", groups=["benchmark"])
    parser.add_argument("before", type=Path, nargs="?",
                        help="run folder: light.refine=false, or a method that keeps the lights")
    parser.add_argument("after", type=Path, nargs="?", help="run folder: the fit learns the lights")
    parser.add_argument("--linear", action="store_true",
                        help="split off the common linear map of the scaled lights, not only the rotation")
    parser.add_argument("--selfcal", action="store_true",
                        help="split the self-calibration's move on the light benchmark's cases instead")
    args = parser.parse_args(argv)
    if args.selfcal:
        selfcal_moves(args)
    elif args.before is None or args.after is None:
        parser.error("give BEFORE and AFTER run folders, or --selfcal")
    else:
        fit_moves(args.before, args.after, args.linear)


if __name__ == "__main__":
    main()

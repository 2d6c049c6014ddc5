"""Where the fit's step on the lights goes: a common rotation of all of them, or the rest.

    python experiments/light_benchmark/light_moves.py BEFORE AFTER

BEFORE and AFTER are run folders of ``normals.py --light selfcal`` (one ``<object>-unps/``
folder per object): BEFORE made with ``light.refine=false`` (the self-calibrated lights as the
fit gets them), AFTER with the fit learning them (``preset.hold_light_frame=false`` to see the
rotation the fit would learn). For each object found in both: the lights' direction error before
and after, how far the fit moved them, the angle of the rotation that best carries the lights
before onto those after (Kabsch), and the error of the lights with only that rotation applied,
and with only the rest of the move. Rotating all lights and all normals together leaves the
diffuse shading unchanged, so the fit's loss hardly tells such a turn; what the images do tell
it is in the rest.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from unps.lights.contour import best_rotation, rotation_angle
from unps.metrics import angular_error
from unps.report.figures import read_light_file


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


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("before", type=Path, help="run folder: light.refine=false")
    parser.add_argument("after", type=Path, help="run folder: the fit learns the lights")
    args = parser.parse_args(argv)
    names = sorted(p.name for p in args.after.glob("*-unps")
                   if (args.before / p.name / "lights.txt").is_file() and (p / "lights.txt").is_file())
    if not names:
        sys.exit(f"no object with lights.txt in both {args.before} and {args.after}")
    print(f"{'object':<14}{'before':>9}{'after':>9}{'moved':>8}{'turn':>8}{'turn only':>11}{'rest only':>11}")
    for name in names:
        row = decompose(read_light_file(args.before / name / "lights.txt"),
                        read_light_file(args.after / name / "lights.txt"),
                        read_light_file(args.after / name / "lights_gt.txt"))
        print(f"{name.removesuffix('-unps'):<14}{row['before']:>8.2f}°{row['after']:>8.2f}°{row['moved']:>7.2f}°"
              f"{row['turn']:>7.2f}°{row['turn_only']:>10.2f}°{row['rest_only']:>10.2f}°")


if __name__ == "__main__":
    main()

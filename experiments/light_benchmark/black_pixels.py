"""Where the calibrated normals go wrong on the light benchmark: pixels black in every image.

    python experiments/light_benchmark/black_pixels.py --runs <cache>/normals/default
    python experiments/light_benchmark/black_pixels.py --runs paper=<dir> relative=<dir> --methods rpca unps

Reads the rows that ``normals.py`` fitted (``<run>/<object>-<method>/normals.npy``, 96 lights,
``light=gt``) and splits each object's normal error between the pixels the images say something
about and those that are black in every one of the 96 images: no value above the stack's
``--levels`` lowest quantisation levels (:func:`unps.data.checks.black_everywhere`; 2/255 for the
8-bit objects, practically nothing for the 16-bit ones, whose noise fills the lowest levels). A
black pixel holds no shading at all, so any normal explains it; what a method puts there is its
guess.

It also prints what continuing the surface from the lit pixels across the black ones gives
(:func:`unps.geometry.continue_surface`, what ``method=unps`` does with
``preset.continue_black=true``, the default since 2026-11-26), for rows fitted without it.

Printed per object: the share of black pixels, then per run and method the mean angular error
over the whole object, over its lit pixels, and with the black pixels continued.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from unps.data.checks import black_everywhere
from unps.data.diligent import read_diligent
from unps.geometry import continue_surface
from unps.metrics import angular_error

sys.path.insert(0, str(Path(__file__).resolve().parent))
import scenes  # noqa: E402

DEFAULT_DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
DEFAULT_CACHE = Path("~/.cache/unps/light_benchmark").expanduser()
LIGHT_SET = "96"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", nargs="+", required=True,
                        help="normals.py run folders, each [label=]folder")
    parser.add_argument("--methods", nargs="+", default=["unps"], choices=("woodham", "rpca", "unps"))
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    parser.add_argument("--levels", type=int, default=2, help="quantisation levels still counted as black")
    args = parser.parse_args(argv)
    runs = dict(r.split("=", 1) if "=" in r else (Path(r).name, r) for r in args.runs)
    columns = [(label, Path(folder), method) for label, folder in runs.items() for method in args.methods]
    for _, folder, method in columns:
        missing = [o.name for o in scenes.OBJECTS
                   if not (folder / f"{o.name}-{method}" / "normals.npy").is_file()]
        if missing:
            sys.exit(f"{folder}: no {method} normals for {', '.join(missing)} (run normals.py first)")

    print(f"light benchmark, {LIGHT_SET} lights, light=gt: normal MAE ° over the object / its lit pixels / "
          f"with the black pixels continued (black: no value above {args.levels} steps in any image)")
    print(f"{'object':<12}{'storage':>8}{'black':>7}  "
          + "".join(f"{label + ' ' + m:>24}" for label, _, m in columns))
    totals = np.zeros((len(columns), 3))
    for obj in scenes.OBJECTS:
        folder = scenes.make_captures(obj, args.data, args.cache)[LIGHT_SET]
        subject = read_diligent(folder, name=obj.name, quantization=scenes.quantization(obj.storage))
        mask = subject.mask
        black = black_everywhere(subject.observed_images(), mask, args.levels)
        line = f"{obj.name:<12}{obj.storage:>8}{black.sum() / mask.sum():>7.0%}  "
        for i, (_, run, method) in enumerate(columns):
            normals = np.load(run / f"{obj.name}-{method}" / "normals.npy")
            error = angular_error(normals[mask], subject.normals[mask])
            lit = error[~black[mask]].mean() if (~black[mask]).any() else float("nan")
            filled = angular_error(continue_surface(normals, mask, black)[mask], subject.normals[mask]).mean()
            totals[i] += error.mean(), lit, filled
            line += f"{error.mean():>8.2f}{lit:>8.2f}{filled:>8.2f}"
        print(line, flush=True)
    means = totals / len(scenes.OBJECTS)
    print(f"{'mean':<27}  " + "".join(f"{a:>8.2f}{b:>8.2f}{c:>8.2f}" for a, b, c in means))


if __name__ == "__main__":
    main()

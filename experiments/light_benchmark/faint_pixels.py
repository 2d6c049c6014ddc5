"""Where continuing the surface across faintly lit pixels moves the normals on the light benchmark.

    python experiments/light_benchmark/faint_pixels.py --before <run> --after <run> [--lights 96]

Reads the rows of two ``normals.py`` run folders (``<run>/<object>-unps/normals.npy``, the true
lights), one fitted before faintly lit pixels were continued and one after (``README.md``,
"Pixels nearly black"), and prints for each 8-bit object that has faintly lit pixels
(:func:`unps.data.checks.faintly_lit`: no value above the stack's ten lowest levels, more than the
first in at most half the images): their share of the object; the share whose values do not
follow Lambert's cosine under the true lights (:func:`unps.inverse.fit.unshaded`), which the
read-out continues unless a highlight lights them; the mean angular error on those pixels before
and after; and each object's whole error before and after.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from unps.data.checks import faintly_lit
from unps.data.diligent import read_diligent
from unps.inverse.fit import unshaded
from unps.metrics import angular_error

sys.path.insert(0, str(Path(__file__).resolve().parent))
import scenes  # noqa: E402

DEFAULT_DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
DEFAULT_CACHE = Path("~/.cache/unps/light_benchmark").expanduser()


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--before", type=Path, required=True, help="normals.py run folder")
    parser.add_argument("--after", type=Path, required=True, help="normals.py run folder")
    parser.add_argument("--lights", choices=list(scenes.LIGHT_SETS), default="96")
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    args = parser.parse_args(argv)
    for run in (args.before, args.after):
        missing = [o.name for o in scenes.OBJECTS if not (run / f"{o.name}-unps" / "normals.npy").is_file()]
        if missing:
            sys.exit(f"{run}: no unps normals for {', '.join(missing)} (run normals.py first)")

    print(f"light benchmark, {args.lights} lights, light=gt: faintly lit pixels (share of the object), "
          "those not following Lambert's cosine, the normal MAE ° there before -> after, the object's")
    print(f"{'object':<12}{'storage':>8}{'faint':>7}{'unshaded':>10}{'there':>18}{'object':>18}")
    for obj in scenes.OBJECTS:
        folder = scenes.make_captures(obj, args.data, args.cache)[args.lights]
        subject = read_diligent(folder, name=obj.name, quantization=scenes.quantization(obj.storage))
        mask = subject.mask
        faint = faintly_lit(subject.observed_images(), mask)
        if not faint.any():
            continue
        continued = faint.copy()
        continued[faint] = unshaded(subject.images[:, faint].mean(-1), subject.light_directions)
        errors = [angular_error(np.load(run / f"{obj.name}-unps" / "normals.npy"), subject.normals)
                  for run in (args.before, args.after)]
        there = " -> ".join(f"{e[continued].mean():.2f}" if continued.any() else "-" for e in errors)
        whole = " -> ".join(f"{e[mask].mean():.2f}" for e in errors)
        print(f"{obj.name:<12}{obj.storage:>8}{faint.sum() / mask.sum():>7.1%}"
              f"{continued.sum() / mask.sum():>10.1%}{there:>18}{whole:>18}", flush=True)


if __name__ == "__main__":
    main()

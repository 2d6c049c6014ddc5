"""How much f_sp's reflectance changes from image to image, in finished fits.

    python experiments/calibrated/reflectance_spread.py runs/ball-fast runs/ball-w384 runs/ball-w384-scaled

Each argument is one ``python -m unps.fit`` output folder of ``method=unps``. Its
``reflectance.npy`` holds f_sp's (n, h, w, 3) reflectance on the working grid; per pixel of the
object, the spread of its grey level over the n images (standard deviation over the mean) says
how far f_sp lets each image's reflectance depart from the pixel's own: 0 is one albedo for all
images, a Lambertian fit. Printed per folder: the median and mean of that spread over the
object's pixels, with the fit's normal error and slant bias from its ``metrics.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def reflectance_spread(reflectance: np.ndarray) -> np.ndarray:
    """(n, h, w, 3) reflectance → per object pixel, std / mean of its grey level over the n images.

    Pixels whose mean is 0 (off the object) are left out.

    >>> r = np.ones((4, 1, 2, 3)); r[:2, 0, 1] = 3.0          # pixel 1: 3, 3, 1, 1
    >>> reflectance_spread(r).round(3).tolist()
    [0.0, 0.5]
    """
    grey = np.asarray(reflectance, dtype=np.float64).mean(-1)
    mean = grey.mean(0)
    on_object = mean > 1e-6
    return grey.std(0)[on_object] / mean[on_object]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", type=Path, help="python -m unps.fit output folders")
    args = parser.parse_args(argv)
    print(f"{'run':<40} {'median spread':>14} {'mean spread':>12} {'MAE':>7} {'slant':>7}")
    for run in args.runs:
        file = run / "reflectance.npy"
        if not file.is_file():
            print(f"{run}: no reflectance.npy (a run of method=unps writes one)", file=sys.stderr)
            return 2
        spread = reflectance_spread(np.load(file))
        metrics = json.loads((run / "metrics.json").read_text()) if (run / "metrics.json").is_file() else {}
        mae, slant = metrics.get("normal_mae"), metrics.get("slant_bias")
        print(f"{str(run):<40} {np.median(spread):>14.3f} {spread.mean():>12.3f} "
              f"{'' if mae is None else f'{mae:.2f}°':>7} {'' if slant is None else f'{slant:+.2f}°':>7}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

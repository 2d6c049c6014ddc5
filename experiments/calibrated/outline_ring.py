"""Where the calibrated fit's error lies, by distance to the object's outline.

    python experiments/calibrated/outline_ring.py --runs <dir>
    python experiments/calibrated/outline_ring.py --runs <dir> --objects ball cat pot1 blob01 face

``<dir>/<object>-unps/normals.npy`` is a fit's output: ``python -m unps.fit subject=<object>
light=gt hydra.run.dir=<dir>/<object>-unps`` for DiLiGenT's ball, cat and pot1 (read from
``UNPS_DILIGENT_DIR``), ``experiments/light_benchmark/normals.py --methods unps --out <dir>`` for
the light benchmark's objects (96 lights). Printed per object and band of distance to the outline
(the object's pixels with a neighbour off it are at distance 1): the band's share of the object,
its mean angular error, its share of the object's summed error, and the median elevation (degrees
above the image plane) of the fitted and of the true normals there.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

from unps.data.diligent import read_diligent, read_diligent_object
from unps.geometry import outline_distance
from unps.metrics import angular_error

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "light_benchmark"))
import scenes  # noqa: E402

DILIGENT = ("ball", "cat", "pot1")
DEFAULT_DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
DEFAULT_CACHE = Path("~/.cache/unps/light_benchmark").expanduser()
BANDS = ((0, 1), (1, 2), (2, 4), (4, np.inf))


def elevation(normals: np.ndarray) -> np.ndarray:
    """(...,) degrees above the image plane of (..., 3) unit normals (90° facing the camera)."""
    return np.degrees(np.arcsin(np.clip(normals[..., 2], -1, 1)))


def truth(name: str, diligent_dir: Path | None, data: Path, cache: Path):
    """The subject ``name`` as its fit read it: a DiLiGenT object or a light benchmark object."""
    if name in DILIGENT:
        if diligent_dir is None:
            sys.exit(f"{name}: set UNPS_DILIGENT_DIR or --diligent to the DiLiGenT folder")
        return read_diligent_object(diligent_dir, name)
    known = {o.name: o for o in scenes.OBJECTS}
    if name not in known:
        sys.exit(f"{name}: neither {', '.join(DILIGENT)} nor a light benchmark object")
    obj = known[name]
    folder = scenes.make_captures(obj, data, cache)["96"]
    return read_diligent(folder, name=name, quantization=scenes.quantization(obj.storage))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=Path, required=True)
    parser.add_argument("--objects", nargs="+", default=list(DILIGENT))
    parser.add_argument("--diligent", type=Path, default=os.environ.get("UNPS_DILIGENT_DIR"))
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    args = parser.parse_args(argv)
    print("band (px to the outline): share of the object, mean error, share of its error, "
          "median elevation fitted / true")
    for name in args.objects:
        path = args.runs / f"{name}-unps" / "normals.npy"
        if not path.is_file():
            sys.exit(f"{path}: not found (fit {name} first; see this script's docstring)")
        subject = truth(name, args.diligent, args.data, args.cache)
        fitted, mask = np.load(path), subject.mask
        if fitted.shape[:2] != mask.shape:
            sys.exit(f"{path}: {fitted.shape[:2]} normals for a {mask.shape} subject")
        error = angular_error(fitted, subject.normals)
        distance = outline_distance(mask)
        line = f"{name:<10}{error[mask].mean():6.2f}°"
        for low, high in BANDS:
            band = mask & (distance > low) & (distance <= high)
            share = error[band].sum() / error[mask].sum()
            fitted_up = np.median(elevation(fitted[band]))
            true_up = np.median(elevation(subject.normals[band]))
            line += (f" | ({low},{high:g}] {band.sum() / mask.sum():5.1%} {error[band].mean():5.1f}° "
                     f"{share:5.1%} {fitted_up:4.1f}/{true_up:4.1f}")
        print(line, flush=True)


if __name__ == "__main__":
    main()

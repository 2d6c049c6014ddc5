"""Where reading an 8-bit 0 as light below the first level moves the normals: by each pixel's
share of images read as 0.

    python experiments/light_benchmark/zero_share.py --runs off=<cache>/normals/<tag> \
        on=<cache>/normals/<tag> --names blob09 tablet

Reads the unps rows that ``normals.py`` fitted (``<run>/<object>-unps/normals.npy``, 96 lights,
``light=gt``) and splits each object's pixels by the share of its images in which the pixel
reads 0 in every channel: a pixel grazed by some lights reads 0 in a few, one of a material
darker than the first level under most lights reads 0 in most (``preset.censor_black`` leaves
those as read, :data:`unps.inverse.grids.MOSTLY_ZERO`). Printed per object and band: the pixel
count, each run's mean angular error there, and the median RGB-mean albedo of the first run.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from unps.data.diligent import read_diligent
from unps.metrics import angular_error

sys.path.insert(0, str(Path(__file__).resolve().parent))
import scenes  # noqa: E402

DEFAULT_DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
DEFAULT_CACHE = Path("~/.cache/unps/light_benchmark").expanduser()
LIGHT_SET = "96"
BANDS = (0.0, 0.05, 0.25, 0.5, 0.75, 1.0)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", nargs="+", required=True,
                        help="normals.py run folders, each [label=]folder")
    parser.add_argument("--names", nargs="+", default=None, help="objects (default: all 24)")
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    args = parser.parse_args(argv)
    runs = dict(r.split("=", 1) if "=" in r else (Path(r).name, r) for r in args.runs)
    objects = [o for o in scenes.OBJECTS if args.names is None or o.name in args.names]
    unknown = sorted(set(args.names or ()) - {o.name for o in objects})
    if unknown:
        sys.exit(f"--names: {', '.join(unknown)} not among the objects")
    for obj in objects:
        missing = [folder for folder in runs.values()
                   if not (Path(folder) / f"{obj.name}-unps" / "normals.npy").is_file()]
        if missing:
            sys.exit(f"{', '.join(missing)}: no unps normals for {obj.name} (run normals.py first)")

    print(f"light benchmark, {LIGHT_SET} lights, light=gt: unps's normal MAE ° by the share of a pixel's "
          f"images read as 0")
    print(f"{'object':<12}{'zeros':>12}{'pixels':>8}" + "".join(f"{label:>10}" for label in runs)
          + f"{'albedo':>9}")
    for obj in objects:
        folder = scenes.make_captures(obj, args.data, args.cache)[LIGHT_SET]
        subject = read_diligent(folder, name=obj.name, quantization=scenes.quantization(obj.storage))
        mask = subject.mask
        zeros = (subject.observed_images() == 0).all(-1).mean(0)
        errors = {label: angular_error(np.load(Path(run) / f"{obj.name}-unps" / "normals.npy"),
                                       subject.normals) for label, run in runs.items()}
        albedo = np.load(Path(next(iter(runs.values()))) / f"{obj.name}-unps" / "albedo.npy").mean(-1)
        for low, high in zip(BANDS[:-1], BANDS[1:]):
            band = mask & (zeros >= low) & ((zeros < high) if high < 1 else (zeros <= high))
            if band.any():
                print(f"{obj.name:<12}{f'{low:.2f}-{high:.2f}':>12}{band.sum():>8}"
                      + "".join(f"{e[band].mean():>10.2f}" for e in errors.values())
                      + f"{np.median(albedo[band]):>9.3f}", flush=True)


if __name__ == "__main__":
    main()

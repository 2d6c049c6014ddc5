"""Masks found from the images (``subject.mask=auto``) against the true ones.

    python experiments/automask/benchmark.py                 # DiLiGenT ball, cat, pot1 and the renders
    python experiments/automask/benchmark.py --no-lights     # masks only (seconds)

Per subject: the intersection over union of the automatic mask with the true one, the pixels it
adds and misses, how many times more than the background the object changes with the light, and
(unless ``--no-lights``) the light network's estimate (``light=estimated``, without its stages) with
the automatic mask against the estimate with the true mask and against the true lights, and the
estimate with the whole image as the object (``subject.mask=none``, what a folder without a mask
gave before). DiLiGenT's ball is read at its full frame (612×512, most of it background), cat and
pot1 as the crops they are; unps's renders at 128×128.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

import numpy as np
from scipy import ndimage

from unps.data.automask import auto_mask
from unps.data.catalogue import subjects
from unps.data.diligent import read_diligent_object
from unps.errors import InputError
from unps.metrics import light_direction_mae
from unps.pipeline.lights import estimated_lights

DEFAULT_DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
DILIGENT = ("ball", "cat", "pot1")


def rendered(name: str):
    from hydra import compose, initialize_config_module
    from hydra.utils import instantiate

    with initialize_config_module("unps.conf", version_base=None):
        return instantiate(compose("fit", overrides=[f"subject={name}"]).subject, _partial_=True)()


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--subjects", nargs="*", default=[*DILIGENT, *subjects("synthetic")])
    parser.add_argument("--no-lights", action="store_true")
    args = parser.parse_args()
    logging.basicConfig(level=logging.ERROR)
    lights = None if args.no_lights else estimated_lights
    print(f"{'subject':<10} {'pixels':>7} {'IoU':>6} {'added':>6} {'missed':>6} {'contrast':>8}"
          + ("" if args.no_lights else f" {'lights: true mask':>17} {'auto mask':>9} {'between':>8}"
                                       f" {'eroded true mask':>16} {'whole image':>11}"))
    for name in args.subjects:
        try:
            subject = (read_diligent_object(args.data / "DiLiGenT", name) if name in DILIGENT
                       else rendered(name))
        except InputError as e:
            print(f"{name:<10} skipped: {e}")
            continue
        found = auto_mask(subject.observed_images())
        truth, mask = subject.mask, found.mask
        iou = (mask & truth).sum() / (mask | truth).sum()
        row = (f"{name:<10} {truth.sum():>7} {iou:>6.3f} {(mask & ~truth).sum():>6} "
               f"{(truth & ~mask).sum():>6} {found.contrast:>8.1f}")
        if lights is not None:
            with_true = lights(subject, stages=[])
            with_auto = lights(subject.replace(mask=mask), stages=[])
            with_eroded = lights(subject.replace(mask=ndimage.binary_erosion(truth)), stages=[])
            with_whole = lights(subject.replace(mask=np.ones_like(truth)), stages=[])
            error = lambda found: light_direction_mae(found.directions, subject.light_directions)  # noqa: E731
            row += (f" {error(with_true):>16.2f}° {error(with_auto):>8.2f}° "
                    f"{light_direction_mae(with_auto.directions, with_true.directions):>7.2f}° "
                    f"{light_direction_mae(with_eroded.directions, with_true.directions):>15.2f}° "
                    f"{error(with_whole):>10.2f}°")
        print(row, flush=True)


if __name__ == "__main__":
    main()

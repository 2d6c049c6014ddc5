"""The working grid's floor: the error a perfect fit on the block-averaged grid would still have.

    python experiments/calibrated/grid_floor.py [--factors 1 2 3 4] [--objects ball cat pot1] [--diligent DIR]

``preset=fast`` fits objects of more than ``max_pixels`` object pixels on a grid ``f`` times
coarser and brings the normals back with the robust initialisation's finer detail added
(:func:`unps.inverse.grids.upsample_with_detail`). Here the "fit" is the ground truth itself,
block-averaged to that grid: what remains against the full-resolution truth is what the working
grid costs however well the networks do. Printed per object and factor: the plain bilinear
upsampling, the upsampling with the initialisation's detail (what the fit does) and the robust
initialisation alone at full resolution, as mean angular errors in degrees.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

from unps.data.diligent import read_diligent_object
from unps.inverse.fit import CROP_MARGIN
from unps.inverse.grids import upsample_normals, upsample_with_detail, working_factor
from unps.metrics import angular_error
from unps.solvers.rpca import robust_init

DILIGENT = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "DiLiGenT"
FAST_MAX_PIXELS = 4000


def floor(subject, fine_init, factor: int) -> tuple[float, float]:
    """Mean error (°) of the block-averaged truth upsampled plainly and with the robust
    initialisation's detail, against the truth, for a subject already cropped to its mask;
    ``fine_init``: (H, W, 3) its robust initialisation at full resolution."""
    coarse = subject.downsample(factor)
    coarse_init = robust_init(coarse, subject.light_directions, device="cpu").normals
    shape = subject.mask.shape
    plain = upsample_normals(coarse.normals, coarse.mask, shape, factor)
    detailed = upsample_with_detail(coarse.normals, coarse_init, fine_init, coarse.mask, factor)

    def error(normals):
        return float(angular_error(normals, subject.normals)[subject.mask].mean())

    return error(plain), error(detailed)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--objects", nargs="+", default=["ball", "cat", "pot1"])
    parser.add_argument("--factors", nargs="+", type=int, default=[2, 3, 4])
    parser.add_argument("--diligent", type=Path, default=DILIGENT,
                        help="the folder holding pmsData/ or pmsData_crop/ (default: ../shared/data/DiLiGenT "
                             "beside the repository)")
    args = parser.parse_args(argv)
    if not args.diligent.is_dir():
        sys.exit(f"{args.diligent}: DiLiGenT not found (give --diligent, or put ../shared/data beside "
                 f"the repository)")
    torch.set_num_threads(min(2, torch.get_num_threads()))
    print(f"{'object':<7}{'fast ×':>7}{'RPCA full':>10} {'factor':>7}{'plain':>8}{'detail':>8}")
    for name in args.objects:
        subject = read_diligent_object(args.diligent, name).crop_to_mask(CROP_MARGIN)
        fast = working_factor(int(subject.mask.sum()), FAST_MAX_PIXELS)
        init = robust_init(subject, subject.light_directions, device="cpu").normals
        full = float(angular_error(init, subject.normals)[subject.mask].mean())
        for factor in args.factors:
            plain, detailed = floor(subject, init, factor)
            print(f"{name:<7}{fast:>7}{full:>9.2f}° {factor:>7}{plain:>7.2f}°{detailed:>7.2f}°")
    print("\nfast ×: the factor preset=fast uses; plain: the block-averaged truth upsampled bilinearly; "
          "detail: with the robust initialisation's finer detail added (the fit's read-out).")


if __name__ == "__main__":
    main()

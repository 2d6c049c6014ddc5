"""The robust initialisation's normals with values read as 0 as they read, and with headroom.

    python experiments/calibrated/init_headroom.py [OBJECT …]     # default: ball cat pot1

Prints, per DiLiGenT object and its true lights, the mean angular error and the slant bias of
the partial-sum RPCA's normals at full resolution, plain and with each 0 read as any light below
the stack's first level (``headroom``, :func:`unps.inverse.grids.black_headroom`).
"""

from __future__ import annotations

import argparse
import os

from unps.data.checks import zero_ceiling
from unps.data.diligent import read_diligent_object
from unps.inverse.grids import black_headroom
from unps.metrics import normal_metrics
from unps.solvers.rpca import robust_init


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("objects", nargs="*", default=["ball", "cat", "pot1"])
    parser.add_argument("--diligent", default=os.environ.get("UNPS_DILIGENT_DIR", "../shared/data/DiLiGenT"))
    args = parser.parse_args()
    for name in args.objects:
        subject = read_diligent_object(args.diligent, name)
        observed = subject.observed_images()
        ceiling = zero_ceiling(observed, subject.mask)
        headroom = (None if ceiling is None else
                    black_headroom(observed, subject.mask, 1, ceiling, subject.light_intensities))
        for label, given in (("as read", None), ("headroom", headroom)):
            normals = robust_init(subject, subject.light_directions, headroom=given).normals
            m = normal_metrics(normals, subject.normals, subject.mask)
            print(f"{name:<6} {label:<9} mean {m['normal_mae']:5.2f}°  slant bias {m['slant_bias']:+.2f}°")


if __name__ == "__main__":
    main()

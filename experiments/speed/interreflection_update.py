"""How long one interreflection update takes: the kernel between facets (orientation terms and
visibility) and the factorisation of (I − P K), as the fit rebuilds them every ``update_every``
steps (:meth:`unps.inverse.interreflection.Interreflection.update`).

    python experiments/speed/interreflection_update.py                    # ball, cat, pot1; x4 facets
    python experiments/speed/interreflection_update.py --downsample 2
    PYTHONPATH=<worktree of an older revision> python experiments/speed/interreflection_update.py

DiLiGenT's objects at the resolution of ``../shared/data`` (the paper preset's working grid), their
true normals, facets of ``--downsample`` × ``--downsample`` pixels, one torch thread, CPU. Prints
each object's facets, the update's seconds (best of ``--repeats``) and a checksum of the factors,
so that two versions can be compared for speed and for identical output.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import time
from pathlib import Path

import numpy as np
import torch

import unps
from unps.data.diligent import read_diligent_object
from unps.inverse.interreflection import Interreflection

DILIGENT = Path(os.environ.get("UNPS_DILIGENT_DIR",
                               Path(__file__).resolve().parents[3] / "shared" / "data" / "DiLiGenT"))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--objects", nargs="+", default=["ball", "cat", "pot1"])
    parser.add_argument("--downsample", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(f"unps from {Path(unps.__file__).parent}; facets of {args.downsample}×{args.downsample} pixels")
    for name in args.objects:
        subject = read_diligent_object(DILIGENT, name).crop_to_mask(1)
        interreflection = Interreflection(subject.mask, np.full(subject.mask.shape, 0.5),
                                          downsample=args.downsample)
        seconds = []
        for _ in range(args.repeats):
            start = time.perf_counter()
            interreflection.update(subject.normals.astype(np.float64))
            seconds.append(time.perf_counter() - start)
        checksum = hashlib.sha256(interreflection.lu.numpy().tobytes()).hexdigest()[:12]
        print(f"{name:<6} {interreflection.n_facets:>6} facets  update {min(seconds):6.2f} s  "
              f"factors {checksum}", flush=True)


if __name__ == "__main__":
    main()

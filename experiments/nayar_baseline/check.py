"""Does our Nayar baseline remove real interreflections? A diffuse pot fragment, rendered
with and without them.

    python experiments/nayar_baseline/check.py

The BrokenPot shape with a white diffuse BSDF (albedo 0.8), 40 lights within 30° of the view
axis (few cast shadows), 96×96, 36 spp, rendered with path length 2 (direct light only) and 5
(interreflections). Woodham is exact in the first case and biased in the second; Nayar's
removal should undo the bias in the second and, assuming interreflections that are not
there, over-correct in the first.
"""

from __future__ import annotations

import argparse
from unps.metrics import normal_metrics
from unps.solvers.nayar import nayar
from unps.solvers.woodham import woodham
from unps.synthetic import shapes
from unps.synthetic.render import light_dome, render_subject


def main():
    directions, intensities = light_dome(40, 30, (0.8, 1.2), 0.0, seed=0)
    mesh = shapes.broken_pot()
    print("path length   Woodham °   Nayar ×4 °   Nayar ×2 °   Nayar ×4, no occlusion °")
    for depth in (2, 5):
        s = render_subject("pot", mesh, {"type": "diffuse", "reflectance": [0.8] * 3}, None,
                           directions, intensities, resolution=96, spp=36, max_depth=depth,
                           progress=False)
        mae = lambda est: normal_metrics(est.normals, s.normals, s.mask)["normal_mae"]  # noqa: E731
        print(f"{depth:>11} {mae(woodham(s, directions)):>11.2f} {mae(nayar(s, directions)):>12.2f} "
              f"{mae(nayar(s, directions, downsample=2)):>12.2f} "
              f"{mae(nayar(s, directions, occlusion=False)):>26.2f}")


if __name__ == "__main__":
    argparse.ArgumentParser(description=__doc__,
                            formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    main()

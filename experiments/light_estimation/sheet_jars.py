"""Is the Vase's light error its shape? The network on the Vase's own shape and on jars of its outline.

    python experiments/light_estimation/sheet_jars.py [--checkpoint PATH] [--stacks 48]

Both parts shade with the training data's own renderer (:class:`unps.lightnet.synthesis.LightDataset`:
analytic and measured-span materials, texture and paint, the rig layouts, the simulated camera)
instead of Mitsuba, so neither the glaze nor the interreflections of the Vase's render are in them:

1. The Vase subject's ground-truth normals, depth and mask, framed as the network sees a capture.
   If the error stays, the shape is what the network has not learned.
2. Jars drawn as the ``jar`` family draws them (:func:`unps.lightnet.lathe.jar_view`), with the
   Vase's outline (:func:`unps.synthetic.vessels.vase_profile`) and height, tilted as the Vase is
   (its 50° toward the camera: 40° from looking into its mouth) or more or less: with a wall,
   whose lip shows as a ring, and as one sheet, whose mouth is a sharp edge as the Vase's mesh's.

Each row: the light direction MAE of the mean over the eight symmetries, averaged over
``--stacks`` stacks of 16 images (the same lights and materials in every row); first, the same on
the Vase's own render, for comparison.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from unps.lightnet import lathe
from unps.lightnet.estimate import network_estimate, network_input, network_pass
from unps.lightnet.materials import MaterialBank
from unps.lightnet.rig import Camera
from unps.lightnet.shapes import ShapeMaps
from unps.lightnet.symmetry import SYMMETRIES, mean_direction
from unps.lightnet.synthesis import LightDataset
from unps.lightnet.system import load_lightnet
from unps.metrics import light_direction_mae
from unps.synthetic.vessels import vase_profile

sys.path.insert(0, str(Path(__file__).resolve().parent))
from concave_failures import render  # noqa: E402

VASE_HEIGHT, VASE_TILT_DEG = 1.5, 50.0      # unps/conf/subject/Vase.yaml, unps.synthetic.vessels.vase


def subject_maps(subject, resolution: int) -> ShapeMaps:
    """A rendered subject's ground-truth maps, framed and resized as :func:`network_input` frames
    its images; depth in the view units of :mod:`unps.lightnet.shapes` (the view is 2 wide)."""
    mask = np.asarray(subject.mask)
    rows, cols = np.nonzero(mask)
    side = max(rows.max() - rows.min(), cols.max() - cols.min()) + 3     # network_input's square
    depth = np.where(mask, np.asarray(subject.depth), 0.0) * 2 / side     # NaN off the object
    normals, framed = network_input(np.asarray(subject.normals)[None], mask, resolution)
    depth, _ = network_input(np.repeat(depth[None, ..., None], 3, -1), mask, resolution)
    inside = framed[0, 0] > 0.5
    unit = F.normalize(normals[0, 0].permute(1, 2, 0), dim=-1) * inside[..., None]
    return ShapeMaps(unit, depth[0, 0, 0] * inside, inside)


def vase_jar(wall: float, tilt_deg: float, resolution: int) -> ShapeMaps:
    """A jar of the Vase's outline and height, its mouth toward the top of the image."""
    profile = vase_profile()

    def radius(h: torch.Tensor) -> torch.Tensor:
        return torch.as_tensor(profile(h.numpy()), dtype=torch.float32)

    return ShapeMaps(*lathe.jar_view(radius, VASE_HEIGHT, 0.0, wall, math.radians(tilt_deg),
                                     math.pi, 1.8, resolution))


@torch.no_grad()
def symmetric_error(net: torch.nn.Module, maps: ShapeMaps, stacks: int, resolution: int) -> float:
    """Mean direction MAE (degrees) of the eight-symmetry mean over ``stacks`` stacks of ``maps``."""
    data = LightDataset(stacks, resolution=resolution, images=16, meshes=[maps], mesh_fraction=1.0,
                        materials=MaterialBank(analytic=1.0, measured=1.0), paint=0.5,
                        layouts={"cap": 1.0, "dome": 1.0, "ring": 0.5}, camera=Camera(), seed=7)
    errors = []
    for sample in data:
        images, mask = sample["images"][None], sample["mask"][None]
        passes = torch.stack([network_pass(net, images, mask, turns, mirror)[0]
                              for turns, mirror in SYMMETRIES])
        errors.append(light_direction_mae(mean_direction(passes)[0].numpy(),
                                          sample["directions"].numpy()))
    return float(np.mean(errors))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--checkpoint", help="default: the weights shipped with unps")
    parser.add_argument("--stacks", type=int, default=48, help="stacks per row")
    args = parser.parse_args()
    torch.set_num_threads(2)
    net, config = load_lightnet(args.checkpoint)
    resolution = config["recipe"]["resolution"]
    tilt = 90 - VASE_TILT_DEG
    vase = render("Vase")
    on_render = network_estimate(vase, args.checkpoint, soft_decode=True, symmetric=True)
    print(f"weights: {args.checkpoint or 'shipped'}; the Vase as rendered (Mitsuba, "
          f"{len(vase.light_directions)} images): "
          f"{light_direction_mae(on_render.directions, vase.light_directions):.2f}°")
    rows = [("the Vase's own maps", subject_maps(vase, resolution))]
    rows += [(f"jar of its outline, wall 0.03, tilt {tilt:.0f}°", vase_jar(0.03, tilt, resolution)),
             (f"jar of its outline, wall 0.003, tilt {tilt:.0f}°", vase_jar(0.003, tilt, resolution))]
    rows += [(f"jar of its outline, one sheet, tilt {t:.0f}°", vase_jar(0.0, t, resolution))
             for t in (tilt - 15, tilt, tilt + 15)]
    print(f"the training data's renderer, {args.stacks} stacks of 16 images per row, {resolution} px:")
    print(f"{'shape':48s} {'8-sym dir MAE':>14s}")
    for name, maps in rows:
        print(f"{name:48s} {symmetric_error(net, maps, args.stacks, resolution):13.2f}°", flush=True)


if __name__ == "__main__":
    main()

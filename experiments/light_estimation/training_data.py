"""A picture of the light network's training data: each shape family, its normals and stacks.

    python experiments/light_estimation/training_data.py      # writes training_data.png beside this file

Rows: the shape families of ``unps.lightnet.shapes.SHAPES``. Columns: the normal maps of three
samples (RGB = (n + 1) / 2), then the first image of three stacks drawn as the default training
data draws them (every light layout, analytic materials, the simulated camera), each scaled to
its own maximum. Next to last row: three samples of two materials (``data.second_material``),
where the second lies (white) and the first image. Last row: three vessels and jars lit by their
own bounced light (``data.interreflection``): the share of the first image's light that came by
way of the object (0 black, 1 white), and that image.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from unps.lightnet.rig import LAYOUTS, Camera  # noqa: E402
from unps.lightnet.shapes import SHAPES, sample_generator  # noqa: E402
from unps.lightnet.interreflection import interreflected  # noqa: E402
from unps.lightnet.materials import shade  # noqa: E402
from unps.lightnet.synthesis import LightDataset, reflectance_map  # noqa: E402

SAMPLES = 3


def main() -> None:
    rows = len(SHAPES) + 2
    fig, axes = plt.subplots(rows, 2 * SAMPLES, figsize=(2 * SAMPLES * 1.6, rows * 1.7))
    for row, name in enumerate(SHAPES):
        stacks = LightDataset(SAMPLES, resolution=128, images=4, shape=name, seed=1,
                              layouts=dict.fromkeys(LAYOUTS, 1.0), camera=Camera())
        for k in range(SAMPLES):
            maps = SHAPES[name](128, sample_generator(0, k))
            axes[row, k].imshow(((maps.normals + 1) / 2 * maps.mask[..., None]).numpy())
            image = stacks[k]["images"][0].permute(1, 2, 0).numpy()
            axes[row, SAMPLES + k].imshow(np.clip(image / max(float(image.max()), 1e-6), 0, 1))
        axes[row, 0].set_ylabel(name)
    two = LightDataset(SAMPLES, resolution=128, images=4, seed=2, shapes=dict.fromkeys(SHAPES, 1.0),
                       layouts=dict.fromkeys(LAYOUTS, 1.0), camera=Camera(), second_material=1.0)
    for k in range(SAMPLES):
        scene = two.draw(k)
        axes[-2, k].imshow((0.3 * scene.maps.mask + 0.7 * scene.coat).numpy(), cmap="gray", vmin=0, vmax=1)
        image = two[k]["images"][0].permute(1, 2, 0).numpy()
        axes[-2, SAMPLES + k].imshow(np.clip(image / max(float(image.max()), 1e-6), 0, 1))
    axes[-2, 0].set_ylabel("two materials")
    bounced = LightDataset(SAMPLES, resolution=128, images=4, seed=3, shapes={"vessel": 1.0, "jar": 1.0},
                           layouts=dict.fromkeys(LAYOUTS, 1.0), camera=Camera(), interreflection=1.0)
    for k in range(SAMPLES):
        scene = bounced.draw(k)
        direct = shade(scene.maps, scene.brdf, scene.lights[:1], scene.intensities[:1], scene.albedo)
        maps = scene.maps
        lit = interreflected(direct, maps.normals, maps.depth, maps.mask, reflectance_map(scene))
        share = ((lit - direct) / lit.clamp_min(1e-12)).mean(1)[0] * maps.mask
        axes[-1, k].imshow(share.numpy(), cmap="gray", vmin=0, vmax=1)
        image = bounced[k]["images"][0].permute(1, 2, 0).numpy()
        axes[-1, SAMPLES + k].imshow(np.clip(image / max(float(image.max()), 1e-6), 0, 1))
    axes[-1, 0].set_ylabel("bounced light")
    axes[0, 1].set_title("normals")
    axes[0, SAMPLES + 1].set_title("through the simulated camera")
    for ax in axes.flat:
        ax.set_xticks([]), ax.set_yticks([])
    fig.tight_layout()
    out = Path(__file__).with_name("training_data.png")
    fig.savefig(out, dpi=80)
    print(f"wrote {out}")


if __name__ == "__main__":
    argparse.ArgumentParser(description=__doc__,
                            formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    main()

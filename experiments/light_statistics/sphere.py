"""Supplementary Fig. 6: estimated vs ground-truth light directions on the calibration sphere.

    python experiments/light_statistics/sphere.py [--checkpoint PATH] [--out sphere_lights.png]
        [Hydra overrides for the subject, e.g. paths.cache_dir=…]

Renders (or reads from the cache) the `Sphere` subject, estimates its lights with the light
network, prints the direction MAE and intensity error, and plots the x, y and z components of
the estimated and true direction of every image (ordered by azimuth, as the dome's lights are
not in any order of their own).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from hydra import compose, initialize_config_module  # noqa: E402
from hydra.utils import instantiate  # noqa: E402

from unps.fit import light_errors  # noqa: E402
from unps.io.files import atomic_path  # noqa: E402
from unps.lightnet.estimate import estimate_lights  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--checkpoint", help="default: the weights shipped with unps")
    parser.add_argument("--out", type=Path, default=Path(__file__).with_name("sphere_lights.png"))
    parser.add_argument("overrides", nargs="*")
    args = parser.parse_args()

    with initialize_config_module(config_module="unps.conf", version_base="1.3"):
        cfg = compose("fit", overrides=["subject=Sphere", "paths.output_dir=unused", *args.overrides])
    subject = instantiate(cfg.subject, _partial_=True)()
    lights = estimate_lights(subject, args.checkpoint)
    errors = light_errors(lights, subject)
    print(f"Sphere, {subject.n_images} images at {subject.resolution[0]} px: direction MAE "
          f"{errors['light_dir_mae']:.2f}°, intensity error {errors['light_int_err']:.3f} "
          f"(weights: {args.checkpoint or 'shipped'})")

    true, est = subject.light_directions, lights.directions
    order = np.argsort(np.arctan2(true[:, 1], true[:, 0]))
    fig, axes = plt.subplots(3, 1, figsize=(8, 6.5), sharex=True, dpi=120)
    for k, (ax, name) in enumerate(zip(axes, "xyz")):
        ax.plot(true[order, k], "-", color="tab:green", label="ground truth")
        ax.plot(est[order, k], ".-", color="tab:red", lw=0.8, ms=3, label="estimated")
        ax.set_ylabel(f"l_{name}")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[0].set_title(f"Calibration sphere: light directions per image (MAE "
                      f"{errors['light_dir_mae']:.2f}°)")
    axes[-1].set_xlabel("image (ordered by true azimuth)")
    fig.tight_layout()
    with atomic_path(args.out) as tmp:
        fig.savefig(tmp)
    print(f"figure: {args.out}")


if __name__ == "__main__":
    main()

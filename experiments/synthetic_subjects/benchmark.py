"""The synthetic subjects: render time, Monte Carlo noise, facet counts, classical baselines.

    python experiments/synthetic_subjects/benchmark.py [--downsample 4] [--sheet subjects.png]

For each subject, with the configs exactly as `unps.fit subject=<Name>` uses them (rendered
into the cache if missing):
- render time and resolution (from the cache entry);
- Monte Carlo noise: the first light rendered twice with independent sampler seeds; the
  standard deviation of one render, relative to the 99th percentile of the captured pixels (the
  reference of `noise=σ`), so it compares directly with σ = 0.05;
- facets: object pixels of the interreflection grid at the given downsampling factor (the
  analogue of the supplementary's Table 3);
- normal MAE of Woodham, the robust initialisation and the Nayar baseline (15 iterations,
  facets ×4) with the ground-truth lights.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from hydra import compose, initialize_config_module
from hydra.utils import instantiate
from omegaconf import OmegaConf

from unps.data.catalogue import subjects
from unps.data.diligent import read_diligent
from unps.data.prepare import prepare
from unps.io.images import write_png8
from unps.metrics import normal_metrics
from unps.io.pictures import image_strip
from unps.solvers.nayar import nayar
from unps.solvers.rpca import robust_init
from unps.solvers.woodham import woodham
from unps.synthetic.render import light_dome, render_subject
from unps.synthetic.scenes import cached_render

SUBJECTS = list(subjects("synthetic"))


def monte_carlo_noise(spec, reference: float) -> float:
    lights = dict(spec["lights"])
    directions, intensities = light_dome(**lights)
    twice = np.repeat(directions[:1], 2, 0), np.repeat(intensities[:1], 2, 0)
    s = render_subject("noise", instantiate(spec["shape"]), spec["material"], spec["texture"],
                       *twice, progress=False, **spec["render"])
    diff = (s.observed_images()[0] - s.observed_images()[1])[s.mask]
    return float(diff.std() / np.sqrt(2) / reference)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--downsample", type=int, default=4)
    parser.add_argument("--sheet", type=Path, help="write a contact sheet of all subjects here")
    parser.add_argument("overrides", nargs="*", help="Hydra overrides, e.g. paths.cache_dir=…")
    args = parser.parse_args()

    print(f"{'subject':<10} {'res':>4} {'imgs':>4} {'render s':>8} {'MC noise':>8} "
          f"{'pixels':>6} {'facets':>6} {'Woodham °':>9} {'RPCA °':>7} {'Nayar °':>7}")
    rows, strips = [], []
    for name in SUBJECTS:
        with initialize_config_module(config_module="unps.conf", version_base="1.3"):
            cfg = compose("fit", overrides=[f"subject={name}", "paths.output_dir=unused",
                                            *args.overrides])
        spec = OmegaConf.to_container(cfg.subject, resolve=True)
        entry = cached_render(name, spec["shape"], spec["material"], spec["texture"],
                              spec["lights"], spec["render"], spec["cache_dir"])
        meta = json.loads((entry / "unps_subject.json").read_text())
        subject = read_diligent(entry)
        reference = float(np.percentile(subject.observed_images()[:, subject.mask], 99))
        noise = monte_carlo_noise(spec, reference)
        facets = int(prepare(subject, downsample=args.downsample).mask.sum())
        errors = [normal_metrics(solve(subject, subject.light_directions).normals,
                                 subject.normals, subject.mask)["normal_mae"]
                  for solve in (woodham, robust_init, nayar)]
        res = subject.resolution[0]
        print(f"{name:<10} {res:>4} {subject.n_images:>4} {meta['render_seconds']:>8.1f} "
              f"{noise:>8.4f} {subject.mask.sum():>6} {facets:>6} {errors[0]:>9.2f} {errors[1]:>7.2f} "
              f"{errors[2]:>7.2f}",
              flush=True)
        rows.append((name, errors[0]))
        strips.append(image_strip(subject.observed_images(), subject.mask, subject.normals, count=3))
    if args.sheet:
        write_png8(args.sheet, np.concatenate(strips, axis=0))
        print(f"contact sheet: {args.sheet}")
    woodham_mae = dict(rows)
    harder = all(woodham_mae[k] > woodham_mae["Sphere"] for k in ("Vase", "BrokenPot", "Rose"))
    print(f"{'met ' if harder else 'MISSED'}  Woodham error larger on Vase, BrokenPot and Rose "
          f"than on Sphere")


if __name__ == "__main__":
    main()

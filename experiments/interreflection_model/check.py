"""Does the renderer's interreflection model ξ_n2 predict what a path tracer makes?

    python experiments/interreflection_model/check.py [--subjects Tablet1 BrokenPot Vase]

For each subject, with its lights, shape, texture and samples exactly as `unps.fit
subject=<Name>` uses them, four renders (from the cache, rendered on first use): its own material
and a Lambertian one of the same base colour, each with path length 5 (interreflections, what the
subject is) and 2 (direct light only). Then, per material:

- observed: Woodham's normals (Nayar's pseudo-normals) with and without interreflections: the
  mean angle between them and the mean change of slant (:func:`unps.metrics.slant_bias` of one
  against the other; negative = flatter), over the object;
- predicted: ξ_n2 (`unps.inverse.interreflection.Interreflection`, what method=unps renders
  with) applied to the ground-truth normals, with P from the robust initialisation of the
  interreflected render as in a fit, at facet grids ×4 (the default) and ×2: the same two figures,
  and the cosine between the predicted change N_ny − N and the observed one (1 = same direction
  and proportions at every pixel; Monte Carlo noise in the observed change lowers it);
- the robust initialisation's slant bias on the direct-light render: what the material alone does
  to a Lambertian reading, with no interreflection to blame.
"""

from __future__ import annotations

import argparse

import numpy as np
import torch
from hydra import compose, initialize_config_module
from omegaconf import OmegaConf

from unps.data.diligent import read_diligent
from unps.inverse.interreflection import Interreflection
from unps.metrics import angular_error, slant_bias
from unps.solvers.nayar import reflectance_scale
from unps.solvers.rpca import robust_init
from unps.solvers.woodham import woodham
from unps.synthetic.render import BASE_COLOUR
from unps.synthetic.scenes import cached_render

FACET_GRIDS = (4, 2)


def lambertian(material: dict) -> dict:
    """A diffuse BSDF with the material's base colour (the texture multiplies it the same way)."""
    return {"type": "diffuse", "reflectance": material[BASE_COLOUR[material["type"]]]}


def render(name: str, spec: dict, material: dict, max_depth: int):
    """The subject of config ``spec`` with another material and path length (cached)."""
    entry = cached_render(name, spec["shape"], material, spec["texture"], spec["lights"],
                          {**spec["render"], "max_depth": max_depth}, spec["cache_dir"])
    return read_diligent(entry)


def predicted_pseudo_normals(subject, downsample: int) -> np.ndarray:
    """ξ_n2's N_ny from the subject's ground-truth normals, (H, W, 3)."""
    init = robust_init(subject, subject.light_directions)
    albedo = init.albedo.mean(-1)
    albedo = albedo * reflectance_scale(albedo[subject.mask])
    solver = Interreflection(subject.mask, albedo, downsample)
    truth = subject.normals.astype(np.float64)
    solver.update(truth)
    return solver(torch.as_tensor(truth).permute(2, 0, 1)[None])[0].permute(1, 2, 0).numpy()


def compare(full, direct) -> dict:
    """The observed and predicted interreflection changes of one material (see the docstring)."""
    mask, truth = full.mask & direct.mask, full.normals
    with_ir = woodham(full, full.light_directions).normals
    without = woodham(direct, direct.light_directions).normals
    observed = with_ir - without
    row = {"observed_bend": angular_error(with_ir, without)[mask].mean(),
           "observed_dslant": slant_bias(with_ir, without, mask)}
    for factor in FACET_GRIDS:
        pseudo = predicted_pseudo_normals(full, factor)
        change = pseudo - truth
        cosine = (observed * change).sum(-1)[mask].sum() / np.sqrt(
            (observed ** 2).sum(-1)[mask].sum() * (change ** 2).sum(-1)[mask].sum())
        row[f"x{factor}"] = (angular_error(pseudo, truth)[mask].mean(), slant_bias(pseudo, truth, mask),
                             cosine)
    direct_init = robust_init(direct, direct.light_directions).normals
    row["material_slant_bias"] = slant_bias(direct_init, truth, mask)
    return row


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--subjects", nargs="+", default=["Tablet1", "BrokenPot", "Vase"])
    parser.add_argument("overrides", nargs="*", help="Hydra overrides, e.g. paths.cache_dir=…")
    args = parser.parse_args()

    grids = "".join(f"  ξ_n2 ×{f}: bend / Δslant / cos" for f in FACET_GRIDS)
    print(f"{'subject':<10} {'material':<13} observed: bend / Δslant{grids}  direct RPCA slant bias")
    for name in args.subjects:
        with initialize_config_module(config_module="unps.conf", version_base="1.3"):
            cfg = compose("fit", overrides=[f"subject={name}", "paths.output_dir=unused",
                                            *args.overrides])
        spec = OmegaConf.to_container(cfg.subject, resolve=True)
        for material in (spec["material"], lambertian(spec["material"])):
            row = compare(render(name, spec, material, 5), render(name, spec, material, 2))
            predicted = "".join(f"  {b:>11.2f}° / {d:+.2f}° / {c:.2f}  "
                                for b, d, c in (row[f"x{f}"] for f in FACET_GRIDS))
            print(f"{name:<10} {material['type']:<13} {row['observed_bend']:>7.2f}° / "
                  f"{row['observed_dslant']:+.2f}°   {predicted} {row['material_slant_bias']:+.2f}°",
                  flush=True)


if __name__ == "__main__":
    main()

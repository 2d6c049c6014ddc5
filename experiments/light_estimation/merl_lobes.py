"""Fit diffuse + two GGX lobes to each MERL material, and print the ranges the fits span.

    python experiments/light_estimation/merl_lobes.py [--data ../shared/data] [--iterations 400]

The light network's ``measured`` material family (:func:`unps.lightnet.brdf.random_measured`) draws
analytic materials inside these ranges, so that its training data spans measured reflectance
without shipping any measured data. Each of the 100 MERL neural fits (``<data>/merl_nbrdf``) is
sampled at 16,384 direction pairs (light and view cosine-distributed over the hemisphere), and
f = ρ_d/π + Σₖ ρₖ · D(α_k) G F(F0_k) / (4 cos θᵢ cos θₒ) is fitted to them by Adam on the
squared difference of log(1 + f cos θᵢ / m), m the material's median of f cos θᵢ: a
log-cosine-weighted error, as in BRDF fitting, which keeps highlights from swamping the diffuse
part, made independent of the material's brightness. Lobe 1 is the sharper one. The printed
percentiles (5 %, 50 %, 95 %) are what :data:`unps.lightnet.brdf.MEASURED_RANGES` holds, with
the ratios on a log scale: specular over diffuse albedo (luminance), lobe 2 over lobe 1.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np
import torch

from unps.lightnet.brdf import AnalyticBRDF, read_neural_brdf

DEFAULT_DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
LUMINANCE = torch.tensor([0.2126, 0.7152, 0.0722])


def direction_pairs(count: int, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """(count, 3) light and view directions, cosine-distributed over the upper hemisphere."""
    g = torch.Generator().manual_seed(seed)

    def cosine_hemisphere() -> torch.Tensor:
        u, v = torch.rand(count, generator=g), torch.rand(count, generator=g)
        r, phi = torch.sqrt(u), 2 * math.pi * v
        return torch.stack([r * torch.cos(phi), r * torch.sin(phi), torch.sqrt(1 - u).clamp_min(1e-3)], -1)

    return cosine_hemisphere(), cosine_hemisphere()


def fit_lobes(target: torch.Tensor, wi: torch.Tensor, wo: torch.Tensor, iterations: int) -> dict:
    """Diffuse + two GGX lobes fitted to ``target`` (P, 3) values of f at the pairs (wi, wo)."""
    raw = {"diffuse": torch.full((3,), -1.0), "specular": torch.tensor([[-1.0] * 3, [-2.0] * 3]),
           "alpha": torch.tensor([-2.5, -0.5]), "fresnel0": torch.tensor([-2.0, -2.0])}
    for value in raw.values():
        value.requires_grad_(True)
    optimiser = torch.optim.Adam(raw.values(), lr=0.05)
    cos_i = wi[:, 2:]
    scale = (target * cos_i).median()                               # errors relative to the material's level
    goal = torch.log1p(target * cos_i / scale)

    def parameters() -> dict:
        return {"diffuse": torch.exp(raw["diffuse"]), "specular": torch.exp(raw["specular"]),
                "alpha": 0.005 + torch.sigmoid(raw["alpha"]), "fresnel0": torch.sigmoid(raw["fresnel0"])}

    for _ in range(iterations):
        optimiser.zero_grad()
        p = parameters()
        f = AnalyticBRDF(p["diffuse"], p["specular"], p["alpha"], p["fresnel0"])(wi, wo)
        loss = (torch.log1p(f * cos_i / scale) - goal).square().mean()
        loss.backward()
        optimiser.step()
    with torch.no_grad():
        p = parameters()
        order = torch.argsort(p["alpha"])                           # lobe 1: the sharper
        return {"diffuse": p["diffuse"], "specular": p["specular"][order], "alpha": p["alpha"][order],
                "fresnel0": p["fresnel0"][order], "rms_log": float(loss.sqrt())}


def summary(fit: dict) -> dict:
    """The numbers :data:`unps.lightnet.brdf.MEASURED_RANGES` spans, from one fit."""
    diffuse, specular = float(fit["diffuse"] @ LUMINANCE), (fit["specular"] @ LUMINANCE).tolist()
    ratio = lambda a, b: math.log10((a + 1e-6) / (b + 1e-6))          # noqa: E731
    return {"alpha1": float(fit["alpha"][0]), "alpha2": float(fit["alpha"][1]),
            "fresnel0_1": float(fit["fresnel0"][0]), "fresnel0_2": float(fit["fresnel0"][1]),
            "log10_specular_over_diffuse": ratio(sum(specular), diffuse),
            "log10_lobe2_over_lobe1": ratio(specular[1], specular[0]), "rms_log": fit["rms_log"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--iterations", type=int, default=400)
    args = parser.parse_args()
    folder = args.data / "merl_nbrdf"
    files = sorted(folder.glob("*.h5"))
    if not files:
        raise SystemExit(f"{folder}: no MERL neural fits (*.h5); pass --data")
    wi, wo = direction_pairs(16384)
    rows = []
    start = time.perf_counter()
    for path in files:
        with torch.no_grad():
            target = read_neural_brdf(path)(wi, wo)
        row = summary(fit_lobes(target, wi, wo, args.iterations))
        rows.append(row)
        print(f"{path.stem:<28} α {row['alpha1']:.3f} / {row['alpha2']:.3f}   "
              f"F0 {row['fresnel0_1']:.2f} / {row['fresnel0_2']:.2f}   "
              f"log10 spec/diff {row['log10_specular_over_diffuse']:+.2f}   "
              f"log10 lobe2/lobe1 {row['log10_lobe2_over_lobe1']:+.2f}   rms {row['rms_log']:.3f}",
              flush=True)
    print(f"\n{len(rows)} materials fitted in {time.perf_counter() - start:.0f} s; percentiles 5 / 50 / 95:")
    for key in rows[0]:
        low, mid, high = np.percentile([row[key] for row in rows], [5, 50, 95])
        print(f"  {key:<30} {low:8.3f} {mid:8.3f} {high:8.3f}")


if __name__ == "__main__":
    main()

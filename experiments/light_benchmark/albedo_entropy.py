"""Does the albedo's entropy pin the bas-relief the network's lights leave? (Alldrin, Mallick &
Kriegman, "Resolving the generalized bas-relief ambiguity by entropy minimization", CVPR 2007.)

    python experiments/light_benchmark/albedo_entropy.py            # every case, ~4 min on 2 cores
    python experiments/light_benchmark/albedo_entropy.py --shear 0.15 --scale 0.15   # near the network's
    python experiments/light_benchmark/albedo_entropy.py --only diligent

Under distant lights a Lambertian object's images are X ≈ B·Sᵀ (pixels × images); lights S·P⁻¹
with scaled normals B·Pᵀ explain them as well for any generalised bas-relief P (μ, ν, λ). An
object painted in a few materials has a few albedos, and a wrong P smears them with the normals,
so the P whose albedos |b_p| have the least entropy should be the true one. Per case: the light
network's lights (no stage after it), the robust low-rank part Z of the gray images
(:func:`unps.solvers.rpca.partial_sum_rpca`), B = Z·S(SᵀS)⁻¹ for the network's and for the true
lights, and the P of a grid over μ, ν ∈ [−shear, shear] (25 steps) and λ ∈ [e^−scale,
e^scale] (15 steps; by default 0.6 and 0.7) whose albedos have the least entropy (a histogram
of log albedo over the lit pixels, Parzen-smoothed). It prints the direction error of the
network's lights and of the same lights under that P, and the entropy under the true, the
network's and the chosen lights. None of it feeds training.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import numpy as np

from unps.metrics import angular_error
from unps.solvers.rpca import partial_sum_rpca

sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchmark import asked_cases, case_parser, light_source  # noqa: E402

BIN_EDGES = np.linspace(-3.0, 3.0, 601)      # log albedo, relative to the median
PARZEN_SIGMA = 0.05
LIT_SHARE = 0.05                              # pixels darker than this share of the bright ones are left out


def bas_relief(mu: float, nu: float, lam: float) -> np.ndarray:
    """(3, 3) P of the surface z' = λz + μx + νy on scaled normals (b' = P·b); lights go by P⁻ᵀ."""
    return np.array([[lam, 0.0, -mu], [0.0, lam, -nu], [0.0, 0.0, 1.0]])


def scaled_normals(low_rank: np.ndarray, scaled_lights: np.ndarray) -> np.ndarray:
    """(m, 3) B with low_rank ≈ B·Sᵀ, for (m, n) low_rank and (n, 3) S (least squares)."""
    return np.linalg.lstsq(scaled_lights, low_rank.T, rcond=None)[0].T


def albedo_entropy(scaled: np.ndarray) -> float:
    """Entropy (nats) of the log albedo log|b_p| of (m, 3) scaled normals, about its median."""
    values = np.log(np.maximum(np.linalg.norm(scaled, axis=1), 1e-9))
    counts, _ = np.histogram(np.clip(values - np.median(values), -2.99, 2.99), BIN_EDGES)
    offsets = np.arange(-30, 31) * (BIN_EDGES[1] - BIN_EDGES[0])
    kernel = np.exp(-0.5 * (offsets / PARZEN_SIGMA) ** 2)
    p = np.convolve(counts.astype(np.float64), kernel / kernel.sum(), "same")
    p = p[p > 0] / p.sum()
    return float(-(p * np.log(p)).sum())


def least_entropy(scaled: np.ndarray, shear: float, scale: float) -> tuple[float, np.ndarray]:
    """The least albedo entropy over a grid of bas-reliefs (|μ|, |ν| ≤ ``shear``, |log λ| ≤
    ``scale``) applied to ``scaled``, and its P."""
    best = (albedo_entropy(scaled), np.eye(3))
    for lam in np.exp(np.linspace(-scale, scale, 15)):
        for mu in np.linspace(-shear, shear, 25):
            for nu in np.linspace(-shear, shear, 25):
                p = bas_relief(mu, nu, lam)
                entropy = albedo_entropy(scaled @ p.T)
                if entropy < best[0]:
                    best = (entropy, p)
    return best


def main() -> None:
    parser = case_parser(__doc__.split("\n")[0])
    parser.add_argument("--shear", type=float, default=0.6, help="the grid's largest |μ|, |ν|")
    parser.add_argument("--scale", type=float, default=0.7, help="the grid's largest |log λ|")
    args = parser.parse_args()
    logging.basicConfig(level=logging.ERROR)
    network, _ = light_source([], [])
    print(f"{'case':<28} {'network':>8} {'least H':>8}   entropy: {'true':>6} {'network':>7} {'least':>6}")
    rows = []
    for group, name, label, read in asked_cases(args):
        subject = read()
        lights = network(subject)
        gray = subject.observed_images()[:, subject.mask].mean(-1)                     # (n, m)
        lit = gray.max(0) > LIT_SHARE * np.percentile(gray.max(0), 90)
        low_rank = partial_sum_rpca(gray.T, 3).low_rank[lit]
        net = lights.directions * lights.intensities.mean(1)[:, None]
        true = subject.light_directions * (subject.light_intensities.mean(1)[:, None]
                                           if subject.light_intensities is not None else 1.0)
        b = scaled_normals(low_rank, net)
        entropy, p = least_entropy(b, args.shear, args.scale)
        chosen = net @ np.linalg.inv(p)
        errors = [float(angular_error(d, subject.light_directions).mean()) for d in (net, chosen)]
        rows.append((group, *errors))
        print(f"{f'{group}-{name}-{label}':<28} {errors[0]:7.2f}° {errors[1]:7.2f}°   "
              f"{albedo_entropy(scaled_normals(low_rank, true)):14.3f} {albedo_entropy(b):7.3f} "
              f"{entropy:6.3f}", flush=True)
    for group in args.only:
        errors = np.array([r[1:] for r in rows if r[0] == group])
        if len(errors):
            print(f"{group}: {len(errors)} cases, network {errors[:, 0].mean():.2f}°, least entropy "
                  f"{errors[:, 1].mean():.2f}°; better on {int((errors[:, 1] < errors[:, 0]).sum())}, "
                  f"worse by more than 1° on {int((errors[:, 1] > errors[:, 0] + 1).sum())}")


if __name__ == "__main__":
    main()

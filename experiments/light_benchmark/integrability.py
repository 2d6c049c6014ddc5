"""Would the images' integrability give the lights' shared frame? (Yuille & Snow, "Shape and albedo
from multiple images using integrability", CVPR 1997.)

    python experiments/light_benchmark/integrability.py             # benchmark and DiLiGenT, ~4 min
    python experiments/light_benchmark/integrability.py --only diligent --sets 96
    python experiments/light_benchmark/integrability.py --report   # the tables from what has run

Under distant lights a Lambertian object's images are X ≈ B·Sᵀ (pixels × images): the rank-3 part
of X gives the scaled normals B̂ and lights Ŝ up to one 3×3 transform Q (B = B̂·Q, S = Ŝ·Q⁻ᵀ).
Requiring the normals to come from a depth map fixes Q up to the generalised bas-relief (μ, ν, λ);
the bas-relief could then be taken from the light network. Per case (the network's lights, no
stage after it; the robust low-rank part of the gray images, :func:`unps.solvers.rpca.partial_sum_rpca`):

- **orbit**: the bas-relief of the *true* lights that comes nearest the network's, and its error
  from the truth — what the lights would be if the images pinned everything but the bas-relief
  exactly and the network chose the bas-relief (a bound on what integrability could give);
- **rank 3**: Ŝ under the 3×3 transform that brings it nearest the true lights — how well the
  images' low-rank part holds each light's place;
- **frame**: |cos| between the integrability constraint's solution and the one the true lights
  give (1: found exactly), and the lights it gives, under the bas-relief nearest the network's.

The constraint: with b = ê·Q, ê a row of B̂, ∂(b₁/b₃)/∂y = ∂(b₂/b₃)/∂x reads
(ê × ê_y)·(q₃ × q₁) = (ê × ê_x)·(q₃ × q₂), linear in the six numbers c = (q₃ × q₁, q₃ × q₂): the
least-squares null vector of one row per pixel (B̂ smoothed over :data:`SMOOTH_PIXELS` pixels first,
then iteratively reweighted toward an L1 fit), from which Q follows up to the bas-relief.
Results are kept case by case in ``--out`` (default ``<cache>/integrability``); a rerun resumes.
None of it feeds training.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy import ndimage
from scipy.optimize import least_squares

from unps.metrics import angular_error
from unps.solvers.rpca import partial_sum_rpca

sys.path.insert(0, str(Path(__file__).resolve().parent))
import benchmark  # noqa: E402
import runs  # noqa: E402
import scenes  # noqa: E402

SMOOTH_PIXELS = 1.0     # Gaussian σ on B̂ before its differences (0, 1, 2 measured: README)
REWEIGHTINGS = 5        # of the constraint's rows, toward an L1 fit
FOUND = 0.99            # |cos| above which the frame counts as found


def unit(v: np.ndarray) -> np.ndarray:
    """``v`` (…, 3) scaled to unit length along its last axis."""
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def rank3(gray: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(m, 3) B̂ and (n, 3) Ŝ with B̂·Ŝᵀ the robust rank-3 part of the (m, n) gray image matrix."""
    low_rank = partial_sum_rpca(gray / np.percentile(gray, 99), 3).low_rank
    u, s, vt = np.linalg.svd(low_rank, full_matrices=False)
    return u[:, :3] * np.sqrt(s[:3]), vt[:3].T * np.sqrt(s[:3])


def constraint_rows(scaled: np.ndarray, mask: np.ndarray, sigma: float = SMOOTH_PIXELS) -> np.ndarray:
    """(k, 6) rows [ê × ê_y, −(ê × ê_x)] of the integrability constraint, one per pixel of ``mask``
    (H, W) whose four neighbours are on it (after an erosion by 2σ), from the (H, W, 3) ``scaled``
    normals B̂ on the image grid (zero off the mask); central differences, x right (+col), y up
    (−row)."""
    if sigma > 0:
        weight = ndimage.gaussian_filter(mask.astype(np.float64), sigma)
        scaled = np.stack([ndimage.gaussian_filter(scaled[..., k], sigma) for k in range(3)], -1)
        scaled = scaled / np.maximum(weight, 1e-6)[..., None]
        mask = ndimage.binary_erosion(mask, iterations=int(round(2 * sigma)))
    inside = mask[1:-1, 1:-1] & mask[1:-1, 2:] & mask[1:-1, :-2] & mask[2:, 1:-1] & mask[:-2, 1:-1]
    e = scaled[1:-1, 1:-1][inside]
    e_x = (scaled[1:-1, 2:] - scaled[1:-1, :-2])[inside] / 2
    e_y = (scaled[:-2, 1:-1] - scaled[2:, 1:-1])[inside] / 2
    return np.hstack([np.cross(e, e_y), -np.cross(e, e_x)])


def null_vector(rows: np.ndarray, reweightings: int = REWEIGHTINGS) -> np.ndarray:
    """(6,) unit c minimising Σ w_k |rows_k·c| by iteratively reweighted least squares."""
    weight = np.ones(len(rows))
    for _ in range(reweightings + 1):
        c = np.linalg.svd(rows * weight[:, None], full_matrices=False)[2][-1]
        residual = np.abs(rows @ c)
        weight = 1.0 / np.sqrt(np.maximum(residual, 0.1 * np.median(residual)))
    return c


def frame_from(c: np.ndarray) -> np.ndarray:
    """(3, 3) Q = [q₁ q₂ q₃] with (q₃ × q₁, q₃ × q₂) ∝ c: one member of its bas-relief family."""
    q3 = np.cross(c[:3], c[3:])
    return np.stack([np.cross(c[:3], q3), np.cross(c[3:], q3), q3 * (q3 @ q3)], 1) / (q3 @ q3)


def constraint_of(frame: np.ndarray) -> np.ndarray:
    """(6,) unit c of the (3, 3) ``frame`` Q (the inverse of :func:`frame_from`, up to scale)."""
    q1, q2, q3 = frame.T
    c = np.concatenate([np.cross(q3, q1), np.cross(q3, q2)])
    return c / np.linalg.norm(c)


def nearest_bas_relief(lights: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(n, 3) unit directions: the bas-relief s ↦ ±(s_x, s_y, μ s_x + ν s_y + λ s_z) of the (n, 3)
    ``lights`` nearest the (n, 3) unit ``target`` (least squares; λ of either sign, so a reading
    inside out is reachable)."""
    def moved(p: np.ndarray, sign: float) -> np.ndarray:
        return unit(sign * lights @ np.array([[1.0, 0.0, p[0]], [0.0, 1.0, p[1]], [0.0, 0.0, p[2]]]))
    fits = [(least_squares(lambda p, s=sign: (moved(p, s) - target).ravel(), [0.0, 0.0, lam]), sign)
            for sign in (1.0, -1.0) for lam in (1.0, -1.0)]
    fit, sign = min(fits, key=lambda f: f[0].cost)
    return moved(fit.x, sign)


def run_case(subject, network) -> dict:
    """The case's figures (module docstring): the mean direction errors of the network's lights,
    of the orbit's and the frame's, and of the rank-3 lights; the frame's |cos|."""
    lights = network(subject)
    truth = subject.light_directions.astype(np.float64)
    true_scaled = truth * (subject.light_intensities.mean(1)[:, None]
                           if subject.light_intensities is not None else 1.0)
    scaled, images_lights = rank3(subject.observed_images()[:, subject.mask].mean(-1).T.astype(np.float64))
    true_frame = np.linalg.inv(np.linalg.lstsq(images_lights, true_scaled, rcond=None)[0]).T
    grid = np.zeros(subject.mask.shape + (3,))
    grid[subject.mask] = scaled
    c = null_vector(constraint_rows(grid, subject.mask))
    integrable = images_lights @ np.linalg.inv(frame_from(c)).T
    network_dirs = lights.directions.astype(np.float64)
    return {"network": float(angular_error(network_dirs, truth).mean()),
            "orbit": float(angular_error(nearest_bas_relief(truth, network_dirs), truth).mean()),
            "rank3": float(angular_error(unit(images_lights @ np.linalg.inv(true_frame).T), truth).mean()),
            "found": float(abs(c @ constraint_of(true_frame))),
            "frame": float(angular_error(nearest_bas_relief(integrable, network_dirs), truth).mean())}


def report(rows: dict) -> str:
    """Per case, then per group and light set: the figures of :func:`run_case`."""
    lines = [f"{'group':<9} {'case':<11} {'set':>3} {'network':>8} {'orbit':>7} {'rank 3':>7} "
             f"{'|cos|':>6} {'frame':>7}"]
    for (group, name, label), r in rows.items():
        lines.append(f"{group:<9} {name:<11} {label:>3} {r['network']:>7.2f}° {r['orbit']:>6.2f}° "
                     f"{r['rank3']:>6.2f}° {r['found']:>6.3f} {r['frame']:>6.2f}°")
    lines.append(f"\n{'group':<9} {'set':>4} {'cases':>5} {'network':>8} {'orbit':>7} {'rank 3':>7} "
                 f"{'frame':>7}   frame found (|cos| > {FOUND}): cases, their network → frame")
    for group, label, chosen in runs.by_light_set(rows):
        means = [np.mean([r[k] for r in chosen]) for k in ("network", "orbit", "rank3", "frame")]
        found = [r for r in chosen if r["found"] > FOUND]
        tail = (f"{len(found)}, {np.mean([r['network'] for r in found]):.2f}° → "
                f"{np.mean([r['frame'] for r in found]):.2f}°" if found else "0")
        lines.append(f"{group:<9} {label:>4} {len(chosen):>5} " + " ".join(f"{m:>6.2f}°" for m in means)
                     + f"   {tail}")
    return "\n".join(lines)


def progress(case: tuple, row: dict, result: dict) -> str:
    """The line printed when a case has run."""
    return (f"{' '.join(case)}: network {row['network']:.2f}° orbit {row['orbit']:.2f}° "
            f"frame {row['frame']:.2f}° (|cos| {row['found']:.3f})")


def main() -> None:
    parser = benchmark.study_parser(__doc__.split("\n")[0], "default: <cache>/integrability",
                                    groups=("benchmark", "diligent"))
    args = parser.parse_args()
    out = args.out or args.cache / "integrability"
    made_with = {"scenes": scenes.SCENE_VERSION, "smooth": SMOOTH_PIXELS, "reweightings": REWEIGHTINGS}
    benchmark.network_study(parser, args, out, made_with, run_case, report, progress)


if __name__ == "__main__":
    main()

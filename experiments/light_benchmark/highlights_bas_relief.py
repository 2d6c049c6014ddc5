"""Do the images' specular highlights pin the bas-relief the network's lights leave? (Drbohlav &
Šára, "Specularities reduce ambiguity of uncalibrated photometric stereo", ECCV 2002.)

    python experiments/light_benchmark/highlights_bas_relief.py                  # 96-light cases, ~6 min
    python experiments/light_benchmark/highlights_bas_relief.py --only diligent

Under distant lights the diffuse part of an object's images is X ≈ B·Sᵀ, and lights S·P⁻¹ with
scaled normals B·Pᵀ explain it as well for any generalised bas-relief P (μ, ν, λ). A highlight
does not: it peaks where the normal bisects the light and the view, and under a wrong P the
half vector of the peak's light and the pixel's diffuse normal part. Given a pixel's diffuse
normal, each highlight ties one normal to one half vector, and together they pin P.

Per case: the light network's lights (no stage after it); the highlight pixels as the fit reads
them (:func:`unps.inverse.highlights.highlight_normals`: a peaked brightest image whose lit images
do not follow Lambert's cosine, under a dense set of lights, so only the 96-light sets have
them); each one's diffuse normal by least squares on its lit images whose light stands more
than ``--away`` from the peak's, where there are at least ``--min-images`` of them and they
follow the cosine (relative residual under ``--max-misfit``). The P that brings the turned
diffuse normals nearest the half vectors of their turned peak lights (mean angle, each capped at
15°, Nelder–Mead from P = I) turns the network's lights. It prints the direction error of the
network's lights and of the turned ones, the highlight pixels used, and the premise under the
true lights: the median angle between those pixels' diffuse normals and their half vectors, and
of each from the true normals where the subject has them (where the cue holds, all three are
small). None of it feeds a stage.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

from unps.inverse.fit import unit
from unps.inverse.highlights import LIT_SHARE, VIEW, highlight_normals
from unps.metrics import angular_error

sys.path.insert(0, str(Path(__file__).resolve().parent))
from albedo_entropy import bas_relief  # noqa: E402
from benchmark import asked_cases, case_parser, light_source  # noqa: E402

CAP_DEG = 15.0          # an angle between a diffuse normal and its half vector counts at most this


def diffuse_normals(shading: np.ndarray, lights: np.ndarray, peaks: np.ndarray, away_deg: float,
                    min_images: int, max_misfit: float) -> tuple[np.ndarray, np.ndarray]:
    """Each pixel's scaled normal from its diffuse images, and which pixels have one.

    Args:
        shading: (n, k) the pixels' brightness in each image, divided by the light intensities.
        lights: (n, 3) unit surface-to-light directions.
        peaks: (k,) each pixel's brightest image.
        away_deg, min_images, max_misfit: a pixel's diffuse images are its lit ones (above
            ``LIT_SHARE`` of its brightest) whose light stands more than ``away_deg`` from its
            peak's; it has a diffuse normal where there are ``min_images`` of them or more and the
            least-squares cosine fits them to a relative RMS residual under ``max_misfit``.

    Returns:
        (k, 3) scaled normals b (b·l ≈ shading; zero where there is none) and (k,) bool.
    """
    far = (lights[peaks] @ lights.T) < np.cos(np.radians(away_deg))              # (k, n)
    used = ((shading > LIT_SHARE * shading.max(0)).T & far).astype(np.float64)
    gram = np.einsum("kn,ni,nj->kij", used, lights, lights)
    count = used.sum(1)
    solvable = count >= max(min_images, 3)
    gram[~solvable] = np.eye(3)
    scaled = np.linalg.solve(gram, np.einsum("kn,nk,ni->ki", used, shading, lights)[..., None])[..., 0]
    residual = ((scaled @ lights.T - shading.T) * used) ** 2
    misfit = np.sqrt(residual.sum(1) / np.maximum(((shading.T * used) ** 2).sum(1), 1e-30))
    found = solvable & (misfit < max_misfit)
    return np.where(found[:, None], scaled, 0.0), found


def highlight_misfit(p: np.ndarray, normals: np.ndarray, lights: np.ndarray) -> float:
    """Mean angle (degrees, each capped at CAP_DEG) between (k, 3) scaled diffuse ``normals``
    turned by P (b' = P·b) and the half vectors of their (k, 3) peak ``lights`` turned by P⁻ᵀ."""
    half = unit(unit(lights @ np.linalg.inv(p)) + VIEW)
    return float(np.minimum(angular_error(normals @ p.T, half), CAP_DEG).mean())


def pinned_bas_relief(normals: np.ndarray, lights: np.ndarray) -> np.ndarray:
    """The (3, 3) bas-relief P bringing the diffuse ``normals`` nearest the half vectors of their
    peak ``lights`` (both (k, 3)), from P = I."""
    cost = lambda x: highlight_misfit(bas_relief(x[0], x[1], np.exp(x[2])), normals, lights)  # noqa: E731
    x = minimize(cost, np.zeros(3), method="Nelder-Mead", options={"xatol": 1e-4, "fatol": 1e-4}).x
    return bas_relief(x[0], x[1], np.exp(x[2]))


def highlight_cues(gray: np.ndarray, directions: np.ndarray, intensities: np.ndarray, away_deg: float,
                   min_images: int, max_misfit: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """For (n, m) ``gray`` images under lights of (n, 3) ``directions`` and (n,) ``intensities``:
    the (k,) highlight pixels that have a diffuse normal (:func:`diffuse_normals`, with
    ``away_deg``, ``min_images`` and ``max_misfit``), their (k, 3) scaled diffuse normals, (k, 3)
    half vectors and (k,) peak images."""
    shading = gray / intensities[:, None]
    halves, peaked = highlight_normals(shading, directions)
    pixels = np.flatnonzero(peaked)
    peaks = shading[:, pixels].argmax(0)
    normals, found = diffuse_normals(shading[:, pixels], directions, peaks, away_deg, min_images,
                                     max_misfit)
    return pixels[found], normals[found], halves[pixels[found]], peaks[found]


def main() -> None:
    parser = case_parser(__doc__.split("\n")[0])
    parser.set_defaults(sets=["96"])
    parser.add_argument("--away", type=float, default=25.0,
                        help="degrees: a pixel's diffuse images are lit by lights this far from its peak's")
    parser.add_argument("--min-images", type=int, default=8,
                        help="diffuse images a pixel needs for its normal")
    parser.add_argument("--max-misfit", type=float, default=0.15,
                        help="largest relative residual of the cosine fit to a pixel's diffuse images")
    parser.add_argument("--min-pixels", type=int, default=20,
                        help="highlight pixels with a diffuse normal a case needs to be turned")
    args = parser.parse_args()
    logging.basicConfig(level=logging.ERROR)
    network, _ = light_source([], [])
    print(f"{'case':<28} {'network':>8} {'turned':>8} {'pixels':>7}   under the true lights: "
          f"{'pixels':>6} {'diffuse-half':>12} {'half-true':>9} {'diffuse-true':>12}")
    diffuse = (args.away, args.min_images, args.max_misfit)
    rows = []
    for group, name, label, read in asked_cases(args):
        subject = read()
        lights = network(subject)
        gray = subject.observed_images()[:, subject.mask].mean(-1)                      # (n, m)
        truth = subject.light_directions
        true_intensities = (subject.light_intensities.mean(1) if subject.light_intensities is not None
                            else np.ones(len(truth)))
        true_pixels, true_diffuse, true_halves, _ = highlight_cues(gray, truth, true_intensities, *diffuse)
        premise = [np.nan] * 3
        if len(true_pixels):
            premise[0] = float(np.median(angular_error(true_diffuse, true_halves)))
            if subject.normals is not None:
                true_normals = subject.normals[subject.mask][true_pixels]
                premise[1] = float(np.median(angular_error(true_halves, true_normals)))
                premise[2] = float(np.median(angular_error(true_diffuse, true_normals)))
        pixels, normals, _, peaks = highlight_cues(gray, lights.directions, lights.intensities.mean(1),
                                                   *diffuse)
        before = float(angular_error(lights.directions, truth).mean())
        after = before
        if len(pixels) >= args.min_pixels:
            p = pinned_bas_relief(normals, lights.directions[peaks])
            after = float(angular_error(lights.directions @ np.linalg.inv(p), truth).mean())
        rows.append((group, label, before, after, len(pixels) >= args.min_pixels))
        print(f"{f'{group}-{name}-{label}':<28} {before:7.2f}° {after:7.2f}° {len(pixels):7d}   "
              f"{len(true_pixels):29d} {premise[0]:11.2f}° {premise[1]:8.2f}° {premise[2]:11.2f}°",
              flush=True)
    for group, label in dict.fromkeys((r[0], r[1]) for r in rows):
        chosen = np.array([r[2:] for r in rows if r[:2] == (group, label)], dtype=np.float64)
        turned = chosen[chosen[:, 2] > 0]
        print(f"{group} {label}: {len(chosen)} cases, network {chosen[:, 0].mean():.2f}°, turned by the "
              f"highlights {chosen[:, 1].mean():.2f}°; {len(turned)} turned, better on "
              f"{int((turned[:, 1] < turned[:, 0]).sum())}, worse by more than 1° on "
              f"{int((turned[:, 1] > turned[:, 0] + 1).sum())}")


if __name__ == "__main__":
    main()

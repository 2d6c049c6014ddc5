"""Do the images' diffuse maxima pin the bas-relief the network's lights leave? (Papadhimitri &
Favaro, "A closed-form, consistent and robust solution to uncalibrated photometric stereo via
local diffuse reflectance maxima", IJCV 2014.)

    python experiments/light_benchmark/diffuse_maxima.py            # every case, ~10 min on one core
    python experiments/light_benchmark/diffuse_maxima.py --plane    # the isotropic form (below)
    python experiments/light_benchmark/diffuse_maxima.py --only diligent --sets 96

Under distant lights a Lambertian object's images are X ≈ B·Sᵀ (pixels × images), and lights
S·P⁻¹ with scaled normals B·Pᵀ explain them as well for any generalised bas-relief P (μ, ν, λ).
Where the albedo is the same around a pixel, image i is brightest where the normal points at
light i; that place is the images' own, whatever P, so each such maximum ties one normal to one
light and together they pin P. A glossy material's maximum lies between the light and the view
instead, but for any isotropic material still in the plane of the two: ``--plane`` asks only
that, which pins μ and ν and leaves λ (kept at 1).

Per case: the light network's lights (no stage after it); each pixel's scaled normal by least
squares on its images between the 30th and 90th percentile of its values (``--keep``: shadows
and highlights left out); the images and the normals smoothed (Gaussian, 2 px); in every image
the pixels brightest in their 7 × 7 window of the object, where the albedos (the scaled normals'
lengths) spread less than ``--albedo-spread``, above ``--bright`` of the image's 99th
percentile. The P that brings the maxima's normals nearest their lights (or their planes; mean
angle, each capped at 15°, Nelder–Mead from P = I) turns the network's lights. It prints the
direction error of the network's lights and of the turned ones, the maxima found, and the mean
angle between maxima and lights under the network's, the turned and the true lights (where the
images hold the cue, the true lights' is near 0 and the least). None of it feeds a stage.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter, maximum_filter, uniform_filter
from scipy.optimize import minimize

from unps.metrics import angular_error

sys.path.insert(0, str(Path(__file__).resolve().parent))
from albedo_entropy import bas_relief  # noqa: E402
from benchmark import asked_cases, case_parser, light_source  # noqa: E402

WINDOW = 7              # pixels: a maximum is the brightest of its WINDOW × WINDOW neighbours
SMOOTH_PX = 2.0         # the images and the scaled normals are smoothed (Gaussian σ, pixels)
CAP_DEG = 15.0          # an angle between a maximum's normal and its light counts at most this


def on_grid(values: np.ndarray, mask: np.ndarray, fill: float) -> np.ndarray:
    """(H, W, ...) image of (m, ...) per-pixel ``values`` on the (H, W) ``mask``, ``fill`` off it."""
    grid = np.full(mask.shape + values.shape[1:], fill, dtype=np.float64)
    grid[mask] = values
    return grid


def trimmed_scaled_normals(gray: np.ndarray, lights: np.ndarray, keep: tuple[float, float]) -> np.ndarray:
    """(m, 3) scaled normals by least squares on each pixel's images between the ``keep``
    quantiles of its values (the darker ones shadowed, the brighter ones glossy), for (n, m)
    ``gray`` images and (n, 3) scaled ``lights``. Under lights S·P⁻¹ they come out as B·Pᵀ."""
    order = np.argsort(np.argsort(gray, axis=0), axis=0) / max(len(gray) - 1, 1)
    used = (order >= keep[0]) & (order <= keep[1])                               # (n, m)
    gram = np.einsum("nm,ni,nj->mij", used.astype(np.float64), lights, lights)
    moment = np.einsum("nm,ni->mi", used * gray, lights)
    return np.linalg.solve(gram + 1e-9 * np.eye(3), moment[..., None])[..., 0]


def diffuse_maxima(gray: np.ndarray, scaled: np.ndarray, mask: np.ndarray,
                   albedo_spread: float, bright: float) -> tuple[np.ndarray, np.ndarray]:
    """The diffuse maxima of every image: (k,) image indices and (k, 3) scaled normals there, for
    (n, m) ``gray`` images and (m, 3) ``scaled`` normals on the (H, W) ``mask``'s pixels. The
    images are smoothed (SMOOTH_PX) where their maxima are read, and so are the normals."""
    albedo = on_grid(np.linalg.norm(scaled, axis=1), mask, 0.0)
    mean = uniform_filter(albedo, WINDOW)
    spread = np.sqrt(np.maximum(uniform_filter(albedo ** 2, WINDOW) - mean ** 2, 0)) / np.maximum(mean, 1e-9)
    uniform = (uniform_filter(mask.astype(np.float64), WINDOW) > 0.999) & (spread < albedo_spread)
    weight = np.maximum(gaussian_filter(mask.astype(np.float64), SMOOTH_PX), 1e-9)
    smooth = lambda values: gaussian_filter(on_grid(values, mask, 0.0), SMOOTH_PX) / weight  # noqa: E731
    normals = np.stack([smooth(scaled[:, c]) for c in range(3)], -1)
    images, found = [], []
    for i, values in enumerate(gray):
        image = np.where(mask, smooth(values), -np.inf)
        peaks = (image == maximum_filter(image, WINDOW)) & uniform
        peaks &= image > bright * np.percentile(image[mask], 99)
        images.append(np.full(int(peaks.sum()), i))
        found.append(normals[peaks])
    return np.concatenate(images), np.concatenate(found).reshape(-1, 3)


def maxima_misfit(p: np.ndarray, normals: np.ndarray, lights: np.ndarray, plane: bool) -> float:
    """Mean angle (degrees, each capped at CAP_DEG) between (k, 3) scaled ``normals`` turned by P
    (b' = P·b) and the (k, 3) ``lights`` they face, turned by P⁻ᵀ; with ``plane``, only the
    normal's angle out of the plane of its light and the view."""
    turned = normals @ p.T
    facing = lights @ np.linalg.inv(p)
    if not plane:
        return float(np.minimum(angular_error(turned, facing), CAP_DEG).mean())
    across = np.cross(facing, [0.0, 0.0, 1.0])
    sine = np.abs((turned * across).sum(1)) / np.maximum(
        np.linalg.norm(turned, axis=1) * np.linalg.norm(across, axis=1), 1e-12)
    return float(np.minimum(np.degrees(np.arcsin(np.minimum(sine, 1))), CAP_DEG).mean())


def pinned_bas_relief(normals: np.ndarray, lights: np.ndarray, plane: bool) -> np.ndarray:
    """The (3, 3) P bringing the maxima's normals nearest their lights: (μ, ν, λ), or with
    ``plane`` (μ, ν) into the plane of each light and the view (λ = 1, which that leaves free)."""
    if plane:
        cost = lambda x: maxima_misfit(bas_relief(x[0], x[1], 1.0), normals, lights, True)  # noqa: E731
        x = minimize(cost, np.zeros(2), method="Nelder-Mead", options={"xatol": 1e-4, "fatol": 1e-4}).x
        return bas_relief(x[0], x[1], 1.0)
    cost = lambda x: maxima_misfit(bas_relief(x[0], x[1], np.exp(x[2])), normals, lights, False)  # noqa: E731
    x = minimize(cost, np.zeros(3), method="Nelder-Mead", options={"xatol": 1e-4, "fatol": 1e-4}).x
    return bas_relief(x[0], x[1], np.exp(x[2]))


def main() -> None:
    parser = case_parser(__doc__.split("\n")[0])
    parser.add_argument("--albedo-spread", type=float, default=0.05,
                        help="largest relative spread of the albedos around a maximum")
    parser.add_argument("--keep", type=float, nargs=2, default=(0.3, 0.9),
                        help="the quantiles of each pixel's values its normal is solved on")
    parser.add_argument("--bright", type=float, default=0.5,
                        help="a maximum is at least this share of its image's 99th percentile")
    parser.add_argument("--plane", action="store_true",
                        help="ask only that each maximum's normal lie in the plane of its light and the view")
    args = parser.parse_args()
    logging.basicConfig(level=logging.ERROR)
    network, _ = light_source([], [])
    print(f"{'case':<28} {'network':>8} {'turned':>8} {'maxima':>7}   maxima to lights: "
          f"{'network':>7} {'turned':>7} {'true':>6}")
    rows = []
    for group, name, label, read in asked_cases(args):
        subject = read()
        lights = network(subject)
        gray = subject.observed_images()[:, subject.mask].mean(-1)                     # (n, m)
        net = lights.directions * lights.intensities.mean(1)[:, None]
        true = subject.light_directions * (subject.light_intensities.mean(1)[:, None]
                                           if subject.light_intensities is not None else 1.0)
        keep = tuple(args.keep)
        images, normals = diffuse_maxima(gray, trimmed_scaled_normals(gray, net, keep), subject.mask,
                                         args.albedo_spread, args.bright)
        true_images, true_normals = diffuse_maxima(gray, trimmed_scaled_normals(gray, true, keep),
                                                   subject.mask, args.albedo_spread, args.bright)
        if len(images) < 3:
            print(f"{f'{group}-{name}-{label}':<28} {len(images)} maxima: left as it is", flush=True)
            rows.append((group, label, *[float(angular_error(net, subject.light_directions).mean())] * 2,
                         None))
            continue
        p = pinned_bas_relief(normals, net[images], args.plane)
        turned = net @ np.linalg.inv(p)
        errors = [float(angular_error(d, subject.light_directions).mean()) for d in (net, turned)]
        fits = (maxima_misfit(np.eye(3), normals, net[images], args.plane),
                maxima_misfit(p, normals, net[images], args.plane),
                maxima_misfit(np.eye(3), true_normals, true[true_images], args.plane))
        rows.append((group, label, *errors, fits))
        print(f"{f'{group}-{name}-{label}':<28} {errors[0]:7.2f}° {errors[1]:7.2f}° {len(images):7d}   "
              f"{fits[0]:25.2f}° {fits[1]:6.2f}° {fits[2]:5.2f}°", flush=True)
    for group, label in dict.fromkeys((r[0], r[1]) for r in rows):
        chosen = [r for r in rows if r[:2] == (group, label)]
        errors = np.array([r[2:4] for r in chosen])
        fits = np.array([r[4] for r in chosen if r[4] is not None]).reshape(-1, 3)
        better, worse = int((errors[:, 1] < errors[:, 0]).sum()), int((errors[:, 1] > errors[:, 0] + 1).sum())
        network, turned, true = fits.mean(0)
        least = int((fits[:, 2] <= fits[:, :2].min(1)).sum())
        print(f"{group} {label}: {len(errors)} cases, network {errors[:, 0].mean():.2f}°, turned by the "
              f"maxima {errors[:, 1].mean():.2f}°; better on {better}, worse by more than 1° on {worse}; "
              f"maxima to lights on the {len(fits)} with maxima: network {network:.2f}°, turned "
              f"{turned:.2f}°, true {true:.2f}° (the least on {least})")

if __name__ == "__main__":
    main()

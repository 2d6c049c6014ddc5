"""Each pixel's normal on the subject's own grid, solved against its images with the fitted reflectance.

A fit on a working grid ``f`` times coarser than the subject cannot hold detail finer than ``f``
pixels; its normals come back by upsampling, with the robust initialisation's finer detail added
(:func:`unps.inverse.grids.upsample_with_detail`). The fitted reflectance is smooth at that scale
too, but the images are not: holding each image's reflectance at its upsampled value, each pixel's
normal is what its own images say under the fit's rendering model,

    I_j(p) ≈ c_j(p) · max(n(p)·l_j, 0),     c_j(p) = scale_j · R_j(p)  (RGB),

solved for n(p) in the L1 sense of the fit's loss, over the images that light the pixel and do not
leave it in a shadow the model cannot render.

A fit at full resolution gains from the solve too: its normal network renders the images only
through its few convolutions, and each pixel's own images still move its normal by 2–3° on
DiLiGenT's cat and pot1 (with the fast preset's network at full resolution, 500 steps: cat 6.21°
→ 5.82°, pot1 6.85° → 6.18°, ball 1.29° → 1.32°; ``experiments/calibrated/``).

Holding the reflectance fixed is only right where it does not turn with the normal. Where the
fitted reflectance has a specular lobe (its brightest value over the pixel's images more than
:data:`LOBE_PEAK` times its median), the solve moves the normal to explain the lobe's error with
shading, and the pixel keeps the fit.

A pixel's own images carry its noise as well as its detail. The noise is read off the solve's
own residuals, differenced between neighbouring pixels (:func:`noise_level`): what the model
cannot render (highlights, interreflections) changes little from a pixel to the next and
cancels, noise does not. Where it is above :data:`NOISE_LIMIT`, the caller keeps the fit.

Frame: unps's (x right, y up, z toward the camera).
"""

from __future__ import annotations

import numpy as np

SHADOW_RATIO = 0.5
"""A value below this share of what the model renders under the start's normal is taken for a
cast shadow (or a dark spot the model cannot render) and left out. 0.5 rather than 0.3: on the
light benchmark's 24 unseen objects, 13.11° → 12.95° (``experiments/light_benchmark/``, "Cast
shadows in each pixel's solve"), most on the self-shadowing ones (the rose, the knot), where a
shadow lit by interreflections or covering part of a pixel stays above 0.3 of the model's value."""
LIT = 0.02
"""Images whose light meets the normal at n·l below this are left out (attached shadow)."""
MIN_IMAGES = 4
"""A pixel with fewer usable images keeps its start."""
LOBE_PEAK = 2.0
"""A pixel whose fitted reflectance, over the values its solve stands on, peaks above this multiple
of its median keeps the upsampled fit (:func:`reflectance_peak`): its reflectance turns with the
normal, and the solve, holding it fixed, moved such pixels off a right fit (on the light
benchmark's 24 unseen objects the mean 10.78° → 10.48°, blob07's nickel and PVC 13.8° and 10.9° →
8.6°, the worst blob09's +0.05°; under 20 and 12 lights 10.60° → 10.34° and 12.82° → 12.64°, with
losses up to 1.3° among the gains: ``experiments/light_benchmark/``, "Each pixel's solve
and a specular lobe"). The error was flat from 1.5 to 2.5 there; a Lambertian pixel's peak is 1."""
NOISE_LIMIT = 0.15
"""Image noise (σ, a share of the images' 99th percentile) above which each pixel's own images
hold more noise than detail: in the ``noise`` study (``experiments/noise/``) the solve lowered
the error up to σ = 0.1 (read as 0.12) and raised it by 2° at σ = 0.2 (read as 0.17–0.18); the
light benchmark's captures read 0.006–0.05, DiLiGenT's cat 0.017."""


def observed_shading(images: np.ndarray, colour: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each value's shading t = max(n·l, 0) as the model reads it, and how much it weighs.

    Args:
        images: (n, P, 3) observed values; colour: (n, P, 3) c_j(p), the model's value at t = 1.

    Returns:
        (n, P) t = <I, c> / <c, c> (the least-squares shading of the three channels), and (n, P) |c|:
        an L1 residual in image units, |I − c·t|, is about |c|·|t_observed − t|.
    """
    power = np.einsum("npc,npc->np", colour, colour)      # a third of the time of (colour ** 2).sum(-1)
    return np.einsum("npc,npc->np", colour, images) / np.maximum(power, 1e-12), np.sqrt(power)


def weighted_normals(shading: np.ndarray, weight: np.ndarray, lights: np.ndarray) -> np.ndarray:
    """(P, 3) unit normals minimising Σ_j w_j (t_j − n·l_j)² per pixel (:func:`scaled_normals`,
    then scaled).

    Args:
        shading: (n, P) observed shading t; weight: (n, P) ≥ 0; lights: (n, 3) unit directions.

    Returns:
        (P, 3); NaN or arbitrary where the weighted lights do not span three directions (the caller
        keeps only pixels with enough images).
    """
    solved = scaled_normals(shading, weight, lights)
    with np.errstate(invalid="ignore", divide="ignore"):
        return solved / np.linalg.norm(solved, axis=-1, keepdims=True)


def scaled_normals(shading: np.ndarray, weight: np.ndarray, lights: np.ndarray) -> np.ndarray:
    """(P, 3) b minimising Σ_j w_j (t_j − b·l_j)² per pixel: the normal scaled by the albedo, as
    weighted_normals' arguments; a small ridge keeps every system solvable."""
    outer = (lights[:, :, None] * lights[:, None, :]).reshape(len(lights), 9)      # (n, 9) l_j l_jᵀ
    gram = (weight.T @ outer).reshape(-1, 3, 3)          # matrix products: 20× faster than einsum's loops
    target = (weight * shading).T @ lights
    ridge = (1e-9 * np.trace(gram, axis1=1, axis2=2) + 1e-30)[:, None, None] * np.eye(3)   # never singular
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.linalg.solve(gram + ridge, target[..., None])[..., 0]


def refine_pixel_normals(images: np.ndarray, colour: np.ndarray, normals: np.ndarray, lights: np.ndarray,
                         usable: np.ndarray | None = None,
                         reweightings: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each pixel's normal under the fitted reflectance, from its own images (L1, by iteratively
    reweighted least squares), starting from ``normals``.

    Args:
        images: (n, P, 3) the pixels' values, divided by the light intensities.
        colour: (n, P, 3) the model's value of each at shading 1: light scale × fitted reflectance.
        normals: (P, 3) unit, the start (the upsampled fit), which also decides which values are
            in shadow.
        lights: (n, 3) unit surface-to-light directions.
        usable: (n, P) bool, False for values the fit left out (clipped); None: all.
        reweightings: L1 reweightings after the least-squares solve.

    Returns:
        (P, 3) unit normals; (P,) bool, the pixels solved (the others keep their start: fewer
        than :data:`MIN_IMAGES` usable images, lights that do not span three directions, a
        solution facing away from the camera, n_z ≤ 0, which no pixel of the object can see, or a
        specular lobe); (n, P) bool, the values the solution stands on (kept, and lit under it);
        and (P,) bool, the pixels whose fitted reflectance has a specular lobe (peaks above
        :data:`LOBE_PEAK` times its median over their kept values) and so keep their start.
    """
    shading, weight = observed_shading(images, colour)
    keep = kept_values(shading, normals, lights, usable)
    lobed = reflectance_peak(weight, keep) > LOBE_PEAK
    current = normals
    for step in range(1 + reweightings):
        along = lights @ current.T                                              # (n, P) n·l
        facing = keep & (along > LIT)
        w = weight * facing
        if step:
            w = w / np.maximum(np.abs(shading - along), 1e-2)
        solved = weighted_normals(shading, w, lights)
        ok = np.isfinite(solved).all(-1) & (facing.sum(0) >= MIN_IMAGES) & (solved[:, 2] > 0) & ~lobed
        current = np.where(ok[:, None], solved, normals)
    return current, ok, keep & (lights @ current.T > LIT), lobed


def reflectance_peak(brightness: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """(P,) each pixel's brightest model value at shading 1 over its kept values, as a multiple of
    their median: 1 for a reflectance that does not change from one light to the next (Lambertian),
    well above it where the light of some images falls in a specular lobe.

    Args:
        brightness: (n, P) |c_j(p)| (:func:`observed_shading`'s second output); kept: (n, P) bool,
            the values a pixel's solve may stand on (:func:`kept_values`).

    Returns:
        (P,) ≥ 1; 1 for a pixel with no kept value.

    >>> reflectance_peak(np.array([[1.0, 1.0], [1.0, 5.0], [1.0, 1.0]]), np.ones((3, 2), bool)).tolist()
    [1.0, 5.0]
    """
    ordered = np.sort(np.where(kept, brightness, np.inf), axis=0)     # each pixel's kept values first
    count = kept.sum(0)
    some = np.flatnonzero(count)
    n = count[some]
    median = 0.5 * (ordered[(n - 1) // 2, some] + ordered[n // 2, some])
    peak = np.ones(kept.shape[1])
    peak[some] = ordered[n - 1, some] / np.maximum(median, 1e-12)     # 15× faster than nanmax / nanmedian
    return peak


def kept_values(shading: np.ndarray, normals: np.ndarray, lights: np.ndarray,
                usable: np.ndarray | None = None) -> np.ndarray:
    """(n, P) bool: the values a pixel's solve may use — lit under ``normals`` (P, 3), not darker
    than :data:`SHADOW_RATIO` of what the model renders there (a cast shadow), and ``usable``."""
    rendered = np.clip(lights @ normals.T, 0, None)
    keep = (rendered > LIT) & (shading > SHADOW_RATIO * rendered)
    return keep & usable if usable is not None else keep


def neighbour_pairs(mask: np.ndarray) -> np.ndarray:
    """(Q, 2) indices, in ``mask``'s row-major order of object pixels, of the pixels side by side
    or one above the other, both on the object.

    >>> neighbour_pairs(np.array([[True, True], [False, True]])).tolist()
    [[0, 1], [1, 2]]
    """
    index = np.full(mask.shape, -1)
    index[mask] = np.arange(int(mask.sum()))
    across = mask[:, :-1] & mask[:, 1:]
    down = mask[:-1] & mask[1:]
    return np.concatenate([np.stack([index[:, :-1][across], index[:, 1:][across]], 1),
                           np.stack([index[:-1][down], index[1:][down]], 1)])


def noise_level(images: np.ndarray, colour: np.ndarray, normals: np.ndarray, lights: np.ndarray,
                used: np.ndarray, pairs: np.ndarray) -> float:
    """The images' noise σ per channel, in image units, read off the per-pixel solve.

    Each used value's residual in image units, |c|·(t − a·n·l) with a the pixel's own scale (its
    albedo's departure from the fitted reflectance, finer texture among it), holds the noise and
    what the model cannot render. The second changes little from a pixel to its neighbour, so the
    difference of two neighbours' residuals under the same image is the noise of both: σ² is half
    the variance of those differences (from their median absolute value, robust to the edges of
    shadows and highlights), corrected for the three unknowns each pixel's solve fitted.

    Args:
        images, colour: (n, P, 3) as :func:`refine_pixel_normals` takes them; normals: (P, 3) its
            solution; lights: (n, 3); used: (n, P) bool, the values it stands on (its third
            output); pairs: (Q, 2) neighbouring pixels (:func:`neighbour_pairs`).

    Returns:
        σ, or 0 where fewer than 100 pairs of used values are found.
    """
    shading, power = observed_shading(images, colour)
    along = (lights @ normals.T) * used                                         # (n, P)
    scale = (power * shading * along).sum(0) / np.maximum((power * along ** 2).sum(0), 1e-12)
    residual = np.ascontiguousarray((power * (shading - scale * along)).T)      # (P, n): pairs gather rows
    first, second = pairs.T
    used_by_pixel = np.ascontiguousarray(used.T)
    both = used_by_pixel[first] & used_by_pixel[second]                         # (Q, n)
    images_used = used.sum(0)
    count = float(np.median(images_used[images_used >= MIN_IMAGES])) if both.sum() >= 100 else 0.0
    if count <= 3:
        return 0.0
    differences = (residual[first] - residual[second])[both]
    sigma = 1.4826 * np.median(np.abs(differences)) / np.sqrt(2)                # MAD → σ
    return float(sigma * np.sqrt(count / (count - 3)))

"""Normals read off specular highlights, for the pixels whose images a diffuse model cannot explain.

The fit's L1 loss treats a pixel's one or two bright images as outliers when the rest are dark, and
so, on dark glossy materials (metals, black or coloured phenolics, metallic paints), nothing in it
holds the normal: on the light benchmark's tablet under its true lights the fit's normals were 52°
off. Those images say more than any other, though: a highlight peaks where the normal bisects the
light and the view, so under a dense set of lights the half vector of the brightest image's light
is the normal to within about a quarter of the spacing between lights.

A pixel is taken to be lit by a highlight when all three hold:

- its brightest image is at least :data:`PEAK_RATIO` times its median image (a diffuse pixel under
  a dome of lights varies as a cosine: two to three times, more where it shadows itself);
- its lit images (above :data:`LIT_SHARE` of its brightest) do not follow Lambert's cosine: the
  relative residual of the least-squares Lambertian fit to them is above :data:`NOT_LAMBERTIAN`,
  or they are too few (under :data:`MIN_LIT`) for the cosine to be tested, as under a sharp
  highlight on a nearly black material. A diffuse pixel deep in a cavity, lit by a few lights
  only, is as peaked as a highlight, but its lit images still follow the cosine;
- the lights are dense around the brightest image's light (its nearest other light within
  :data:`MAX_SPACING_DEG`): the half vector pins the normal only to within about a quarter of that.

Frame: unps's (x right, y up, z toward the camera; orthographic, the view along +z).
"""

from __future__ import annotations

import numpy as np

from unps.inverse.pixels import scaled_normals

PEAK_RATIO = 8.0
"""The brightest image over the median image (floored at :data:`FLOOR_SHARE`) a highlight reaches.
At 5 the light benchmark gained 0.7° more, but unps's Rose, whose petals shadow each other (a
broad lobe on a red material), lost 3.2°: at 8 it gains 0.7° (``experiments/light_benchmark``)."""
NOT_LAMBERTIAN = 0.4
"""Relative RMS residual of the Lambertian fit to a pixel's lit images above which they are not
diffuse. Without this test DiLiGenT's cat and pot1 lost 0.4-0.5° on pixels in cavities and near
their outlines, lit by few lights (``experiments/light_benchmark/README.md``, "Normals from
highlights")."""
MIN_LIT = 6
"""Lit images a pixel needs for its Lambertian fit (three unknowns) to be tested at all."""
LIT_SHARE = 0.05
"""Images darker than this share of the pixel's brightest are left out of the Lambertian fit
(attached and cast shadows)."""
FLOOR_SHARE = 0.01
"""The median is floored at this share of the object's 99th percentile of brightest values, so
a pixel dark in most images (8-bit storage floors them at 0) is not peaked by its noise alone."""
MAX_SPACING_DEG = 15.0
"""The farthest the brightest image's light may be from its nearest other light: DiLiGenT's dome
of 96 lights spaces them by about 7°; 20 lights spread over the same cap, by about 25°."""
VIEW = np.array([0.0, 0.0, 1.0])


def highlight_normals(shading: np.ndarray, lights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The half vectors of each pixel's brightest image, and which pixels are lit by a highlight.

    Args:
        shading: (n, P) each pixel's brightness in each image (the images' channels averaged),
            divided by the light intensities.
        lights: (n, 3) unit surface-to-light directions.

    Returns:
        (P, 3) unit normals, the half vector of the light and the view for each pixel's brightest
        image; (P,) bool, the pixels lit by a highlight (module docstring).
    """
    brightest, top = shading.max(0), shading.argmax(0)
    floor = FLOOR_SHARE * float(np.percentile(brightest, 99)) if brightest.size else 0.0
    peaked = (brightest > 0) & (brightest >= PEAK_RATIO * np.maximum(np.median(shading, 0), floor))
    dense = light_spacing(lights)[top] <= MAX_SPACING_DEG
    half = lights[top] + VIEW
    half /= np.linalg.norm(half, axis=-1, keepdims=True)
    return half, peaked & dense & (lambertian_misfit(shading, lights) > NOT_LAMBERTIAN)


def light_spacing(lights: np.ndarray) -> np.ndarray:
    """(n,) degrees from each of the (n, 3) unit ``lights`` to the nearest other one (180 for a
    single light).

    >>> light_spacing(np.array([[0.0, 0, 1], [1, 0, 0], [0.6, 0, 0.8]])).round(2).tolist()
    [36.87, 53.13, 36.87]
    """
    cosines = lights @ lights.T
    np.fill_diagonal(cosines, -1.0)
    return np.degrees(np.arccos(np.clip(cosines.max(1), -1.0, 1.0)))


def lambertian_misfit(shading: np.ndarray, lights: np.ndarray) -> np.ndarray:
    """(P,) the relative RMS residual of the least-squares fit t_j ≈ max(b·l_j, 0) to each pixel's
    lit values (above :data:`LIT_SHARE` of its brightest), b a scaled normal; ∞ for a pixel with
    fewer than :data:`MIN_LIT` of them (its few values say nothing of a cosine).

    Args:
        shading: (n, P) as :func:`highlight_normals`; lights: (n, 3) unit directions.
    """
    lit = shading > LIT_SHARE * shading.max(0)
    scaled = scaled_normals(shading, lit.astype(np.float64), lights)
    residual = (np.clip(scaled @ lights.T, 0, None).T - shading) * lit
    energy = ((shading * lit) ** 2).sum(0)
    misfit = np.sqrt((residual ** 2).sum(0) / np.maximum(energy, 1e-30))
    return np.where(lit.sum(0) >= MIN_LIT, misfit, np.inf)

"""Analytic Lambertian subjects rendered in numpy: known answers for tests and a first run.

No interreflections and no cast shadows (attached shadows only), so calibrated least
squares is exact where every light sees a pixel; the physically rendered benchmark
subjects come from ``unps.render``.
"""

from __future__ import annotations

import numpy as np

from unps.data.subject import Subject
from unps.errors import InputError

SHAPES = ("sphere", "bumps")


def height_field(shape: str, size: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Depth, normals and mask of an analytic surface seen orthographically.

    Args:
        shape: ``sphere`` (a hemisphere filling 90 % of the image) or ``bumps`` (a disc
            with Gaussian bumps and dents placed by ``seed``).
        size: image side in pixels.

    Returns:
        depth (H, W) in pixel units, normals (H, W, 3) unit in the unps frame, mask (H, W) bool.
    """
    if shape not in SHAPES:
        raise InputError(f"unknown analytic shape {shape!r}; known: {', '.join(SHAPES)}")
    if size < 8:
        raise InputError(f"size must be at least 8 pixels, got {size}")
    centre = (size - 1) / 2
    r, c = np.mgrid[0:size, 0:size].astype(np.float64)
    x, y = c - centre, centre - r
    radius = 0.45 * size
    rho2 = x ** 2 + y ** 2
    mask = rho2 < (0.97 * radius) ** 2
    if shape == "sphere":
        z = np.sqrt(np.maximum(radius ** 2 - rho2, 0))
        dz_dx, dz_dy = -x / np.maximum(z, 1e-9), -y / np.maximum(z, 1e-9)
    else:
        rng = np.random.default_rng(seed)
        z = np.zeros_like(x)
        dz_dx = np.zeros_like(x)
        dz_dy = np.zeros_like(x)
        for _ in range(6):
            cx, cy = rng.uniform(-0.5, 0.5, 2) * radius
            width = rng.uniform(0.12, 0.25) * radius
            height = rng.choice([-1, 1]) * rng.uniform(0.3, 0.6) * width
            g = height * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * width ** 2))
            z += g
            dz_dx += -g * (x - cx) / width ** 2
            dz_dy += -g * (y - cy) / width ** 2
    normals = np.stack([-dz_dx, -dz_dy, np.ones_like(x)], axis=-1)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    return z.astype(np.float32), normals.astype(np.float32), mask


def dome_lights(n: int, seed: int, min_elevation_deg: float = 30.0) -> np.ndarray:
    """(n, 3) unit directions uniform over the cap of the upper hemisphere above an elevation."""
    if n < 1:
        raise InputError(f"need at least one light, got {n}")
    rng = np.random.default_rng(seed)
    z = rng.uniform(np.sin(np.radians(min_elevation_deg)), 1.0, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    s = np.sqrt(1 - z ** 2)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1).astype(np.float32)


def render_lambertian(shape: str = "sphere", size: int = 64, n_lights: int = 32,
                      textured: bool = False, seed: int = 0) -> Subject:
    """Render a Lambertian subject: x_i = ρ ⊙ max(n · l_i, 0), with known lights and normals.

    Light intensities are drawn per image and colour (U(0.5, 1.5)) and the stored images are
    divided by them, as a reader does with a real capture.

    Args:
        shape: see :func:`height_field`.
        size: image side in pixels.
        n_lights: number of images.
        textured: spatially varying RGB albedo instead of a uniform grey 0.8.
        seed: everything random (lights, bumps, texture) follows from it.
    """
    depth, normals, mask = height_field(shape, size, seed)
    rng = np.random.default_rng(seed + 1)
    lights = dome_lights(n_lights, seed + 2)
    if textured:
        r, c = np.mgrid[0:size, 0:size] / size
        phase = rng.uniform(0, 2 * np.pi, 3)
        albedo = 0.55 + 0.35 * np.sin(2 * np.pi * (2 * r + 3 * c)[..., None] + phase)
    else:
        albedo = np.full((size, size, 3), 0.8)
    shading = np.maximum(np.einsum("hwc,nc->nhw", normals, lights), 0)
    images = albedo[None] * shading[..., None] * mask[None, ..., None]
    intensities = rng.uniform(0.5, 1.5, (n_lights, 3)).astype(np.float32)
    return Subject(name=f"lambertian-{shape}", images=images.astype(np.float32), mask=mask,
                   light_directions=lights, light_intensities=intensities, normals=normals,
                   depth=np.where(mask, depth, np.nan))

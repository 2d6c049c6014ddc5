"""Woodham's calibrated Lambertian photometric stereo (least squares per pixel)."""

from __future__ import annotations

import numpy as np

from unps.data.estimate import Estimate
from unps.data.subject import Subject


def lambertian_least_squares(intensity: np.ndarray, light_directions: np.ndarray) -> np.ndarray:
    """Solve intensity = lightsᵀ·b for b = ρ·n at every pixel.

    Args:
        intensity: (n, m) one brightness per image and pixel.
        light_directions: (n, 3) unit surface-to-light directions.

    Returns:
        (m, 3) scaled normals b; |b| is the albedo.
    """
    solution, *_ = np.linalg.lstsq(light_directions.astype(np.float64),
                                   intensity.astype(np.float64), rcond=None)
    return solution.T


def normals_from_scaled(b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split (m, 3) scaled normals into (m, 3) unit normals and (m,) albedo.

    A zero vector (a pixel dark in every image) gets the normal (0, 0, 1), facing the camera.
    """
    albedo = np.linalg.norm(b, axis=1)
    normals = np.where(albedo[:, None] > 0, b / np.maximum(albedo, 1e-30)[:, None], [0, 0, 1.0])
    return normals, albedo


def rgb_albedo(images: np.ndarray, normals: np.ndarray, light_directions: np.ndarray) -> np.ndarray:
    """Least-squares RGB albedo per pixel given its normal: Σᵢ xᵢ·sᵢ / Σᵢ sᵢ², sᵢ = max(n·lᵢ, 0).

    Args:
        images: (n, m, 3) pixel values.
        normals: (m, 3) unit normals.
        light_directions: (n, 3).

    Returns:
        (m, 3) albedo.
    """
    shading = np.maximum(light_directions.astype(np.float32) @ normals.T.astype(np.float32), 0)
    num = np.einsum("nm,nmc->mc", shading, images.astype(np.float32, copy=False), optimize=True)
    return num / np.maximum((shading ** 2).sum(0), 1e-12)[:, None]


def to_maps(values: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Scatter (m, C) per-pixel values into an (H, W, C) float32 map, zero off the mask."""
    out = np.zeros(mask.shape + values.shape[1:], np.float32)
    out[mask] = values
    return out


def woodham(subject: Subject, light_directions: np.ndarray) -> Estimate:
    """Calibrated Lambertian photometric stereo (Woodham 1980) on the gray images.

    Gray is the mean of the intensity-normalised RGB channels; no shadow or highlight is
    treated specially, which is what the classical reference figures assume.

    Args:
        subject: images divided by their intensities.
        light_directions: (n, 3) unit, surface to light, unps frame.
    """
    pixels = subject.images[:, subject.mask]                          # (n, m, 3)
    b = lambertian_least_squares(pixels.mean(-1), light_directions)
    normals, _ = normals_from_scaled(b)
    albedo = rgb_albedo(pixels, normals, light_directions)
    return Estimate(to_maps(normals, subject.mask), to_maps(albedo, subject.mask))

"""Nayar's interreflection model (Nayar, Ikeuchi & Kanade 1991; supplementary Eqs. 2–3, §5).

A Lambertian surface is cut into m facets. Facet i's radiance is its own direct radiance plus
what it receives from every other facet:

    L = L_s + P K L   ⇒   L = (I − P K)⁻¹ L_s,

with P = diag(ρ) the facet albedos and K the interreflection kernel. In terms of facet
matrices (rows ρᵢ·nᵢ), the observed, "pseudo" facets are F_p = (I − P K)⁻¹ F, so the true ones
are F = (I − P K) F_p.

Frame: x right (+col), y up (−row), z toward the camera; facet positions in pixel units of
the facet grid (depth from :func:`unps.geometry.integrate_normals` on that grid).
"""

from __future__ import annotations

import logging

import cv2
import numpy as np
from scipy.ndimage import map_coordinates
import torch
import torch.nn.functional as F

from unps.data.estimate import Estimate
from unps.data.subject import Subject
from unps.grid import block_mean
from unps.geometry import integrate_normals
from unps.solvers.woodham import (lambertian_least_squares, normals_from_scaled,
                                  rgb_albedo, to_maps)

log = logging.getLogger(__name__)


def facet_positions(depth: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(m, 3) centres of the object's facets: x = col, y = −row, z = depth."""
    rows, cols = np.nonzero(mask)
    return np.stack([cols, -rows, depth[mask]], 1).astype(np.float64)


def visibility(depth: np.ndarray, mask: np.ndarray, steps: int = 16, chunk: int = 256,
               pairs: np.ndarray | None = None) -> np.ndarray:
    """(m, m) bool: whether the segment between two facets clears the surface.

    The segment is sampled at ``steps`` interior points; it is blocked where the depth map,
    interpolated bilinearly (off the object it never blocks), stands above it by more than
    0.05 pixel. Rows are processed ``chunk`` facets at a time to bound memory. With ``pairs``
    ((m, m) bool) only those segments are sampled, each to the same values, and the others are
    False.
    """
    rows, cols = np.nonzero(mask)
    z = depth[mask]
    m = len(z)
    surface = np.where(mask, depth, -1e9)
    t = np.linspace(0, 1, steps + 2)[1:-1, None]
    visible = np.zeros((m, m), bool)
    for start in range(0, m, chunk):
        block = np.ones((min(chunk, m - start), m), bool) if pairs is None else pairs[start:start + chunk]
        i, j = np.nonzero(block)
        i += start
        r = rows[i] + t * (rows[j] - rows[i])                                 # (steps, pairs)
        c = cols[i] + t * (cols[j] - cols[i])
        height = z[i] + t * (z[j] - z[i])
        sampled = map_coordinates(surface, [r.ravel(), c.ravel()], order=1, mode="nearest")
        visible[i, j] = ~(sampled.reshape(r.shape) > height + 0.05).any(0)
    return visible


def interreflection_kernel(depth: np.ndarray, normals: np.ndarray, mask: np.ndarray,
                           occlusion: bool = True) -> np.ndarray:
    """Nayar's kernel between the object's facets, (m, m).

        K_ij = V_ij · max(nᵢ·d, 0) · max(nⱼ·(−d), 0) / (π |d|⁴) · Aⱼ,   d = xⱼ − xᵢ,

    i.e. cos θᵢ cos θⱼ / (π r²) times facet j's area Aⱼ = 1 / nⱼ_z (a unit pixel's footprint
    on a facet tilted by θ). V_ij is 1 when the segment between the facets clears the surface
    (:func:`visibility`), and the orientation terms are 0 when either facet faces away from the
    other, so K_ii = 0 and K is zero between facets that cannot see each other. Reciprocity
    holds in the sense K_ij·Aᵢ = K_ji·Aⱼ (the form-factor relation), not K_ij = K_ji.

    Args:
        depth: (h, w) in pixel units of this grid.
        normals: (h, w, 3) unit normals.
        mask: (h, w) bool, m object pixels.
        occlusion: include the visibility term.
    """
    x = facet_positions(depth, mask)
    n = normals[mask].astype(np.float64)
    d = x[None, :, :] - x[:, None, :]                                  # d[i, j] = x_j − x_i
    r2 = (d ** 2).sum(-1)
    np.fill_diagonal(r2, np.inf)
    cos_i = np.maximum(np.einsum("ik,ijk->ij", n, d), 0)
    cos_j = np.maximum(-np.einsum("jk,ijk->ij", n, d), 0)
    area = 1 / np.maximum(n[:, 2], 0.05)
    k = cos_i * cos_j / (np.pi * r2 ** 2) * area[None, :]
    if occlusion:
        k *= visibility(depth, mask, pairs=k > 0)     # only facets that face each other
    return k


def visibility_on_device(depth: torch.Tensor, mask: torch.Tensor, steps: int = 16,
                         chunk: int = 256) -> torch.Tensor:
    """:func:`visibility` in torch, on the device of ``depth`` (the path for a GPU).

    The same segments and samples, read bilinearly by ``grid_sample`` (border padding, as
    ``map_coordinates`` with ``mode="nearest"``) in float64; it agrees with :func:`visibility`
    except where a sample lies within float rounding of the 0.05-pixel threshold.

    Args:
        depth: (h, w) float64 depth in pixels of this grid.
        mask: (h, w) bool, m object pixels.

    Returns:
        (m, m) bool, on ``depth``'s device.
    """
    h, w = mask.shape
    rows, cols = (index.to(depth.dtype) for index in torch.nonzero(mask, as_tuple=True))
    z = depth[mask]
    surface = torch.where(mask, depth, torch.full_like(depth, -1e9))[None, None]
    t = torch.linspace(0, 1, steps + 2, dtype=depth.dtype, device=depth.device)[1:-1, None, None]
    visible = torch.empty(len(z), len(z), dtype=torch.bool, device=depth.device)
    for start in range(0, len(z), chunk):
        i = slice(start, start + chunk)
        r = rows[i, None] + t * (rows[None, :] - rows[i, None])                  # (steps, chunk, m)
        c = cols[i, None] + t * (cols[None, :] - cols[i, None])
        height = z[i, None] + t * (z[None, :] - z[i, None])
        # grid_sample's coordinates with align_corners: −1 and 1 are the first and last pixel
        grid = torch.stack([2 * c / max(w - 1, 1) - 1, 2 * r / max(h - 1, 1) - 1], -1)
        sampled = F.grid_sample(surface, grid.flatten(0, 1)[None], mode="bilinear",
                                padding_mode="border", align_corners=True).view(r.shape)
        visible[i] = ~(sampled > height + 0.05).any(0)
    return visible


def kernel_on_device(depth: torch.Tensor, normals: torch.Tensor, mask: torch.Tensor,
                     occlusion: bool = True) -> torch.Tensor:
    """:func:`interreflection_kernel` in torch, on the device of ``depth`` (the path for a GPU).

    Args:
        depth: (h, w) float64 depth in pixels of this grid.
        normals: (h, w, 3) unit normals, float64.
        mask: (h, w) bool, m object pixels.
        occlusion: include the visibility term (:func:`visibility_on_device`).

    Returns:
        (m, m) float64 K, on ``depth``'s device.
    """
    rows, cols = torch.nonzero(mask, as_tuple=True)
    x = torch.stack([cols.to(depth.dtype), -rows.to(depth.dtype), depth[mask]], 1)
    n = normals[mask]
    d = x[None, :, :] - x[:, None, :]                                  # d[i, j] = x_j − x_i
    r2 = (d ** 2).sum(-1)
    r2.fill_diagonal_(torch.inf)
    cos_i = torch.einsum("ik,ijk->ij", n, d).clamp_min(0)
    cos_j = (-torch.einsum("jk,ijk->ij", n, d)).clamp_min(0)
    area = 1 / n[:, 2].clamp_min(0.05)
    k = cos_i * cos_j / (torch.pi * r2 ** 2) * area[None, :]
    if occlusion:
        k *= visibility_on_device(depth, mask)
    return k


def reflectance_scale(albedo: np.ndarray, stated: float | None = None) -> float:
    """The factor that turns albedos into the reflectances P needs.

    Captures give albedo only up to the unknown exposure (and estimated lights up to a
    global scale), while (I − PK) needs reflectances: a surface cannot reflect more than it
    receives. With ``stated``, the user's figure for the object's median diffuse reflectance,
    the factor makes the albedo's median that (the median, as facets that interreflections
    brighten most would sway a high percentile). Without it the albedo is taken as a reflectance
    already (as it is on unps's renders divided by their true light intensities, not with
    estimated ones, which are relative) and only scaled down when its 99th percentile exceeds 1.
    Albedos are scaled, never clipped.

    Args:
        albedo: (M,) gray albedos over the object.
        stated: in (0, 1], or None.

    Raises:
        ValueError: ``stated`` outside (0, 1].
    """
    if stated is not None:
        if not 0 < stated <= 1:
            raise ValueError(f"interreflection.albedo is a reflectance in (0, 1], got {stated}")
        return stated / float(np.median(albedo))
    level = float(np.percentile(albedo, 99))
    return 1 / level if level > 1 else 1.0


def remove_interreflections(pseudo: np.ndarray, kernel: np.ndarray, albedo: np.ndarray) -> np.ndarray:
    """F = (I − P K) F_p: facets without the light they received from each other.

    Args:
        pseudo: (m, 3) observed facets ρ_p·n_p.
        kernel: (m, m) K.
        albedo: (m,) ρ, the diagonal of P.
    """
    return pseudo - albedo[:, None] * (kernel @ pseudo)


def upsample(values: np.ndarray, mask: np.ndarray, shape: tuple[int, int], factor: int) -> np.ndarray:
    """Bilinear upsampling of (h, w, C) facet values by ``factor`` to ``shape``, normalised by
    the facet mask so that values off the object do not pull the edges toward zero."""
    size = (mask.shape[1] * factor, mask.shape[0] * factor)
    weight = cv2.resize(mask.astype(np.float64), size, interpolation=cv2.INTER_LINEAR)
    spread = cv2.resize(values * mask[..., None], size, interpolation=cv2.INTER_LINEAR)
    out = spread / np.maximum(weight, 1e-6)[..., None]
    return out[: shape[0], : shape[1]]


def nayar(subject: Subject, light_directions: np.ndarray, iterations: int = 15,
          downsample: int = 4, occlusion: bool = True, albedo: float | None = None) -> Estimate:
    """Nayar's shape from interreflections, as the paper's baseline (supplementary §5).

    Woodham's least squares gives the pseudo facets F_p (scaled normals ρ_p·n_p). On a facet
    grid ``downsample`` times coarser, each iteration integrates the current normals into
    depth, computes K, and sets F = (I − P K) F_p with P from the current albedo. The final
    correction P K F_p is smooth, so it is upsampled and subtracted from the full-resolution
    pseudo facets, which keeps their detail.

    Args:
        subject: images divided by their intensities.
        light_directions: (n, 3) unit, surface to light.
        iterations: Nayar's iterations (15 in the paper's comparison).
        downsample: facet grid factor (the interreflection kernel is O(m²) in facets).
        occlusion: include visibility in K.
        albedo: the object's median diffuse reflectance: each iteration scales the current
            albedo to it for P (:func:`reflectance_scale`; None: the albedo is a reflectance
            already).
    """
    mask = subject.mask
    pixels = subject.images[:, mask]
    scaled = lambertian_least_squares(pixels.mean(-1), light_directions)             # (M, 3)
    pseudo_full = to_maps(scaled, mask).astype(np.float64)
    pseudo, facets = block_mean(pseudo_full, mask, downsample)
    pseudo_f = pseudo[facets]
    current = pseudo_f
    log.info("nayar: %d facets at ×%d, %d iterations", facets.sum(), downsample, iterations)
    for _ in range(iterations):
        normals, facet_albedo = normals_from_scaled(current)
        depth = integrate_normals(to_maps(normals, facets), facets)
        kernel = interreflection_kernel(depth, to_maps(normals, facets), facets, occlusion)
        reflectance = facet_albedo * reflectance_scale(facet_albedo, albedo)
        current = remove_interreflections(pseudo_f, kernel, reflectance)
    correction = upsample(to_maps(pseudo_f - current, facets).astype(np.float64), facets,
                          mask.shape, downsample)
    corrected = pseudo_full - correction
    normals, _ = normals_from_scaled(corrected[mask])
    return Estimate(to_maps(normals, mask), to_maps(rgb_albedo(pixels, normals, light_directions), mask))

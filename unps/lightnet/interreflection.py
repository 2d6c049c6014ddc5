"""Interreflections in the light network's training data: light that reaches a pixel from other
parts of the object, as in real captures and in the light benchmark's Mitsuba renders.

Radiosity on a facet grid :data:`FACET` times coarser than the images. Each facet's direct
radiance toward the camera is taken as what it sends everywhere (a diffuse approximation for
glossy emitters), and every bounce is solved at once,

    L = (I − P K)⁻¹ L_direct,

with K Nayar's kernel between facets, visibility over the depth map included
(:func:`unps.solvers.nayar.kernel_on_device`), and P = diag(ρ) the facets' diffuse reflectances.
The irradiance the other facets send, E = π K L, is interpolated to the image's pixels, where
each reflects ρ(x)/π · E(x) of it.

Frame: x right, y up, z toward the camera; depth in view units (the view covers [−1, 1]², one
pixel is 2 / (H − 1)).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from unps.solvers.nayar import kernel_on_device

FACET = 4
"""Image pixels per facet side: at the training's 64 px, a 16 × 16 grid (the kernel is O(m²))."""

MAX_REFLECTANCE = 0.95
"""A facet reflects at most this share of what it receives, so that the bounces converge."""

INCIDENCE_DEG = (30.0, 50.0, 70.0)
"""Zenith angles of light at which a material's reflectance toward the normal is read
(:func:`diffuse_reflectance`): off the mirror direction of a view along the normal, so that
sharp highlights do not count as the light a surface scatters around."""


def diffuse_reflectance(brdf: torch.nn.Module) -> torch.Tensor:
    """(3,) the share of light a material scatters, read as π · f(ωᵢ, n) for light at
    :data:`INCIDENCE_DEG` from the normal n, averaged: the diffuse albedo of a Lambertian
    material, its diffuse part plus the lobes' broad shoulders otherwise; clamped to
    [0, :data:`MAX_REFLECTANCE`]. On the device of the material's buffers."""
    device = next(iter(brdf.buffers()), torch.empty(0)).device
    zenith = torch.deg2rad(torch.tensor(INCIDENCE_DEG, device=device))
    wi = torch.stack([torch.sin(zenith), torch.zeros_like(zenith), torch.cos(zenith)], -1)[None]
    wo = torch.tensor([0.0, 0.0, 1.0], device=device).expand_as(wi)
    with torch.no_grad():
        value = brdf(wi, wo)                                            # (1, k, 3)
    return (math.pi * value.reshape(-1, 3).mean(0)).clamp(0, MAX_REFLECTANCE).float()


def interreflected(images: torch.Tensor, normals: torch.Tensor, depth: torch.Tensor, mask: torch.Tensor,
                   reflectance: torch.Tensor, factor: int = FACET) -> torch.Tensor:
    """Direct images with the light the object's facets bounce to each other added.

    Args:
        images: (n, 3, H, W) direct radiance (shading, cast shadows, intensities).
        normals: (H, W, 3) unit; depth: (H, W) in view units; mask: (H, W) bool.
        reflectance: (H, W, 3) each pixel's diffuse reflectance, in [0, 1).
        factor: image pixels per facet side; H and W its multiples.

    Returns:
        (n, 3, H, W), on the device of ``images``: equal to ``images`` off the object and where
        no facet sees another (a convex surface, a plane).
    """
    h, w = mask.shape
    inside = mask.float()[None]
    cover = F.avg_pool2d(inside, factor)                                   # (1, h', w')
    facets = cover[0] >= 0.5
    if int(facets.sum()) < 2:
        return images

    def pooled(x: torch.Tensor) -> torch.Tensor:                           # (C, H, W) → (C, h', w')
        return F.avg_pool2d(x * inside, factor) / cover.clamp_min(1e-6)

    facet_normals = F.normalize(pooled(normals.permute(2, 0, 1)).permute(1, 2, 0), dim=-1)
    facet_depth = pooled(depth[None])[0] / (2 / (h - 1) * factor)          # in facet pixels
    kernel = kernel_on_device(facet_depth.double(), facet_normals.double(), facets)     # (m, m)
    rho = pooled(reflectance.permute(2, 0, 1))[:, facets].double().clamp(0, MAX_REFLECTANCE)    # (3, m)
    n = images.shape[0]
    direct = pooled(images.flatten(0, 1))[:, facets].view(n, 3, -1).permute(1, 2, 0).double()   # (3, m, n)
    eye = torch.eye(len(kernel), dtype=kernel.dtype, device=kernel.device)
    # one channel at a time: torch 2.13's batched CPU solve fails on two threads (oneMKL's DLASWP)
    radiance = torch.stack([torch.linalg.solve(eye - rho[c, :, None] * kernel, direct[c]) for c in range(3)])
    irradiance = math.pi * kernel @ radiance                               # (3, m, n)
    grid = torch.zeros(n, 3, *facets.shape, dtype=images.dtype, device=images.device)
    grid[:, :, facets] = irradiance.permute(2, 0, 1).to(images.dtype)
    weight = facets.to(images.dtype)[None, None]
    up = lambda x: F.interpolate(x, size=(h, w), mode="bilinear", align_corners=False)    # noqa: E731
    spread = up(grid) / up(weight).clamp_min(1e-6)
    received = torch.where(mask, spread, torch.zeros_like(spread))
    return images + reflectance.permute(2, 0, 1)[None] / math.pi * received

"""Scenes for the light network's training data: shapes as normal and depth maps, lights on the
upper hemisphere, and the shadows the shapes cast.

Frame: x right, y up, z toward the camera; the orthographic view covers [−1, 1]², so one
pixel is 2 / resolution units and depth is in the same units.
"""

from __future__ import annotations

import hashlib
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from unps.errors import InputError


@dataclass(frozen=True)
class ShapeMaps:
    """normals (H, W, 3) unit, depth (H, W), mask (H, W) bool; float32 tensors."""

    normals: torch.Tensor
    depth: torch.Tensor
    mask: torch.Tensor


def sample_generator(seed: int, index: int) -> torch.Generator:
    digest = hashlib.sha256(f"{seed}:{index}".encode()).digest()
    return torch.Generator().manual_seed(int.from_bytes(digest[:8], "little"))


def blob(resolution: int, generator: torch.Generator) -> ShapeMaps:
    """A smooth random blob: a dome over a star-shaped outline, with Gaussian bumps and dents."""
    u = lambda *shape: torch.rand(*shape, generator=generator)    # noqa: E731
    t = torch.linspace(-1, 1, resolution)
    y, x = -t[:, None].expand(resolution, resolution), t[None, :].expand(resolution, resolution)
    phi, rho = torch.atan2(y, x), torch.hypot(x, y)
    k = torch.arange(1, 6, dtype=torch.float32)
    outline = 0.55 + 0.35 * u(1) + ((u(5) - 0.5) * 0.4 / k * torch.cos(
        k * phi[..., None] + 2 * math.pi * u(5))).sum(-1)
    r = (rho / outline).clamp(max=1)
    height = (0.4 + 0.6 * u(1)) * outline.mean()
    z = height * torch.sqrt(1 - r ** 2)        # smooth at the centre, whatever the outline
    for _ in range(int(3 + 8 * u(1))):
        cx, cy = (u(2) - 0.5) * 1.2
        width = 0.08 + 0.3 * u(1)
        amplitude = (u(1) - 0.4) * 0.6 * width
        z = z + amplitude * torch.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * width ** 2)) * (r < 1)
    mask = rho < 0.985 * outline
    return maps_from_depth(z, mask)


def maps_from_depth(z: torch.Tensor, mask: torch.Tensor) -> ShapeMaps:
    """Normals of a height field z over [−1, 1]² (row 0 at y = 1) by central differences."""
    pitch = 2 / (z.shape[0] - 1)
    dz_dy_rows, dz_dx = torch.gradient(z, spacing=pitch)
    normals = F.normalize(torch.stack([-dz_dx, dz_dy_rows, torch.ones_like(z)], -1), dim=-1)
    return ShapeMaps(normals * mask[..., None], torch.where(mask, z, torch.zeros_like(z)), mask)


def mesh_views(folder: str | os.PathLike, resolution: int, views: int, seed: int) -> list[ShapeMaps]:
    """Normal and depth maps of every mesh in a folder (.obj, .ply) from random directions."""
    import trimesh

    from unps.synthetic.render import render_ground_truth
    from unps.synthetic.shapes import Mesh, fit_to_view

    files = sorted(p for p in Path(folder).expanduser().iterdir()
                   if p.suffix.lower() in (".obj", ".ply"))
    if not files:
        raise InputError(f"{folder}: no .obj or .ply meshes for the light network's training data")
    rng = np.random.default_rng(seed)
    out = []
    for path in files:
        loaded = trimesh.load(path, force="mesh", process=False)
        vertices = np.asarray(loaded.vertices, np.float64)
        vertices -= vertices.mean(0)
        for _ in range(views):
            rotation = trimesh.transformations.random_rotation_matrix(rand=rng.random(3))[:3, :3]
            mesh = fit_to_view(Mesh((vertices @ rotation.T).astype(np.float32),
                                    np.asarray(loaded.faces, np.int32)), extent=0.9)
            normals, depth, mask = render_ground_truth(mesh, resolution)
            depth = np.where(mask, depth * 2 / resolution, 0)       # pixels → view units
            out.append(ShapeMaps(torch.as_tensor(normals), torch.as_tensor(depth, dtype=torch.float32),
                                 torch.as_tensor(mask)))
    return out


def hemisphere_lights(count: int, max_zenith_deg: float, generator: torch.Generator) -> torch.Tensor:
    """(count, 3) unit directions uniform over the cap within ``max_zenith_deg`` of +z."""
    z = 1 - torch.rand(count, generator=generator) * (1 - math.cos(math.radians(max_zenith_deg)))
    phi = 2 * math.pi * torch.rand(count, generator=generator)
    s = torch.sqrt(1 - z ** 2)
    return torch.stack([s * torch.cos(phi), s * torch.sin(phi), z], -1)


def cast_shadows(maps: ShapeMaps, lights: torch.Tensor, steps: int = 24) -> torch.Tensor:
    """Which object pixels each light cannot see, marching the depth map toward the light.

    From each object pixel, ``steps`` samples spaced evenly over the image's diagonal are taken
    along the light's image-plane direction (nearest pixel); the ray rises by l_z / |l_xy| per
    unit of distance, and the pixel is in shadow if the object stands above it at any sample.

    Args:
        lights: (n, 3) unit directions.

    Returns:
        (n, H, W) bool.
    """
    h, w = maps.depth.shape
    pitch = 2 / (h - 1)
    rows, cols = torch.nonzero(maps.mask, as_tuple=True)
    planar = lights[:, :2].norm(dim=-1).clamp_min(1e-6)
    step = torch.stack([-lights[:, 1], lights[:, 0]], -1) / planar[:, None]   # (row, col) per pixel
    distance = torch.linspace(1, (h ** 2 + w ** 2) ** 0.5, steps)            # in pixels
    r = (rows[None, None] + distance[None, :, None] * step[:, 0, None, None]).round().int()
    c = (cols[None, None] + distance[None, :, None] * step[:, 1, None, None]).round().int()
    inside = (r >= 0) & (r < h) & (c >= 0) & (c < w)
    flat = (r.clamp(0, h - 1) * w + c.clamp(0, w - 1))
    surface = torch.where(maps.mask, maps.depth, torch.full_like(maps.depth, -torch.inf)).flatten()
    ray = maps.depth[rows, cols][None, None] + (distance * pitch)[None, :, None] * \
        (lights[:, 2] / planar)[:, None, None]
    blocked = (inside & (surface[flat] > ray + 1e-3)).any(1)                  # (n, P)
    out = torch.zeros(len(lights), h, w, dtype=torch.bool)
    out[:, rows, cols] = blocked
    return out

"""Training data for the light network, generated on the fly.

A sample is a function of (seed, index): a shape (a random blob, or a view of a mesh from a
folder), a material (analytic, MERL table or MERL neural fit, mixed by weight), 64 lights on the
upper hemisphere of which ``images`` are drawn, attached and cast shadows, per-image
intensities U(0.2, 2) shared by RGB, and the paper's perturbation U(−0.025, 0.025).

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
from torch.utils.data import Dataset

from unps.errors import InputError
from unps.lightnet.brdf import random_analytic, read_merl_binary, read_neural_brdf


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


def shade(maps: ShapeMaps, brdf, lights: torch.Tensor, intensities: torch.Tensor,
          albedo: torch.Tensor | None = None, shadows: bool = True) -> torch.Tensor:
    """Radiance e · f(l, v) · max(n·l, 0), in shadow 0.

    Args:
        lights: (n, 3); intensities: (n,); albedo: optional (H, W) multiplier.

    Returns:
        (n, 3, H, W) float32.
    """
    m = maps.mask
    n = maps.normals[m]                                               # (P, 3)
    tangent = F.normalize(torch.linalg.cross(torch.where(n[:, :1].abs() < 0.9,
                                                         torch.tensor([1.0, 0, 0]),
                                                         torch.tensor([0, 1.0, 0])), n), dim=-1)
    bitangent = torch.linalg.cross(n, tangent)
    frame = torch.stack([tangent, bitangent, n], 1)                   # (P, 3, 3) rows
    wi = torch.einsum("pij,lj->lpi", frame, lights)                   # (L, P, 3)
    wo = frame[:, :, 2][None].expand_as(wi)                           # view (0, 0, 1)
    with torch.no_grad():
        value = brdf(wi, wo) * wi[..., 2:].clamp_min(0)               # (L, P, 3)
    if albedo is not None:
        value = value * albedo[m][None, :, None]
    value = value * intensities[:, None, None]
    if shadows:
        value = value * (~cast_shadows(maps, lights)[:, m])[..., None]
    images = torch.zeros(len(lights), *m.shape, 3)
    images[:, m] = value
    return images.permute(0, 3, 1, 2)


class MaterialBank:
    """Draws materials: analytic lobes, MERL ``.binary`` tables, MERL neural fits, by weight.

    Args:
        analytic: weight of random analytic materials (always available).
        merl_dir, merl: a folder of ``.binary`` files and its weight.
        neural_dir, neural: a folder of neural fits (``.h5``) and its weight.
    """

    def __init__(self, analytic: float = 1.0, merl_dir: str | None = None, merl: float = 0.0,
                 neural_dir: str | None = None, neural: float = 0.0):
        self.families, self.weights = ["analytic"], [analytic]
        self.files = {}
        for family, folder, weight, suffix in (("merl", merl_dir, merl, ".binary"),
                                               ("neural", neural_dir, neural, ".h5")):
            if weight > 0:
                if not folder or not Path(folder).expanduser().is_dir():
                    raise InputError(f"materials: {family} has weight {weight} but its folder "
                                     f"{folder!r} does not exist")
                files = sorted(Path(folder).expanduser().glob(f"*{suffix}"))
                if not files:
                    raise InputError(f"{folder}: no {suffix} files")
                self.files[family] = files
                self.families.append(family)
                self.weights.append(weight)
        if sum(self.weights) <= 0:
            raise InputError("materials: the weights must not all be zero")
        self._loaded = {}

    def draw(self, generator: torch.Generator, family: str | None = None):
        """A random material (of ``family`` if given); returns (family, brdf)."""
        if family is None:
            p = torch.tensor(self.weights, dtype=torch.float64)
            family = self.families[int(torch.multinomial(p / p.sum(), 1, generator=generator))]
        if family == "analytic":
            return family, random_analytic(generator)
        files = self.files[family]
        path = files[int(torch.randint(len(files), (1,), generator=generator))]
        if path not in self._loaded:
            self._loaded[path] = (read_merl_binary if family == "merl" else read_neural_brdf)(path)
        return family, self._loaded[path]


class LightDataset(Dataset):
    """Synthetic photometric-stereo stacks with their lights, item i a function of (seed, i).

    Args:
        length: items per epoch.
        resolution: image side (a multiple of 32).
        images: images per sample, drawn from ``lights_per_shape`` lights.
        max_zenith_deg: the light cap.
        materials: a :class:`MaterialBank`.
        meshes: optional shape maps from :func:`mesh_views`, used for ``mesh_fraction`` of samples.
        texture: largest relative albedo variation over the surface.
        perturbation: half-width of the uniform noise added to images scaled to a 99th
            percentile of 1.
        saturation: the level, in units of that 99th percentile, where the simulated camera
            saturates (measured mirror-like materials otherwise put highlights hundreds of times
            above the rest of the stack); None keeps every value.
        family: force one material family (for per-family validation).
        offset: item i is sample ``offset + i`` (a resumed run continues where it stopped).
    """

    def __init__(self, length: int, resolution: int = 128, images: int = 32,
                 lights_per_shape: int = 64, max_zenith_deg: float = 70.0,
                 materials: MaterialBank | None = None, meshes: list[ShapeMaps] | None = None,
                 mesh_fraction: float = 0.0, texture: float = 0.3, perturbation: float = 0.025,
                 intensity_range: tuple[float, float] = (0.2, 2.0), saturation: float | None = 4.0,
                 seed: int = 0, family: str | None = None, offset: int = 0):
        if resolution % 32 or resolution < 32:
            raise InputError(f"resolution must be a multiple of 32, got {resolution}")
        if not 1 <= images <= lights_per_shape:
            raise InputError(f"images per sample must lie in 1…{lights_per_shape}, got {images}")
        self.length, self.resolution, self.images = length, resolution, images
        self.lights_per_shape, self.max_zenith_deg = lights_per_shape, max_zenith_deg
        self.materials = materials or MaterialBank()
        self.meshes, self.mesh_fraction = meshes or [], mesh_fraction if meshes else 0.0
        self.texture, self.perturbation = texture, perturbation
        self.intensity_range, self.seed, self.family = intensity_range, seed, family
        self.offset, self.saturation = offset, saturation

    def __len__(self) -> int:
        return self.length

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        g = sample_generator(self.seed, self.offset + index)
        u = lambda *shape: torch.rand(*shape, generator=g)           # noqa: E731
        if self.meshes and float(u(1)) < self.mesh_fraction:
            maps = self.meshes[int(torch.randint(len(self.meshes), (1,), generator=g))]
            if maps.depth.shape[0] != self.resolution:
                raise InputError(f"mesh views are {maps.depth.shape[0]} px, data {self.resolution} px")
        else:
            maps = blob(self.resolution, g)
        family, brdf = self.materials.draw(g, self.family)
        lights = hemisphere_lights(self.lights_per_shape, self.max_zenith_deg, g)
        pick = torch.randperm(self.lights_per_shape, generator=g)[: self.images]
        lights = lights[pick]
        lo, hi = self.intensity_range
        intensities = lo + (hi - lo) * u(self.images)
        albedo = None
        if self.texture > 0:
            coarse = torch.rand(1, 1, 6, 6, generator=g) - 0.5
            albedo = 1 + self.texture * float(u(1)) * 2 * F.interpolate(
                coarse, size=(self.resolution,) * 2, mode="bicubic", align_corners=True)[0, 0]
        images = shade(maps, brdf, lights, intensities, albedo)
        values = images[:, :, maps.mask].flatten()
        level = torch.quantile(values[:: max(1, len(values) // 8192)], 0.99).clamp_min(1e-8)
        images = images / level
        if self.saturation is not None:
            images = images.clamp(max=self.saturation)
        images = images + self.perturbation * (2 * torch.rand(images.shape, generator=g) - 1)
        images = images * maps.mask
        return {"images": images.float(), "mask": maps.mask[None].float(),
                "directions": lights.float(), "intensities": intensities.float(),
                "family": ["analytic", "merl", "neural"].index(family)}

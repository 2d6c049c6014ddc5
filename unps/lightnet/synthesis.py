"""Training data for the light network, generated on the fly.

A sample is a function of (seed, index): a shape (one of the families of
:data:`unps.lightnet.shapes.SHAPES`, or a view of a mesh from a folder), a material (analytic,
MERL table or MERL neural fit, mixed by weight), 64 lights in one of the rig layouts of
:mod:`unps.lightnet.rig` of which ``images`` are drawn, attached and cast shadows, per-image
intensities U(0.2, 2) shared by RGB, and then either the paper's perturbation U(−0.025, 0.025) or
a simulated camera (exposure, noise, saturation, 8/16-bit storage).

Frame: x right, y up, z toward the camera; the orthographic view covers [−1, 1]², so one
pixel is 2 / resolution units and depth is in the same units.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch.utils.data import Dataset

from unps.errors import InputError
from unps.lightnet.materials import FAMILIES, MaterialBank, painted, shade
from unps.lightnet.rig import LAYOUTS, Camera, Exposure, draw_lights, expose, record
from unps.lightnet.shapes import SHAPES, ShapeMaps, check_weights, draw_shape, sample_generator


class LightDataset(Dataset):
    """Synthetic photometric-stereo stacks with their lights, item i a function of (seed, i).

    Args:
        length: items per epoch.
        resolution: image side (a multiple of 32).
        images: images per sample, drawn from ``lights_per_shape`` lights.
        max_zenith_deg: the light cap.
        materials: a :class:`MaterialBank`.
        meshes: optional shape maps from :func:`unps.lightnet.meshes.mesh_views`, used for
            ``mesh_fraction`` of samples.
        texture: largest relative albedo variation over the surface (smooth).
        paint: share of samples with painted patches of other colours (:func:`painted`).
        perturbation: half-width of the uniform noise added to images scaled to a 99th
            percentile of 1.
        saturation: the level, in units of that 99th percentile, where the simulated camera
            saturates (measured mirror-like materials otherwise put highlights hundreds of times
            above the rest of the stack); None keeps every value.
        shapes: weights of the shape families of :data:`~unps.lightnet.shapes.SHAPES`
            (default: blobs only).
        layouts: weights of the light layouts of :data:`~unps.lightnet.rig.LAYOUTS`
            (default: the uniform cap only).
        camera: a simulated :class:`~unps.lightnet.rig.Camera`; it replaces ``saturation`` and
            ``perturbation``. None keeps them.
        family: force one material family (for per-family validation).
        shape: force one shape family (for per-family validation).
        offset: item i is sample ``offset + i`` (a resumed run continues where it stopped).
        device: where a sample is rendered (shading, cast shadows, camera) and returned. Its
            random draws are made on the CPU in every case, so a sample is the same function of
            (seed, index) on any device: bit for bit on the CPU, to float rounding on a GPU.
    """

    def __init__(self, length: int, resolution: int = 128, images: int = 32,
                 lights_per_shape: int = 64, max_zenith_deg: float = 70.0,
                 materials: MaterialBank | None = None, meshes: list[ShapeMaps] | None = None,
                 mesh_fraction: float = 0.0, texture: float = 0.3, perturbation: float = 0.025,
                 intensity_range: tuple[float, float] = (0.2, 2.0), saturation: float | None = 4.0,
                 shapes: dict[str, float] | None = None, layouts: dict[str, float] | None = None,
                 camera: Camera | None = None, seed: int = 0, family: str | None = None,
                 shape: str | None = None, offset: int = 0, paint: float = 0.0,
                 device: torch.device = torch.device("cpu")):
        if resolution % 32 or resolution < 32:
            raise InputError(f"resolution must be a multiple of 32, got {resolution}")
        if not 1 <= images <= lights_per_shape:
            raise InputError(f"images per sample must lie in 1…{lights_per_shape}, got {images}")
        if not 0 <= paint <= 1:
            raise InputError(f"paint is a share of the samples, in 0…1; got {paint}")
        self.shapes = dict(shapes) if shapes else {"blob": 1.0}
        self.layouts = dict(layouts) if layouts else {"cap": 1.0}
        check_weights(self.shapes, SHAPES, "shape families")
        check_weights(self.layouts, LAYOUTS, "light layouts")
        if shape is not None and shape not in SHAPES:
            raise InputError(f"shape family {shape!r} unknown; expected one of {list(SHAPES)}")
        self.camera, self.shape = camera, shape
        self.length, self.resolution, self.images = length, resolution, images
        self.lights_per_shape, self.max_zenith_deg = lights_per_shape, max_zenith_deg
        self.materials = materials or MaterialBank()
        self.meshes, self.mesh_fraction = meshes or [], mesh_fraction if meshes else 0.0
        self.texture, self.paint, self.perturbation = texture, paint, perturbation
        self.intensity_range, self.seed, self.family = intensity_range, seed, family
        self.offset, self.saturation, self.device = offset, saturation, torch.device(device)

    def __len__(self) -> int:
        return self.length

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        """Sample ``index``, rendered on the dataset's device."""
        return render(self.draw(index), self.device)

    def draw(self, index: int) -> Scene:
        """Every random draw of sample ``index``, made on the CPU from its own generator."""
        if not 0 <= index < self.length:     # also ends ``for sample in dataset``
            raise IndexError(f"sample {index} of a dataset of {self.length}")
        g = sample_generator(self.seed, self.offset + index)
        u = lambda *shape: torch.rand(*shape, generator=g)           # noqa: E731
        if self.meshes and self.shape is None and float(u(1)) < self.mesh_fraction:
            maps = self.meshes[int(torch.randint(len(self.meshes), (1,), generator=g))]
            if maps.depth.shape[0] != self.resolution:
                raise InputError(f"mesh views are {maps.depth.shape[0]} px, data {self.resolution} px")
        else:
            maps = draw_shape(self.shapes, self.resolution, g, self.shape)
        family, brdf = self.materials.draw(g, self.family)
        lights = draw_lights(self.layouts, self.lights_per_shape, self.max_zenith_deg, g)
        pick = torch.randperm(self.lights_per_shape, generator=g)[: self.images]
        lo, hi = self.intensity_range
        intensities = lo + (hi - lo) * u(self.images)
        albedo = None
        if self.texture > 0:
            coarse = torch.rand(1, 1, 6, 6, generator=g) - 0.5
            albedo = 1 + self.texture * float(u(1)) * 2 * F.interpolate(
                coarse, size=(self.resolution,) * 2, mode="bicubic", align_corners=True)[0, 0]
        if self.paint > 0 and float(u(1)) < self.paint:
            paint = painted(self.resolution, g)
            albedo = paint if albedo is None else albedo[..., None] * paint
        shape = (self.images, 3, self.resolution, self.resolution)
        if self.camera is not None:
            return Scene(maps, brdf, family, lights[pick], intensities, albedo,
                         exposure=expose(self.camera, shape, g))
        return Scene(maps, brdf, family, lights[pick], intensities, albedo, saturation=self.saturation,
                     perturbation=self.perturbation * (2 * torch.rand(shape, generator=g) - 1))


@dataclass(frozen=True)
class Scene:
    """One sample before it is rendered: every random draw it needs, on the CPU.

    Attributes:
        maps: the shape; brdf: its material (of ``family``); lights: (n, 3) unit directions;
        intensities: (n,); albedo: (H, W) or (H, W, 3) multiplier, or None.
        exposure: the simulated camera's draws, or None for the paper's perturbation:
        saturation: the level the stack is clipped at (None: none), and
        perturbation: (n, 3, H, W) the noise added after.
    """

    maps: ShapeMaps
    brdf: torch.nn.Module
    family: str
    lights: torch.Tensor
    intensities: torch.Tensor
    albedo: torch.Tensor | None
    exposure: Exposure | None = None
    saturation: float | None = None
    perturbation: torch.Tensor | None = None


def render(scene: Scene, device: torch.device) -> dict[str, torch.Tensor]:
    """A sample of :class:`LightDataset` from its draws, computed on ``device``: shading, cast
    shadows, scaling to a 99th percentile of 1, then the camera (or the perturbation).

    Returns:
        ``images`` (n, 3, H, W), ``mask`` (1, H, W), ``directions`` (n, 3), ``intensities`` (n,),
        float32 on ``device``; ``family``, the index of the material family.
    """
    maps = scene.maps.to(device)
    lights, intensities = scene.lights.to(device), scene.intensities.to(device)
    albedo = None if scene.albedo is None else scene.albedo.to(device)
    images = shade(maps, scene.brdf.to(device), lights, intensities, albedo)
    values = images[:, :, maps.mask].flatten()
    level = torch.quantile(values[:: max(1, len(values) // 8192)], 0.99).clamp_min(1e-8)
    images = images / level
    if scene.exposure is not None:
        images = record(images, scene.exposure)
    else:
        if scene.saturation is not None:
            images = images.clamp(max=scene.saturation)
        images = images + scene.perturbation.to(device)
    images = images * maps.mask
    return {"images": images.float(), "mask": maps.mask[None].float(),
            "directions": lights.float(), "intensities": intensities.float(),
            "family": FAMILIES.index(scene.family)}

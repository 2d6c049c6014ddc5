"""Training data for the light network, generated on the fly.

A sample is a function of (seed, index): a shape (one of the families of
:data:`unps.lightnet.shapes.SHAPES`, or a view of a mesh from a folder), a material (analytic,
MERL table or MERL neural fit, mixed by weight; on a share of the samples a second one in patches),
64 lights in one of the rig layouts of
:mod:`unps.lightnet.rig` of which ``images`` are drawn, attached and cast shadows (on a share of the
samples interreflections, :mod:`unps.lightnet.interreflection`), per-image
intensities U(0.2, 2) shared by RGB, and then either the paper's perturbation U(−0.025, 0.025) or
a simulated camera (exposure, noise, saturation, 8/16-bit storage).

Frame: x right, y up, z toward the camera; the orthographic view covers [−1, 1]², so one
pixel is 2 / resolution units and depth is in the same units.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, is_dataclass, replace

import torch
import torch.nn.functional as F
from torch.utils.data import Dataset

from unps.device import to_device
from unps.errors import InputError
from unps.geometry import ShadowPlan, march_shadows
from unps.lightnet.brdf import AnalyticBRDF
from unps.lightnet.interreflection import MAX_REFLECTANCE, diffuse_reflectance, interreflected
from unps.lightnet.materials import (FAMILIES, LobeTable, MaterialBank, coated, darkened, lobe_pixels,
                                     painted, shade, shade_batch)
from unps.lightnet.rig import LAYOUTS, Camera, Exposure, Exposures, draw_lights, expose, record, record_batch
from unps.lightnet.shapes import (SHAPES, ShapeMaps, cast_shadows, check_weights, draw_shape, plan_shadows,
                                  sample_generator)

DARKEST_SECOND = -2.0
"""A second material's diffuse albedo is its drawn one times 10^(DARKEST_SECOND · U(0, 1)): from as
drawn down to a hundredth, so half of them are dark glossy ones, black in an 8-bit image but where
their highlights fall, as the dark materials of real objects are."""

ROOM_LIGHT_MAX = 0.04
"""The brightest room light drawn (:func:`with_room_light`): about 2 % of a stack's 99th percentile."""
LEVEL_SAMPLES = 8192
"""About this many of a stack's object values (evenly spaced) set its 99th percentile."""


def check_share(name: str, share: float) -> float:
    """``share``, a share of the training samples that setting ``name`` applies to.

    Raises:
        InputError: ``share`` is not in [0, 1]; the message names the setting.
    """
    if not 0 <= share <= 1:
        raise InputError(f"{name} is a share of the samples, in 0…1; got {share}")
    return share


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
        second_material: share of samples with a second material, drawn from ``materials`` as the
            first, its diffuse albedo darkened by up to a hundredth (:data:`DARKEST_SECOND`), laid
            on in patches (:func:`~unps.lightnet.materials.coated`): objects of two materials, a
            dark glossy one beside a bright one, as many captures are.
        interreflection: share of samples whose facets light each other
            (:func:`~unps.lightnet.interreflection.interreflected`): cavities and the foot of a
            wall filled with light bounced off the rest of the object, as in real captures.
        room_light: share of samples that a room lights as well (:func:`with_room_light`), at a
            level drawn from U(0, :data:`ROOM_LIGHT_MAX`): light that no dark frame took out, the
            same in every image, as photographs outside a blacked-out rig hold.
        narrowed_intensities: share of samples whose lights' intensities spread less than
            ``intensity_range``: the range shrunk toward 1 by a factor drawn from U(0, 1), from
            every light equally bright to the whole range, as rigs of matched lamps give.
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
            random draws are made on the CPU, but for the simulated camera's noise: off the CPU,
            the device draws it from a seed drawn in its place (:func:`~unps.lightnet.rig.expose`),
            so a sample there is the CPU's sample to float rounding but for its noise and storage
            format, and each a function of (seed, index).
    """

    def __init__(self, length: int, resolution: int = 128, images: int = 32,
                 lights_per_shape: int = 64, max_zenith_deg: float = 70.0,
                 materials: MaterialBank | None = None, meshes: list[ShapeMaps] | None = None,
                 mesh_fraction: float = 0.0, texture: float = 0.3, perturbation: float = 0.025,
                 intensity_range: tuple[float, float] = (0.2, 2.0), saturation: float | None = 4.0,
                 shapes: dict[str, float] | None = None, layouts: dict[str, float] | None = None,
                 camera: Camera | None = None, seed: int = 0, family: str | None = None,
                 shape: str | None = None, offset: int = 0, paint: float = 0.0,
                 second_material: float = 0.0, interreflection: float = 0.0,
                 narrowed_intensities: float = 0.0, room_light: float = 0.0,
                 device: torch.device = torch.device("cpu")):
        if resolution % 32 or resolution < 32:
            raise InputError(f"resolution must be a multiple of 32, got {resolution}")
        if not 1 <= images <= lights_per_shape:
            raise InputError(f"images per sample must lie in 1…{lights_per_shape}, got {images}")
        shares = dict(paint=paint, second_material=second_material, interreflection=interreflection,
                      narrowed_intensities=narrowed_intensities, room_light=room_light)
        for name, share in shares.items():
            check_share(name, share)
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
        self.second_material, self.interreflection = second_material, interreflection
        self.intensity_range, self.seed, self.family = intensity_range, seed, family
        self.narrowed_intensities, self.room_light = narrowed_intensities, room_light
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
        if self.narrowed_intensities > 0 and float(u(1)) < self.narrowed_intensities:
            spread = float(u(1))
            lo, hi = 1 + spread * (lo - 1), 1 + spread * (hi - 1)
        intensities = lo + (hi - lo) * u(self.images)
        albedo = None
        if self.texture > 0:
            coarse = torch.rand(1, 1, 6, 6, generator=g) - 0.5
            albedo = 1 + self.texture * float(u(1)) * 2 * F.interpolate(
                coarse, size=(self.resolution,) * 2, mode="bicubic", align_corners=True)[0, 0]
        if self.paint > 0 and float(u(1)) < self.paint:
            paint = painted(self.resolution, g)
            albedo = paint if albedo is None else albedo[..., None] * paint
        second = coat = None
        if self.second_material > 0 and float(u(1)) < self.second_material:
            second = darkened(self.materials.draw(g)[1], 10 ** (DARKEST_SECOND * float(u(1))))
            coat = coated(self.resolution, g) * maps.mask
        bounces = self.interreflection > 0 and float(u(1)) < self.interreflection
        room = ROOM_LIGHT_MAX * float(u(1)) if self.room_light > 0 and float(u(1)) < self.room_light else 0.0
        shape = (self.images, 3, self.resolution, self.resolution)
        if self.camera is not None:
            return Scene(maps, brdf, family, lights[pick], intensities, albedo, second, coat, bounces,
                         room, exposure=expose(self.camera, shape, g, defer_noise=self.device.type != "cpu"))
        return Scene(maps, brdf, family, lights[pick], intensities, albedo, second, coat, bounces, room,
                     saturation=self.saturation,
                     perturbation=self.perturbation * (2 * torch.rand(shape, generator=g) - 1))


@dataclass(frozen=True)
class Scene:
    """One sample before it is rendered: every random draw it needs, on the CPU.

    Attributes:
        maps: the shape; brdf: its material (of ``family``); lights: (n, 3) unit directions;
        intensities: (n,); albedo: (H, W) or (H, W, 3) multiplier, or None.
        second: a second material, or None; coat: (H, W) float, 1 where it lies (None with it).
        bounces: whether the object's facets light each other (interreflections).
        room: the level of a room's light (:func:`with_room_light`; 0: none).
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
    second: torch.nn.Module | None = None
    coat: torch.Tensor | None = None
    bounces: bool = False
    room: float = 0.0
    exposure: Exposure | None = None
    saturation: float | None = None
    perturbation: torch.Tensor | None = None


def render(scene: Scene, device: torch.device) -> dict[str, torch.Tensor]:
    """A sample of :class:`LightDataset` from its draws, computed on ``device``: shading, cast
    shadows, interreflections (where drawn), scaling to a 99th percentile of 1, then the camera (or
    the perturbation).

    Returns:
        ``images`` (n, 3, H, W), ``mask`` (1, H, W), ``directions`` (n, 3), ``intensities`` (n,),
        float32 on ``device``; ``family``, the index of the material family.
    """
    maps = scene.maps.to(device)
    lights, intensities = scene.lights.to(device), scene.intensities.to(device)
    albedo = None if scene.albedo is None else scene.albedo.to(device)
    if scene.second is None:
        images = shade(maps, scene.brdf.to(device), lights, intensities, albedo)
    else:
        first, second = (shade(maps, brdf.to(device), lights, intensities, albedo, shadows=False)
                         for brdf in (scene.brdf, scene.second))
        images = torch.lerp(first, second, scene.coat.to(device)) * ~cast_shadows(maps, lights)[:, None]
    if scene.bounces:
        reflectance = reflectance_map(scene).to(device)
        images = interreflected(images, maps.normals, maps.depth, maps.mask, reflectance)
    if scene.room:
        images = with_room_light(images, intensities, torch.tensor(scene.room, device=device))
    values = images[:, :, maps.mask].flatten()
    level = torch.quantile(values[:: max(1, len(values) // LEVEL_SAMPLES)], 0.99).clamp_min(1e-8)
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


@dataclass(frozen=True)
class SceneBatch:
    """B samples' draws packed into some twenty tensors, with whatever decides the work of rendering
    them (the shadow march, the values that set each level) worked out beforehand: a worker hands
    a batch over in one go rather than as hundreds of small tensors, each sent on its own, and the
    training process only queues work on its device.

    Attributes:
        normals: (B, H, W, 3); lights: (B, n, 3); intensities: (B, n); albedo: (B, H, W, 3).
        shadows: the shadow march, the (B, H, W) depth and mask within.
        level_index, level_valid: (B, L) which values of each stack set its level
            (:func:`level_picks`).
        lobes: the analytic materials; others: the other materials, by sample; family: (B,) each
            sample's material family, its index in :data:`~unps.lightnet.materials.FAMILIES`.
        pixels: the object pixels of the samples whose material is analytic
            (:func:`~unps.lightnet.materials.lobe_pixels`): those the lobes shade.
        second_lobes, second_others, coat, second_pixels: the second materials as ``lobes``,
            ``others`` and ``pixels`` (a sample without one: a row of no light and no pixels; the
            pixels only those under its coat), and (B, H, W) where each lies; None when no sample
            of the batch has one.
        bounces: (B,) bool, the samples with interreflections; reflectance: (B, H, W, 3) their
            pixels' diffuse reflectance (:func:`reflectance_map`), None when no sample bounces.
        room: (B,) each sample's room light (:func:`with_room_light`; 0: none).
        exposures: the camera's draws, packed (or None); saturation, perturbation: (B, n, 3, H, W)
            the paper's noise otherwise.
    """

    normals: torch.Tensor
    lights: torch.Tensor
    intensities: torch.Tensor
    albedo: torch.Tensor
    shadows: ShadowPlan
    level_index: torch.Tensor
    level_valid: torch.Tensor
    lobes: LobeTable
    others: dict[int, torch.nn.Module]
    family: torch.Tensor
    pixels: torch.Tensor
    second_lobes: LobeTable | None
    second_others: dict[int, torch.nn.Module]
    coat: torch.Tensor | None
    second_pixels: torch.Tensor | None
    bounces: torch.Tensor
    reflectance: torch.Tensor | None
    room: torch.Tensor
    exposures: Exposures | None
    saturation: float | None
    perturbation: torch.Tensor | None

    def pin_memory(self) -> SceneBatch:
        """This batch with its tensors in page-locked memory, so that :func:`render_batch` queues
        its copies to the GPU without waiting (the loader's ``pin_memory``, done in a thread of
        the training process as batches arrive)."""
        return map_tensors(self, torch.Tensor.pin_memory)

    @classmethod
    def of(cls, scenes: list[Scene]) -> SceneBatch:
        """The draws of ``scenes`` (all of one dataset), packed and planned."""
        brdfs = [scene.brdf for scene in scenes]
        camera = scenes[0].exposure is not None
        size = scenes[0].maps.depth.shape
        mask = torch.stack([scene.maps.mask for scene in scenes])
        lights = torch.stack([scene.lights for scene in scenes])
        seconds = [scene.second for scene in scenes]
        two = any(second is not None for second in seconds)
        coat = torch.stack([torch.zeros(size) if scene.coat is None else scene.coat for scene in scenes]) \
            if two else None
        bounces = torch.tensor([scene.bounces for scene in scenes])
        reflectance = torch.stack([reflectance_map(scene) if scene.bounces else torch.zeros(*size, 3)
                                   for scene in scenes]) if bounces.any() else None
        return cls(torch.stack([scene.maps.normals for scene in scenes]), lights,
                   torch.stack([scene.intensities for scene in scenes]),
                   torch.stack([albedo_rgb(scene.albedo, size) for scene in scenes]),
                   plan_shadows(torch.stack([scene.maps.depth for scene in scenes]), mask, lights),
                   *level_picks(mask, lights.shape[1]),
                   LobeTable.of(brdfs),
                   {i: brdf for i, brdf in enumerate(brdfs) if not isinstance(brdf, AnalyticBRDF)},
                   torch.tensor([FAMILIES.index(scene.family) for scene in scenes]),
                   lobe_pixels(mask, brdfs),
                   LobeTable.of(seconds) if two else None,
                   {i: brdf for i, brdf in enumerate(seconds)
                    if brdf is not None and not isinstance(brdf, AnalyticBRDF)},
                   coat, lobe_pixels(mask & (coat > 0), seconds) if two else None, bounces, reflectance,
                   torch.tensor([scene.room for scene in scenes], dtype=torch.float32),
                   Exposures.of([scene.exposure for scene in scenes]) if camera else None,
                   scenes[0].saturation,
                   None if camera else torch.stack([scene.perturbation for scene in scenes]))


def render_batch(batch: SceneBatch, device: torch.device) -> dict[str, torch.Tensor]:
    """B samples rendered at once on ``device``: :func:`render` of each, stacked (to float
    rounding), as a few hundred kernels for the whole batch, none of them waited on.

    Returns:
        ``images`` (B, n, 3, H, W), ``mask`` (B, 1, H, W), ``directions`` (B, n, 3),
        ``intensities`` (B, n), float32, and ``family`` (B,) int64, all on ``device``.
    """
    to = lambda x: to_device(x, device)     # noqa: E731
    mask = to(batch.shadows.mask)
    normals, lights, intensities, albedo = (to(x) for x in (batch.normals, batch.lights, batch.intensities,
                                                            batch.albedo))
    shadows = march_shadows(batch.shadows, device)
    images = shade_batch(normals, mask, to(batch.pixels), batch.lobes.to(device), batch.others, lights,
                         intensities, albedo, shadows)
    if batch.coat is not None:
        second = shade_batch(normals, mask, to(batch.second_pixels), batch.second_lobes.to(device),
                             batch.second_others, lights, intensities, albedo, shadows)
        images = torch.lerp(images, second, to(batch.coat)[:, None, None])
    if batch.reflectance is not None:
        depth, reflectance = to(batch.shadows.depth), to(batch.reflectance)
        images = torch.stack([interreflected(images[b], normals[b], depth[b], mask[b], reflectance[b])
                              if bounce else images[b] for b, bounce in enumerate(batch.bounces.tolist())])
    if bool(batch.room.any()):                 # on the CPU: no wait on the device
        images = with_room_light(images, intensities, to(batch.room))
    images = images / stack_levels(images, to(batch.level_index), to(batch.level_valid))
    if batch.exposures is not None:
        images = record_batch(images, batch.exposures)
    else:
        if batch.saturation is not None:
            images = images.clamp(max=batch.saturation)
        images = images + to(batch.perturbation)
    mask = mask[:, None]
    return {"images": images * mask[:, None], "mask": mask.float(), "directions": to(batch.lights.float()),
            "intensities": to(batch.intensities.float()),
            "family": to(batch.family)}


def with_room_light(images: torch.Tensor, intensities: torch.Tensor, level: torch.Tensor) -> torch.Tensor:
    """``images`` with a room's light added: the same in every image, ``level`` × the mean over
    the stack of each image divided by its light's intensity — the object under a surround as
    bright as its lamps on average, shaded and shadowed as they shade it.

    Args:
        images: (..., n, 3, H, W) radiance; intensities: (..., n); level: (...) ≥ 0.
    """
    surround = (images / intensities[..., None, None, None]).mean(-4, keepdim=True)
    return images + level[..., None, None, None, None] * surround


def map_tensors(item, function):
    """``item`` with ``function`` applied to each tensor in it, in its dataclasses and tuples at any
    depth; everything else (numbers, strings, modules, dicts) kept as it is."""
    if isinstance(item, torch.Tensor):
        return function(item)
    if is_dataclass(item) and not isinstance(item, type):
        return replace(item, **{f.name: map_tensors(getattr(item, f.name), function) for f in fields(item)})
    if isinstance(item, tuple):
        return tuple(map_tensors(value, function) for value in item)
    return item


def reflectance_map(scene: Scene) -> torch.Tensor:
    """(H, W, 3) the diffuse reflectance of each pixel of a scene
    (:func:`~unps.lightnet.interreflection.diffuse_reflectance` of its material, or of its two
    laid in their coat, times its albedo multiplier), clamped to
    [0, :data:`~unps.lightnet.interreflection.MAX_REFLECTANCE`]; on the CPU."""
    size = scene.maps.depth.shape
    reflectance = diffuse_reflectance(scene.brdf).expand(*size, 3)
    if scene.second is not None:
        reflectance = torch.lerp(reflectance, diffuse_reflectance(scene.second).expand(*size, 3),
                                 scene.coat[..., None])
    return (reflectance * albedo_rgb(scene.albedo, size)).clamp(0, MAX_REFLECTANCE)


def albedo_rgb(albedo: torch.Tensor | None, size: torch.Size) -> torch.Tensor:
    """A scene's albedo multiplier as (H, W, 3): ones where it has none."""
    if albedo is None:
        return torch.ones(*size, 3)
    return albedo[..., None].expand(*size, 3) if albedo.dim() == 2 else albedo


def level_picks(mask: torch.Tensor, images: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Which values set each stack's level in :func:`render`: every k-th of its object values in
    (image, channel, pixel) order, k chosen for about :data:`LEVEL_SAMPLES` of them.

    Args:
        mask: (B, H, W) bool; images: n, the images per stack.

    Returns:
        (B, L) int64 flat indices into each (n, 3, H, W) stack, and (B, L) bool, which of them
        count (stacks with fewer picks are padded).
    """
    pixels = mask.flatten(1)
    picks = []
    for inside in pixels:
        where = torch.nonzero(inside).flatten()
        total = images * 3 * len(where)
        taken = torch.arange(0, total, max(1, total // LEVEL_SAMPLES))
        picks.append(taken // len(where) * pixels.shape[1] + where[taken % len(where)] if len(where)
                     else taken)
    longest = max(len(pick) for pick in picks)
    return (torch.stack([F.pad(pick, (0, longest - len(pick))) for pick in picks]),
            torch.stack([torch.arange(longest) < len(pick) for pick in picks]))


def stack_levels(images: torch.Tensor, index: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """(B, 1, 1, 1, 1) each stack's 99th percentile, as :func:`render` takes it, of the (B, n, 3,
    H, W) ``images`` at the :func:`level_picks` (on their device); 1 for an empty stack."""
    values = torch.where(valid, images.flatten(1).gather(1, index), torch.nan)
    level = torch.nanquantile(values, 0.99, dim=1).nan_to_num(1.0).clamp_min(1e-8)
    return level.view(-1, 1, 1, 1, 1)

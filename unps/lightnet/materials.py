"""Materials for the light network's training data, and shading a shape with one.

Frame: x right, y up, z toward the camera; the view is (0, 0, 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from unps.device import to_device
from unps.errors import InputError
from unps.lightnet.brdf import (AnalyticBRDF, ggx_lobe, random_analytic, random_measured, read_merl_binary,
                                read_neural_brdf)
from unps.lightnet.shapes import ShapeMaps, cast_shadows


def shade(maps: ShapeMaps, brdf, lights: torch.Tensor, intensities: torch.Tensor,
          albedo: torch.Tensor | None = None, shadows: bool = True) -> torch.Tensor:
    """Radiance e · f(l, v) · max(n·l, 0), in shadow 0.

    Args:
        lights: (n, 3); intensities: (n,); albedo: optional (H, W) or (H, W, 3) multiplier; all on
            the device of ``maps`` and ``brdf``.

    Returns:
        (n, 3, H, W) float32, on that device.
    """
    m = maps.mask
    frame = local_frames(maps.normals[m])                             # (P, 3, 3) rows
    wi = torch.einsum("pij,lj->lpi", frame, lights)                   # (L, P, 3)
    wo = frame[:, :, 2][None].expand_as(wi)                           # view (0, 0, 1)
    with torch.no_grad():
        value = brdf(wi, wo) * wi[..., 2:].clamp_min(0)               # (L, P, 3)
    if albedo is not None:
        value = value * (albedo[m][None, :, None] if albedo.dim() == 2 else albedo[m][None])
    value = value * intensities[:, None, None]
    if shadows:
        value = value * (~cast_shadows(maps, lights)[:, m])[..., None]
    images = torch.zeros(len(lights), *m.shape, 3, device=m.device)
    images[:, m] = value
    return images.permute(0, 3, 1, 2)


def local_frames(normals: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) rows tangent, bitangent, normal of (..., 3) unit normals (zero normals: zero
    frames)."""
    unit = torch.eye(3, device=normals.device)          # made there: a copy from the CPU would wait
    axis = torch.where(normals[..., :1].abs() < 0.9, unit[0], unit[1])
    tangent = F.normalize(torch.linalg.cross(axis, normals), dim=-1)
    return torch.stack([tangent, torch.linalg.cross(normals, tangent), normals], -2)


def shade_batch(normals: torch.Tensor, mask: torch.Tensor, pixels: torch.Tensor, lobes: LobeTable,
                others: dict[int, nn.Module], lights: torch.Tensor, intensities: torch.Tensor,
                albedo: torch.Tensor, shadows: torch.Tensor, budget: int = 2 ** 23) -> torch.Tensor:
    """:func:`shade` of B scenes at once: the analytic materials over the pixels that need them,
    all scenes' together, any other material scene by scene.

    Args:
        normals: (B, H, W, 3); mask: (B, H, W) bool; lights: (B, n, 3); intensities: (B, n);
            albedo: (B, H, W, 3); shadows: (B, n, H, W) bool, True where a light is hidden; all on
            one device.
        pixels: (P,) int64 flat indices into (B, H, W) of the pixels to shade with ``lobes``
            (:func:`lobe_pixels`); every other pixel of an analytic scene stays 0.
        lobes: the analytic materials (:meth:`LobeTable.of`), on that device.
        others: the scenes whose material is not analytic, by index, each with its material.
        budget: light-pixel pairs shaded at once (memory grows with it).

    Returns:
        (B, n, 3, H, W) float32, 0 off the objects: each scene as :func:`shade` renders it.
    """
    b, h, w, _ = normals.shape
    n = lights.shape[1]
    values = torch.zeros(b * h * w, n, 3, device=normals.device)
    flat_normals, flat_albedo = normals.reshape(-1, 3), albedo.reshape(-1, 3)
    for chunk in pixels.split(max(1, budget // n)):
        scene = chunk // (h * w)
        frame = local_frames(flat_normals[chunk])                              # (p, 3, 3)
        wi = torch.einsum("pij,pnj->pni", frame, lights[scene])                # (p, n, 3)
        wo = frame[..., 2][:, None].expand_as(wi)                               # view (0, 0, 1)
        value = lobes.rows(scene).values(wi, wo) * wi[..., 2:].clamp_min(0)
        values[chunk] = value * flat_albedo[chunk][:, None] * intensities[scene][:, :, None]
    values = values.view(b, h * w, n, 3)
    for i, brdf in others.items():
        maps = ShapeMaps(normals[i], torch.zeros_like(mask[i], dtype=torch.float32), mask[i])
        values[i] = shade(maps, brdf.to(normals.device), lights[i], intensities[i], albedo[i],
                          shadows=False).permute(2, 3, 0, 1).flatten(0, 1)
    values = values * (~shadows).flatten(2).transpose(1, 2)[..., None]
    return values.permute(0, 2, 3, 1).unflatten(3, (h, w))


def lobe_pixels(where: torch.Tensor, brdfs: list) -> torch.Tensor:
    """(P,) int64 flat indices into (B, H, W) of the pixels :func:`shade_batch` shades with
    lobes: those ``where`` (B, H, W) bool marks, of the scenes whose material (``brdfs``, B of them;
    None: no material) is an :class:`~unps.lightnet.brdf.AnalyticBRDF`."""
    lobed = torch.tensor([isinstance(brdf, AnalyticBRDF) for brdf in brdfs])
    return torch.nonzero((where & lobed[:, None, None]).flatten()).flatten()


@dataclass(frozen=True)
class LobeTable:
    """G analytic materials (:class:`AnalyticBRDF`) as tensors, K lobes each (a missing lobe has
    no albedo): diffuse (G, 3), specular (G, K, 3), roughness (G, K), fresnel0 (G, K)."""

    diffuse: torch.Tensor
    specular: torch.Tensor
    roughness: torch.Tensor
    fresnel0: torch.Tensor

    @classmethod
    def of(cls, brdfs: list) -> LobeTable:
        """The table of ``brdfs``; a material that is not analytic gets a row of no light."""
        lobed = [brdf if isinstance(brdf, AnalyticBRDF) else None for brdf in brdfs]
        count = max([len(brdf.specular) for brdf in lobed if brdf is not None], default=1)
        rows = lambda name, fill: torch.tensor([                          # noqa: E731
            [float(v) for v in getattr(brdf, name)] + [fill] * (count - len(brdf.specular))
            if brdf is not None else [fill] * count for brdf in lobed])
        diffuse = [brdf.diffuse.cpu() if brdf is not None else torch.zeros(3) for brdf in lobed]
        specular = [F.pad(brdf.specular.cpu(), (0, 0, 0, count - len(brdf.specular)))
                    if brdf is not None else torch.zeros(count, 3) for brdf in lobed]
        return cls(torch.stack(diffuse), torch.stack(specular), rows("roughness", 1.0),
                   rows("fresnel0", 0.04))

    def to(self, device: torch.device) -> LobeTable:
        return LobeTable(*(to_device(getattr(self, f.name), device) for f in fields(self)))

    def rows(self, index: torch.Tensor) -> LobeTable:
        return LobeTable(*(getattr(self, f.name)[index] for f in fields(self)))

    def values(self, wi: torch.Tensor, wo: torch.Tensor) -> torch.Tensor:
        """(G, ..., 3) RGB f(wi, wo) of the G materials for (G, ..., 3) local directions
        (:meth:`AnalyticBRDF.forward`, its terms in the same order)."""
        along = (-1,) + (1,) * (wi.dim() - 2)
        value = (self.diffuse / math.pi).view(*along, 3)
        for k in range(self.specular.shape[1]):
            value = value + self.specular[:, k].view(*along, 3) * ggx_lobe(
                wi, wo, self.roughness[:, k].view(along), self.fresnel0[:, k].view(along))[..., None]
        return value


def painted(resolution: int, generator: torch.Generator) -> torch.Tensor:
    """Paint: one to three colours laid on in patches with sharp edges, as on painted pots and
    printed labels; (H, W, 3) multipliers in [0.05, 1], 1 where no paint lies.

    Each coat covers where a smooth random field (a 4×4 to 12×12 grid of values, upsampled)
    exceeds a random level, so patches range from a few blobs to fine stripes and spots.
    """
    albedo = torch.ones(resolution, resolution, 3)
    for _ in range(int(torch.randint(1, 4, (1,), generator=generator))):
        coat = patches(resolution, generator, cells=(4, 12), level=(0.35, 0.3))
        albedo[coat] = 0.05 + 0.95 * torch.rand(3, generator=generator)
    return albedo


def coated(resolution: int, generator: torch.Generator) -> torch.Tensor:
    """Where a second material lies: (H, W) float, 1 on patches with sharp edges, 0 elsewhere.

    A smooth random field (a 3×3 to 10×10 grid of values, upsampled) above a level drawn so that
    the patches cover from about a fifth to four fifths of the image: a glaze over part of a
    pot, a metal inlay, a matte label on a glossy body.
    """
    return patches(resolution, generator, cells=(3, 10), level=(0.3, 0.4)).float()


def patches(resolution: int, generator: torch.Generator, cells: tuple[int, int],
            level: tuple[float, float]) -> torch.Tensor:
    """(H, W) bool: where a smooth random field exceeds a random level — patches with sharp edges.

    The field is a square grid of uniform values, ``cells[0]`` to ``cells[1]`` on a side, upsampled
    bicubically to ``resolution``; the level is ``level[0] + level[1]·U(0, 1)``. Coarse grids give a
    few blobs, fine ones stripes and spots; a higher level covers less.
    """
    side = int(torch.randint(cells[0], cells[1] + 1, (1,), generator=generator))
    field = F.interpolate(torch.rand(1, 1, side, side, generator=generator), size=(resolution, resolution),
                          mode="bicubic", align_corners=True)[0, 0]
    return field > level[0] + level[1] * float(torch.rand(1, generator=generator))


def darkened(brdf, factor: float):
    """``brdf`` with its diffuse albedo times ``factor`` and its lobes as they are: a dark glossy
    material (black phenolic, dark oxidised steel) when ``factor`` is small. A material that is not
    an :class:`~unps.lightnet.brdf.AnalyticBRDF` (a MERL table or fit) is returned as it is."""
    if not isinstance(brdf, AnalyticBRDF):
        return brdf
    return AnalyticBRDF(brdf.diffuse * factor, brdf.specular, brdf.roughness, brdf.fresnel0)


HELD_OUT_MERL = frozenset({
    "alumina-oxide", "aventurnine", "black-fabric", "black-oxidized-steel", "black-soft-plastic",
    "blue-fabric", "blue-metallic-paint2", "brass", "chrome-steel", "colonial-maple-223",
    "color-changing-paint2", "dark-blue-paint", "dark-specular-fabric", "fruitwood-241",
    "gold-metallic-paint2", "gold-paint", "grease-covered-steel", "green-fabric",
    "green-metallic-paint", "green-plastic", "ipswich-pine-221", "light-red-paint", "natural-209",
    "nickel", "orange-paint", "pickled-oak-260", "pink-fabric2", "pink-jasper", "polyethylene",
    "pure-rubber", "pvc", "red-fabric2", "red-phenolic", "red-specular-plastic",
    "silver-metallic-paint", "silver-paint", "specular-black-phenolic", "specular-green-phenolic",
    "specular-orange-phenolic", "specular-violet-phenolic", "specular-yellow-phenolic", "steel",
    "tungsten-carbide", "two-layer-silver", "violet-rubber", "white-diffuse-bball", "white-fabric2",
    "white-paint", "yellow-paint", "yellow-plastic",
})
"""The MERL materials kept for the light benchmark (``experiments/light_benchmark``): every second
name in alphabetical order, dark glossy metals, plastics and matte paints among them. The
training mix never draws them (:class:`MaterialBank` leaves their files out); the shipped
weights were trained on no MERL material at all."""


FAMILIES = ("analytic", "merl", "neural", "measured")   # a sample's ``family`` is its index here
DRAWN = {"analytic": random_analytic, "measured": random_measured}   # the families made, not read


class MaterialBank:
    """Draws materials by weight: analytic lobes, lobes in the span of measured materials,
    MERL ``.binary`` tables, MERL neural fits.

    Args:
        analytic: weight of random analytic materials (:func:`~unps.lightnet.brdf.random_analytic`).
        measured: weight of analytic materials spanning MERL's
            (:func:`~unps.lightnet.brdf.random_measured`; no data needed).
        merl_dir, merl: a folder of ``.binary`` files and its weight.
        neural_dir, neural: a folder of neural fits (``.h5``) and its weight.
        exclude: names of materials whose files are never drawn; default: the benchmark's
            (:data:`HELD_OUT_MERL`), so that training never sees them.
    """

    def __init__(self, analytic: float = 1.0, measured: float = 0.0, merl_dir: str | None = None,
                 merl: float = 0.0, neural_dir: str | None = None, neural: float = 0.0,
                 exclude: frozenset[str] = HELD_OUT_MERL):
        self.families, self.weights = ["analytic"], [analytic]
        if measured > 0:
            self.families.append("measured")
            self.weights.append(measured)
        self.files = {}
        for family, folder, weight, suffix in (("merl", merl_dir, merl, ".binary"),
                                               ("neural", neural_dir, neural, ".h5")):
            if weight > 0:
                if not folder or not Path(folder).expanduser().is_dir():
                    raise InputError(f"materials: {family} has weight {weight} but its folder "
                                     f"{folder!r} does not exist")
                files = sorted(p for p in Path(folder).expanduser().glob(f"*{suffix}")
                               if p.stem not in exclude)
                if not files:
                    raise InputError(f"{folder}: no {suffix} files (those of the light benchmark's "
                                     f"materials, unps.lightnet.materials.HELD_OUT_MERL, are left out)")
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
        if family in DRAWN:
            return family, DRAWN[family](generator)
        files = self.files[family]
        path = files[int(torch.randint(len(files), (1,), generator=generator))]
        if path not in self._loaded:
            self._loaded[path] = (read_merl_binary if family == "merl" else read_neural_brdf)(path)
        return family, self._loaded[path]

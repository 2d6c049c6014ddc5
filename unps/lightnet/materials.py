"""Materials for the light network's training data, and shading a shape with one.

Frame: x right, y up, z toward the camera; the view is (0, 0, 1).
"""

from __future__ import annotations

from pathlib import Path

import torch
import torch.nn.functional as F

from unps.errors import InputError
from unps.lightnet.brdf import random_analytic, random_measured, read_merl_binary, read_neural_brdf
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
    n = maps.normals[m]                                               # (P, 3)
    tangent = F.normalize(torch.linalg.cross(torch.where(n[:, :1].abs() < 0.9,
                                                         torch.tensor([1.0, 0, 0], device=n.device),
                                                         torch.tensor([0, 1.0, 0], device=n.device)), n),
                          dim=-1)
    bitangent = torch.linalg.cross(n, tangent)
    frame = torch.stack([tangent, bitangent, n], 1)                   # (P, 3, 3) rows
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


def painted(resolution: int, generator: torch.Generator) -> torch.Tensor:
    """Paint: one to three colours laid on in patches with sharp edges, as on painted pots and
    printed labels; (H, W, 3) multipliers in [0.05, 1], 1 where no paint lies.

    Each coat covers where a smooth random field (a 4×4 to 12×12 grid of values, upsampled)
    exceeds a random level, so patches range from a few blobs to fine stripes and spots.
    """
    u = lambda *shape: torch.rand(*shape, generator=generator)    # noqa: E731
    albedo = torch.ones(resolution, resolution, 3)
    for _ in range(int(torch.randint(1, 4, (1,), generator=generator))):
        cells = int(torch.randint(4, 13, (1,), generator=generator))
        field = F.interpolate(u(1, 1, cells, cells), size=(resolution, resolution), mode="bicubic",
                              align_corners=True)[0, 0]
        coat = field > 0.35 + 0.3 * float(u(1))
        albedo[coat] = 0.05 + 0.95 * u(3)
    return albedo


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

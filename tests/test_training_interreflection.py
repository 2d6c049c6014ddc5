"""Interreflections in the light network's training data (unps.lightnet.interreflection)."""

import dataclasses
import math

import pytest
import torch

from unps.errors import InputError
from unps.lightnet.brdf import AnalyticBRDF
from unps.lightnet.interreflection import diffuse_reflectance, interreflected
from unps.lightnet.shapes import maps_from_depth
from unps.lightnet.synthesis import LightDataset, render


def height_field(resolution: int, depth) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Normals, depth and mask of ``depth(x, y, r²)`` over [−1, 1]², the disc r < 0.87 inside."""
    y, x = torch.meshgrid(torch.linspace(1, -1, resolution), torch.linspace(-1, 1, resolution), indexing="ij")
    r2 = x ** 2 + y ** 2
    maps = maps_from_depth(depth(x, y, r2), r2 < 0.87 ** 2)
    return maps.normals, maps.depth, maps.mask


def lit_from_the_view(normals: torch.Tensor, mask: torch.Tensor, reflectance: float) -> torch.Tensor:
    """(1, 3, H, W) a Lambertian surface's radiance under a unit light along the view."""
    shading = reflectance / math.pi * normals[..., 2].clamp_min(0) * mask
    return shading[None, None].expand(1, 3, *mask.shape).contiguous()


@pytest.mark.parametrize("reflectance", [0.5, 0.8])
def test_a_hemispherical_bowl_receives_the_same_bounced_light_everywhere(reflectance):
    """Inside a sphere every point sees any patch of it at the same form factor, dA / (4πR²). A
    bowl cut from a sphere of radius R at a rim of radius cR, lit along its axis, sends each point
    ρc²/4 of the direct irradiance at its bottom once (its projected area over the sphere's
    area), and (1 − √(1 − c²))/2 of what it reflects again at each further bounce (its area over
    the sphere's): the same everywhere, and known in closed form."""
    radius, rim = 0.9, 0.87
    normals, depth, mask = height_field(64, lambda x, y, r2: -torch.sqrt((radius ** 2 - r2).clamp_min(0)))
    direct = lit_from_the_view(normals, mask, reflectance)
    bounced = interreflected(direct, normals, depth, mask, torch.full((64, 64, 3), reflectance))
    irradiance = (bounced - direct)[0, 0] / (reflectance / math.pi)
    inner = irradiance[16:48, 16:48][mask[16:48, 16:48]]
    c = rim / radius
    expected = reflectance * c ** 2 / 4 / (1 - reflectance * (1 - math.sqrt(1 - c ** 2)) / 2)
    assert float(inner.std() / inner.mean()) < 0.03
    assert float(inner.mean()) == pytest.approx(expected, rel=0.03)
    assert torch.equal(bounced[:, :, ~mask], direct[:, :, ~mask])


@pytest.mark.parametrize("surface", ["dome", "plane"])
def test_surfaces_that_see_nothing_of_themselves_are_left_as_they_are(surface):
    shapes = {"dome": lambda x, y, r2: torch.sqrt((1 - r2).clamp_min(0)), "plane": lambda x, y, r2: 0.3 * x}
    normals, depth, mask = height_field(64, shapes[surface])
    direct = lit_from_the_view(normals, mask, 0.9)
    assert torch.equal(interreflected(direct, normals, depth, mask, torch.full((64, 64, 3), 0.9)), direct)


def test_a_materials_reflectance_is_its_diffuse_albedo_but_for_broad_lobes():
    matte = AnalyticBRDF([0.6, 0.4, 0.2], [0.0, 0.0, 0.0], 0.3)
    torch.testing.assert_close(diffuse_reflectance(matte), torch.tensor([0.6, 0.4, 0.2]))
    sharp = AnalyticBRDF([0.6, 0.4, 0.2], [1.0, 1.0, 1.0], 0.05)
    torch.testing.assert_close(diffuse_reflectance(sharp), torch.tensor([0.6, 0.4, 0.2]), atol=0.01, rtol=0)
    broad = AnalyticBRDF([0.1, 0.1, 0.1], [1.0, 1.0, 1.0], 0.6)
    assert float(diffuse_reflectance(broad)[0]) > 0.11         # its shoulders scatter light too
    assert float(diffuse_reflectance(AnalyticBRDF([1.0] * 3, [1.0] * 3, 0.6)).max()) <= 0.95


def test_a_share_of_the_samples_fills_its_cavities_with_bounced_light():
    """A vessel rendered from the same draws with and without bounces: with them, pixels that no
    light reaches directly are lit, and lit pixels gain unevenly (the stack's level aside)."""
    dataset = LightDataset(8, resolution=64, images=8, shape="vessel", interreflection=0.5, camera=None,
                           perturbation=0.0, saturation=None, seed=3)
    scenes = [dataset.draw(index) for index in range(8)]
    assert 1 <= sum(scene.bounces for scene in scenes) <= 7
    plain = LightDataset(8, resolution=64, shape="vessel")
    assert not any(plain.draw(index).bounces for index in range(8))
    with_bounces, without = (render(dataclasses.replace(scenes[0], bounces=b), torch.device("cpu"))["images"]
                             for b in (True, False))
    lit = without > 1e-4
    gain = with_bounces[lit] / without[lit]
    assert float(gain.max() / gain.min()) > 1.2
    assert int(((with_bounces > 1e-3) & ~lit).sum()) > 0


def test_the_share_of_bounced_samples_is_checked():
    with pytest.raises(InputError, match="interreflection is a share of the samples, in 0…1; got 1.5"):
        LightDataset(4, resolution=32, interreflection=1.5)

"""Normals read off specular highlights (unps.inverse.highlights) and the fit that uses them."""

import numpy as np
import pytest
from conftest import tiny_fit

from unps.data.subject import Subject
from unps.inverse import highlights
from unps.inverse.highlights import MAX_SPACING_DEG, highlight_normals, lambertian_misfit, light_spacing
from unps.metrics import angular_error

VIEW = np.array([0.0, 0.0, 1.0])


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def cap(n: int, max_zenith_deg: float = 55.0) -> np.ndarray:
    """(n, 3) lights spread evenly (a Fibonacci spiral) over the cap around the view."""
    k = np.arange(n) + 0.5
    z = 1 - k / n * (1 - np.cos(np.radians(max_zenith_deg)))
    azimuth = np.pi * (1 + 5 ** 0.5) * k
    r = np.sqrt(1 - z ** 2)
    return np.stack([r * np.cos(azimuth), r * np.sin(azimuth), z], -1)


def glossy(normals: np.ndarray, lights: np.ndarray, diffuse: float = 0.02) -> np.ndarray:
    """(n, P) a dark material with a sharp specular lobe (Blinn-Phong, exponent 400) on (P, 3)
    normals."""
    half = unit(lights + VIEW)
    lit = np.clip(normals @ lights.T, 0, None).T
    return diffuse * lit + (np.clip(normals @ half.T, 0, None).T ** 400) * (lit > 0)


def test_a_dark_glossy_pixel_takes_the_half_vector_of_its_highlight():
    lights = cap(96)
    assert light_spacing(lights).max() < MAX_SPACING_DEG
    rng = np.random.default_rng(0)
    halves = unit(lights[rng.integers(0, 96, 300)] + VIEW)
    normals = unit(halves + rng.normal(scale=0.02, size=halves.shape))           # ~1.5° from a half vector
    estimate, flagged = highlight_normals(glossy(normals, lights), lights)
    assert flagged.mean() > 0.95
    assert angular_error(estimate[flagged], normals[flagged]).max() < 5


def test_diffuse_pixels_are_no_highlights_even_where_few_lights_reach_them(monkeypatch):
    """Lambertian pixels, some in a cavity that only the lights within 25° of its axis reach (ten
    or more of them): those are as peaked as a highlight, but their lit images follow the cosine."""
    lights = cap(96)
    rng = np.random.default_rng(1)
    normals = unit(rng.normal(size=(400, 3)) * [1, 1, 0.3] + VIEW)
    shading = np.clip(normals @ lights.T, 0, None).T * rng.uniform(0.2, 1, 400)
    axis = unit(normals + 2 * VIEW + [0.2, 0, 0])
    in_cavity = np.arange(400) < 200
    reached = np.degrees(np.arccos(np.clip(axis @ lights.T, -1, 1))).T < 25
    assert reached.sum(0).min() >= 10
    shading = np.where(in_cavity & ~reached, 0.0, shading)
    _, flagged = highlight_normals(shading, lights)
    assert not flagged.any()
    assert lambertian_misfit(shading, lights).max() < 0.05
    monkeypatch.setattr(highlights, "NOT_LAMBERTIAN", -1.0)          # the cosine test alone keeps
    _, peaked = highlight_normals(shading, lights)                     # the cavity's pixels
    assert peaked[in_cavity].all()


def test_sparse_lights_read_no_highlight():
    """Under 12 lights the half vector of the brightest pins the normal only to ±15°: kept out."""
    lights = cap(12)
    assert light_spacing(lights).min() > MAX_SPACING_DEG
    normals = unit(lights[:, :] + VIEW)                                      # each light's highlight
    _, flagged = highlight_normals(glossy(normals, lights), lights)
    assert not flagged.any()


def glossy_sphere(size: int = 24) -> Subject:
    """A ``size``² sphere of :func:`glossy`'s dark glossy material under 96 lights of a cap."""
    lights = cap(96)
    y, x = (np.mgrid[:size, :size] + 0.5) / size * 2 - 1
    mask = x ** 2 + y ** 2 < 0.9
    normals = np.zeros((size, size, 3), np.float32)
    normals[mask] = unit(np.stack([x[mask], -y[mask], np.sqrt(np.clip(1 - x[mask] ** 2 - y[mask] ** 2, 0, 1))], -1))
    images = np.zeros((96, size, size, 3), np.float32)
    images[:, mask] = glossy(normals[mask], lights)[..., None]
    return Subject("glossy", images, mask, lights.astype(np.float32), normals=normals)


def test_a_fit_of_a_dark_glossy_sphere_reads_its_highlights(caplog):
    """A 24×24 sphere of a dark glossy material under 96 lights: the pixels lit by a highlight
    take its half vector (nearer the truth than the fit), the others keep the fit's normal, and
    ``highlight_share`` counts them; ``highlights=false`` returns the fit's normals alone."""
    sphere = glossy_sphere()
    lights, mask, normals, images = sphere.light_directions, sphere.mask, sphere.normals, sphere.images
    caplog.set_level("INFO")

    read, plain = tiny_fit(sphere, highlights=True), tiny_fit(sphere, highlights=False)
    _, flagged = highlight_normals(images[:, mask].mean(-1), lights)
    lit = np.zeros_like(mask)
    lit[mask] = flagged
    assert 0.05 < read.info["highlight_share"] == pytest.approx(lit.sum() / mask.sum())
    assert plain.info["highlight_share"] is None
    np.testing.assert_allclose(read.normals[mask & ~lit], plain.normals[mask & ~lit], atol=1e-6)
    error = {name: angular_error(e.normals[lit], normals[lit]).mean() for name, e in (("read", read), ("plain", plain))}
    assert error["read"] < 5 < error["plain"]
    assert "lit by a specular highlight" in caplog.text


def test_the_fit_held_toward_its_highlights_half_vectors_carries_them_to_its_other_pixels(caplog):
    """``preset.highlight_hold`` pulls the pixels lit by a highlight toward its half vector in
    every step: on a dark glossy sphere, with the read-out's own highlights off so that the
    normals are the fit's, the highlit pixels end nearer the truth than without the pull, and so
    do the pixels no highlight lights, which share the network with them."""
    sphere = glossy_sphere()
    lights, mask, normals, images = sphere.light_directions, sphere.mask, sphere.normals, sphere.images
    caplog.set_level("INFO")

    fits = {hold: tiny_fit(sphere, highlights=False, highlight_hold=hold) for hold in (0.0, 1.0)}
    _, flagged = highlight_normals(images[:, mask].mean(-1), lights)
    lit = np.zeros_like(mask)
    lit[mask] = flagged
    parts = {"lit": lit, "unlit": mask & ~lit}
    error = {(hold, name): angular_error(fit.normals[part], normals[part]).mean()
             for hold, fit in fits.items() for name, part in parts.items()}
    assert error[1.0, "lit"] < 0.5 * error[0.0, "lit"]
    assert error[1.0, "unlit"] < error[0.0, "unlit"] - 1
    assert "pulled toward its half vector in every step" in caplog.text

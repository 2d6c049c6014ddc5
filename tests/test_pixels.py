"""Each pixel's normal solved against its images under a given reflectance (unps.inverse.pixels)."""

import numpy as np
import pytest

import unps.inverse.pixels as pixels
from unps.inverse.pixels import neighbour_pairs, noise_level, refine_pixel_normals, scaled_normals
from unps.metrics import angular_error


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@pytest.fixture
def stack():
    """200 pixels of random normals facing the camera, each its own RGB albedo, under 24 lights
    on a 50° cap: Lambertian values, and a start 8° off each true normal."""
    rng = np.random.default_rng(3)
    normals = unit(rng.normal(size=(200, 3)) * [1, 1, 0.3] + [0, 0, 1])
    zenith, azimuth = np.radians(rng.uniform(5, 50, 24)), rng.uniform(0, 2 * np.pi, 24)
    lights = np.stack([np.sin(zenith) * np.cos(azimuth), np.sin(zenith) * np.sin(azimuth), np.cos(zenith)], -1)
    colour = np.broadcast_to(rng.uniform(0.2, 1.0, (200, 3)), (24, 200, 3)).copy()
    images = colour * np.clip(normals @ lights.T, 0, None).T[..., None]
    start = unit(normals + 0.14 * unit(np.cross(normals, rng.normal(size=(200, 3)))))
    return images, colour, normals, lights, start


def test_each_pixels_weighted_least_squares_is_its_own_solve(stack):
    """The per-pixel systems, assembled for all pixels at once as matrix products, give what each
    pixel's own weighted least squares gives (weights of 0 among them: values left out)."""
    _, _, _, lights, _ = stack
    rng = np.random.default_rng(5)
    shading = rng.uniform(-0.1, 1.0, (24, 50)).astype(np.float32)
    weight = (rng.uniform(0, 2, (24, 50)) * (rng.uniform(size=(24, 50)) > 0.3)).astype(np.float32)
    solved = scaled_normals(shading, weight, lights.astype(np.float32))
    for p in range(50):
        root = np.sqrt(weight[:, p].astype(np.float64))[:, None]
        own = np.linalg.lstsq(root * lights, root[:, 0] * shading[:, p], rcond=None)[0]
        np.testing.assert_allclose(solved[p], own, rtol=1e-4, atol=1e-5)


def test_a_lambertian_stack_gives_each_pixel_its_true_normal(stack):
    images, colour, normals, lights, start = stack
    assert angular_error(start, normals).mean() > 7
    solved, ok, _, lobed = refine_pixel_normals(images, colour, start, lights)
    assert ok.all() and angular_error(solved, normals).max() < 1e-3
    assert not lobed.any()


def test_a_pixel_whose_fitted_reflectance_has_a_specular_lobe_keeps_its_start(monkeypatch):
    """A glossy material with a broad lobe (Blinn-Phong, exponent 10, a little diffuse) under 96
    lights, the start 2.3° off, the fitted reflectance's lobe misplaced (that of normals 8.6° off):
    holding it fixed, the solve turns the normals to explain the lobe's error with shading and ends
    further off than it began; the pixels whose reflectance peaks keep their start."""
    rng = np.random.default_rng(3)
    normals = unit(rng.normal(size=(200, 3)) * [1, 1, 0.3] + [0, 0, 1])
    zenith, azimuth = np.radians(rng.uniform(5, 60, 96)), rng.uniform(0, 2 * np.pi, 96)
    lights = np.stack([np.sin(zenith) * np.cos(azimuth), np.sin(zenith) * np.sin(azimuth), np.cos(zenith)], -1)
    half = unit(lights + [0, 0, 1])

    def reflectance(n):                  # (96, 200, 3): the value at shading 1, lobe included
        shading = np.clip(n @ lights.T, 1e-3, None).T
        return (0.05 + np.clip(n @ half.T, 0, None).T ** 10 / shading)[..., None] * np.ones(3)

    def turned(degrees):
        return unit(normals + np.tan(np.radians(degrees)) * unit(np.cross(normals, rng.normal(size=(200, 3)))))

    images = reflectance(normals) * np.clip(normals @ lights.T, 0, None).T[..., None]
    start, fitted = turned(2.3), reflectance(turned(8.6))
    solved, ok, _, lobed = refine_pixel_normals(images, fitted, start, lights)
    monkeypatch.setattr(pixels, "LOBE_PEAK", np.inf)
    through_the_lobe, *_ = refine_pixel_normals(images, fitted, start, lights)

    assert lobed.mean() > 0.5 and not ok[lobed].any()
    np.testing.assert_array_equal(solved[lobed], start[lobed])
    started = angular_error(start, normals)[lobed].mean()
    assert angular_error(through_the_lobe, normals)[lobed].mean() > 3 * started        # measured: 11.3° from 2.3°


def test_values_in_a_cast_shadow_and_clipped_values_are_left_out(stack):
    images, colour, normals, lights, start = stack
    shading = (normals @ lights.T).T
    rng = np.random.default_rng(0)
    shadowed = (shading > 0.3) & (rng.random(shading.shape) < 0.15)
    clipped = (shading > 0.3) & ~shadowed & (rng.random(shading.shape) < 0.15)
    seen = images.copy()
    seen[shadowed] = 0.0
    seen[clipped] *= 0.6                     # a ceiling below the value
    solved, ok, *_ = refine_pixel_normals(seen, colour, start, lights, usable=~clipped)
    assert ok.all() and angular_error(solved, normals).max() < 1e-3
    blind, *_ = refine_pixel_normals(seen, colour, start, lights)
    assert angular_error(blind, normals).mean() > 0.1    # L1 resists them, but not wholly


def test_a_cast_shadow_that_interreflections_light_is_still_left_out(stack):
    images, colour, normals, lights, start = stack
    shading = (normals @ lights.T).T
    rng = np.random.default_rng(1)
    shadowed = (shading > 0.5) & (rng.random(shading.shape) < 0.2)
    seen = images.copy()
    seen[shadowed] *= 0.35                   # a shadow filled by light from the rest of the object
    solved, ok, used, _ = refine_pixel_normals(seen, colour, start, lights)
    assert not used[shadowed].any()
    assert ok.all() and angular_error(solved, normals).max() < 1e-3


def test_l1_passes_over_a_highlight_that_least_squares_follows(stack):
    images, colour, normals, lights, start = stack
    shading = (normals @ lights.T).T
    brightest = np.argmax(shading, axis=0)
    seen = images.copy()
    seen[brightest, np.arange(200)] *= 2.5     # a highlight the reflectance does not hold
    least_squares, *_ = refine_pixel_normals(seen, colour, start, lights, reweightings=0)
    l1, *_ = refine_pixel_normals(seen, colour, start, lights)
    assert angular_error(l1, normals).mean() < 0.5 * angular_error(least_squares, normals).mean()


def test_a_pixel_with_too_few_lit_images_keeps_its_start(stack):
    images, colour, normals, lights, start = stack
    seen = images.copy()
    seen[3:, 7] = 0.0                           # pixel 7: three images left
    solved, ok, *_ = refine_pixel_normals(seen, colour, start, lights)
    assert not ok[7] and ok[np.arange(200) != 7].all()
    np.testing.assert_array_equal(solved[7], start[7])


def test_a_solution_facing_away_from_the_camera_keeps_the_start(stack):
    """A pixel whose images say its normal points away from the camera (n_z < 0: lights low
    enough to reach it) is not seen as such by any pixel of a visible surface: it keeps its start."""
    images, colour, normals, lights, start = stack
    zenith, azimuth = np.radians(np.linspace(60, 85, 12)), np.linspace(-0.6, 0.6, 12)
    low = np.stack([np.sin(zenith) * np.cos(azimuth), np.sin(zenith) * np.sin(azimuth), np.cos(zenith)], -1)
    away = unit(np.array([1.0, 0.0, -0.15]))
    seen = 0.7 * np.clip(low @ away, 0, None)[:, None, None] * np.ones((1, 1, 3))
    begin = unit(np.array([[1.0, 0.0, 0.2]]))
    solved, ok, *_ = refine_pixel_normals(seen, np.full((12, 1, 3), 0.7), begin, low)
    assert not ok[0]
    np.testing.assert_array_equal(solved, begin)


@pytest.fixture
def dome():
    """A 32×32 grid of a sphere cap, a textured albedo, 24 lights; a smooth misfit the model does
    not render (the values up to 25 % brighter toward one side); a start 6° off."""
    rng = np.random.default_rng(5)
    y, x = np.mgrid[-1:1:32j, -1:1:32j] * 0.6
    normals = unit(np.stack([x, y, np.ones_like(x)], -1)).reshape(-1, 3)
    zenith, azimuth = np.radians(rng.uniform(5, 50, 24)), rng.uniform(0, 2 * np.pi, 24)
    lights = np.stack([np.sin(zenith) * np.cos(azimuth), np.sin(zenith) * np.sin(azimuth), np.cos(zenith)], -1)
    colour = np.broadcast_to(rng.uniform(0.4, 0.8, (1024, 3)), (24, 1024, 3)).copy()
    misfit = (1 + 0.25 * (x.ravel() + 0.6) / 1.2)[None, :, None]
    images = colour * misfit * np.clip(normals @ lights.T, 0, None).T[..., None]
    start = unit(normals + 0.1 * unit(np.cross(normals, [0.3, 1.0, 0.0])))
    return images, colour, lights, start, neighbour_pairs(np.ones((32, 32), bool))


def read_noise(images, colour, lights, start, pairs):
    solved, _, used, _ = refine_pixel_normals(images, colour, start, lights)
    return noise_level(images, colour, solved, lights, used, pairs)


@pytest.mark.parametrize("sigma", [0.02, 0.1])
def test_the_noise_is_read_off_neighbouring_residuals_and_not_off_a_smooth_misfit(dome, sigma):
    images, colour, lights, start, pairs = dome
    noisy = images + np.random.default_rng(1).normal(0, sigma, images.shape)
    assert read_noise(noisy, colour, lights, start, pairs) == pytest.approx(sigma, rel=0.2)
    assert read_noise(images, colour, lights, start, pairs) < 0.002    # the misfit: residuals ~0.05

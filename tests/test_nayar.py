import numpy as np
import pytest

from unps.data.subject import Subject
from unps.geometry import integrate_normals
from unps.metrics import angular_error
from unps.solvers.nayar import (interreflection_kernel, nayar, reflectance_scale,
                                remove_interreflections, visibility)
from unps.solvers.woodham import woodham


def groove(size=20, slope=1.5, convex=False):
    """A V-groove along y (concave toward the camera), or a ridge: depth, normals, mask."""
    c = np.arange(size) - (size - 1) / 2
    sign = -1 if convex else 1
    z = sign * slope * np.abs(c)[None, :].repeat(size, 0)
    n = np.stack([-sign * slope * np.sign(c), 0 * c, np.ones_like(c)], -1)
    n = (n / np.linalg.norm(n, axis=-1, keepdims=True))[None].repeat(size, 0)
    return z, n, np.ones((size, size), bool)


def test_kernel_couples_the_two_walls_of_a_groove_only():
    z, n, mask = groove(10)
    k = interreflection_kernel(z, n, mask)
    left = (np.arange(10) < 5)[None].repeat(10, 0)[mask]
    assert (np.diag(k) == 0).all()
    assert (k[np.ix_(left, left)] == 0).all() and (k[np.ix_(~left, ~left)] == 0).all()  # coplanar
    assert (k[np.ix_(left, ~left)] > 0).mean() > 0.9
    area = 1 / n[mask][:, 2]
    np.testing.assert_allclose(k * area[:, None], (k * area[:, None]).T, rtol=1e-10, atol=1e-15)


def test_kernel_is_zero_on_a_ridge_whose_facets_face_away():
    z, n, mask = groove(10, convex=True)
    assert not interreflection_kernel(z, n, mask).any()


def test_visibility_is_blocked_by_a_wall():
    depth = np.zeros((5, 9))
    depth[:, 4] = 10.0
    mask = np.ones((5, 9), bool)
    v = visibility(depth, mask)
    index = np.arange(45).reshape(5, 9)
    assert not v[index[2, 1], index[2, 7]] and v[index[2, 1], index[2, 3]]
    assert (v == v.T).all()


def test_visibility_of_chosen_pairs_samples_those_segments_alone_to_the_same_values():
    depth = np.zeros((7, 9))
    depth[:, 4] = 10.0
    depth[2, 1] = 3.0
    mask = np.ones((7, 9), bool)
    chosen = np.random.default_rng(0).random((63, 63)) < 0.3
    full, some = visibility(depth, mask, chunk=5), visibility(depth, mask, chunk=5, pairs=chosen)
    np.testing.assert_array_equal(some, full & chosen)
    assert not full.all() and (full & chosen).any()


def test_the_kernel_samples_visibility_only_where_facets_face_each_other():
    """Restricting the segments it samples leaves the kernel as it is, bit for bit."""
    z, n, mask = groove(12)
    z[3:6, 2] += 4.0                                     # a bump on one wall shades the other
    k = interreflection_kernel(z, n, mask)
    unoccluded = interreflection_kernel(z, n, mask, occlusion=False)
    np.testing.assert_array_equal(k, unoccluded * visibility(z, mask))
    assert (k < unoccluded).any()


def test_removing_interreflections_inverts_the_forward_model():
    z, n, mask = groove(12)
    k = interreflection_kernel(z, n, mask)
    albedo = np.random.default_rng(0).uniform(0.3, 0.9, mask.sum())
    facets = albedo[:, None] * n[mask]
    pseudo = np.linalg.solve(np.eye(len(k)) - albedo[:, None] * k, facets)
    np.testing.assert_allclose(remove_interreflections(pseudo, k, albedo), facets, atol=1e-10)


def groove_mae(subject, estimate):
    return angular_error(estimate.normals, subject.normals)[subject.mask].mean()


def lit_groove(exposure=1.0):
    """A V-groove of albedo 0.8 under 12 lights, its images with interreflections, × ``exposure``."""
    z, n, mask = groove(24, slope=1.2)
    depth = integrate_normals(n, mask)
    k = interreflection_kernel(depth, n, mask)
    albedo = np.full(mask.sum(), 0.8)
    pseudo = np.linalg.solve(np.eye(len(k)) - albedo[:, None] * k, albedo[:, None] * n[mask])
    rng = np.random.default_rng(1)
    zenith, azimuth = rng.uniform(0, np.radians(25), 12), rng.uniform(0, 2 * np.pi, 12)
    lights = np.stack([np.sin(zenith) * np.cos(azimuth), np.sin(zenith) * np.sin(azimuth),
                       np.cos(zenith)], 1)
    images = np.zeros((12, 24, 24, 3))
    images[:, mask] = exposure * (pseudo @ lights.T).T[..., None]
    return Subject("groove", images, mask, lights, normals=n)


def test_nayar_undoes_interreflections_that_fool_woodham():
    subject = lit_groove()
    err_w = groove_mae(subject, woodham(subject, subject.light_directions))
    err_n = groove_mae(subject, nayar(subject, subject.light_directions, iterations=15, downsample=1))
    assert err_w > 3 and err_n < 0.3 * err_w


def test_a_dim_capture_needs_its_albedo_stated():
    """At exposure 0.1 the albedo reads 0.08: taken as a reflectance, P is 10× too weak."""
    subject = lit_groove(exposure=0.1)
    err_w = groove_mae(subject, woodham(subject, subject.light_directions))
    as_is = groove_mae(subject, nayar(subject, subject.light_directions, downsample=1))
    stated = groove_mae(subject, nayar(subject, subject.light_directions, downsample=1, albedo=0.8))
    assert as_is > 0.7 * err_w and stated < 0.3 * err_w


def test_reflectance_scale_reaches_the_stated_median_or_scales_down_to_white():
    dim = np.full(16, 0.4)
    assert reflectance_scale(dim) == 1.0
    bright = np.linspace(1, 5, 16)
    assert np.percentile(bright * reflectance_scale(bright), 99) == pytest.approx(1.0)
    varied = dim * np.linspace(0.5, 1, 16)
    stated = varied * reflectance_scale(varied, 0.6)
    assert np.median(stated) == pytest.approx(0.6) and stated.max() == pytest.approx(0.8, rel=0.02)
    with pytest.raises(ValueError, match="interreflection.albedo"):
        reflectance_scale(dim, 1.5)

import numpy as np

from unps.data.subject import Subject
from unps.geometry import integrate_normals
from unps.metrics import angular_error
from unps.solvers.nayar import (interreflection_kernel, nayar, remove_interreflections,
                                visibility)
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


def test_removing_interreflections_inverts_the_forward_model():
    z, n, mask = groove(12)
    k = interreflection_kernel(z, n, mask)
    albedo = np.random.default_rng(0).uniform(0.3, 0.9, mask.sum())
    facets = albedo[:, None] * n[mask]
    pseudo = np.linalg.solve(np.eye(len(k)) - albedo[:, None] * k, facets)
    np.testing.assert_allclose(remove_interreflections(pseudo, k, albedo), facets, atol=1e-10)


def test_nayar_undoes_interreflections_that_fool_woodham():
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
    images[:, mask] = (pseudo @ lights.T).T[..., None]
    subject = Subject("groove", images, mask, lights, normals=n)
    err_w = angular_error(woodham(subject, lights).normals, n)[mask].mean()
    err_n = angular_error(nayar(subject, lights, iterations=15, downsample=1).normals, n)[mask].mean()
    assert err_w > 3 and err_n < 0.3 * err_w

import numpy as np
import torch

from unps.data.analytic import render_lambertian
from unps.metrics import angular_error
from unps.solvers.rpca import partial_sum_rpca, partial_svt_weights, robust_init
from unps.solvers.woodham import woodham


def shadow_free(subject):
    """Keep only pixels that every light illuminates, so the Lambertian model holds exactly."""
    lit = (np.einsum("hwc,nc->nhw", subject.normals, subject.light_directions) > 0.05).all(0)
    return subject.replace(mask=subject.mask & lit)


def test_woodham_is_exact_on_a_shadow_free_sphere():
    s = shadow_free(render_lambertian("sphere", size=48, n_lights=10, textured=True, seed=1))
    est = woodham(s, s.light_directions)
    assert angular_error(est.normals, s.normals)[s.mask].max() < 1e-3
    # the albedo is recovered too: x = ρ (n·l) exactly
    shading = np.einsum("hwc,nc->nhw", s.normals, s.light_directions)[:, s.mask]
    np.testing.assert_allclose(est.albedo[s.mask] * shading[..., None], s.images[:, s.mask], atol=1e-5)


def test_woodham_off_mask_is_zero(sphere):
    est = woodham(sphere, sphere.light_directions)
    assert not est.normals[~sphere.mask].any() and not est.albedo[~sphere.mask].any()


def test_partial_svt_weights_keep_the_top_k_and_shrink_the_rest():
    u, _ = np.linalg.qr(np.random.default_rng(0).standard_normal((30, 5)))
    v, _ = np.linalg.qr(np.random.default_rng(1).standard_normal((5, 5)))
    sigma = np.array([9.0, 7, 5, 3, 0.5])
    a = torch.tensor(u @ np.diag(sigma) @ v.T)
    out = (a @ partial_svt_weights(a, rank=3, tau=1.0)).numpy()
    np.testing.assert_allclose(np.linalg.svd(out, compute_uv=False), [9, 7, 5, 2, 0], atol=1e-9)


def test_rpca_recovers_a_rank_3_matrix_under_sparse_corruption():
    rng = np.random.default_rng(0)
    m, n = 600, 40
    low = rng.standard_normal((m, 3)) @ rng.standard_normal((3, n))
    outliers = np.zeros((m, n))
    hit = rng.random((m, n)) < 0.05
    outliers[hit] = rng.uniform(-10, 10, hit.sum())
    result = partial_sum_rpca(low + outliers, rank=3, tol=1e-9, dtype=torch.float64)
    assert np.linalg.norm(result.low_rank - low) / np.linalg.norm(low) < 1e-5
    assert np.abs(result.sparse[~hit]).max() < 1e-4
    assert result.residual < 1e-9


def test_robust_init_beats_woodham_under_shadows_and_outliers():
    s = render_lambertian("sphere", size=48, n_lights=32, seed=2)
    rng = np.random.default_rng(0)
    spikes = (rng.random(s.images.shape[:3]) < 0.03)[..., None] * 3.0   # specular-like outliers
    s = s.replace(images=s.images + spikes.astype(np.float32))
    err_w = angular_error(woodham(s, s.light_directions).normals, s.normals)[s.mask].mean()
    err_r = angular_error(robust_init(s, s.light_directions).normals, s.normals)[s.mask].mean()
    assert err_r < 0.5 * err_w


def test_robust_init_is_deterministic(sphere):
    a = robust_init(sphere, sphere.light_directions).normals
    b = robust_init(sphere, sphere.light_directions).normals
    np.testing.assert_array_equal(a, b)

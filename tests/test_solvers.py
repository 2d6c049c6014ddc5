import numpy as np
import torch

from unps.data.analytic import render_lambertian
from unps.data.checks import zero_ceiling
from unps.inverse.grids import black_headroom
from unps.metrics import angular_error
from unps.solvers.rpca import partial_svt, partial_sum_rpca, robust_init, shrink_outside
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


def test_partial_svt_keeps_the_top_k_and_shrinks_the_rest():
    u, _ = np.linalg.qr(np.random.default_rng(0).standard_normal((30, 5)))
    v, _ = np.linalg.qr(np.random.default_rng(1).standard_normal((5, 5)))
    sigma = np.array([9.0, 7, 5, 3, 0.5])
    a = torch.tensor(u @ np.diag(sigma) @ v.T)
    for m in (a, a.T):                                   # tall and wide
        out = partial_svt(m, rank=3, tau=1.0).numpy()
        got = np.linalg.svd(out, compute_uv=False)
        np.testing.assert_allclose(got, [9, 7, 5, 2, 0], atol=1e-9)


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


def test_values_read_as_zero_with_headroom_let_the_low_rank_part_go_below_zero():
    """Attached shadows read 0 where the Lambertian matrix is negative: given headroom there, the
    partial-sum RPCA recovers the whole rank-3 matrix, shadows included; read as 0 they are
    outliers pulling it up."""
    rng = np.random.default_rng(0)
    normals = rng.standard_normal((500, 3))
    normals[:, 2] = np.abs(normals[:, 2]) + 0.5
    lights = rng.standard_normal((30, 3))
    lights[:, 2] = np.abs(lights[:, 2]) + 0.3
    shading = normals @ lights.T                                  # (m, n), negative where shadowed
    observed = np.maximum(shading, 0)
    assert 0.05 < (observed == 0).mean() < 0.4
    headroom = np.where(observed == 0, 1e-3, 0.0)
    censored = partial_sum_rpca(observed, rank=3, tol=1e-8, dtype=torch.float64, headroom=headroom)
    plain = partial_sum_rpca(observed, rank=3, tol=1e-8, dtype=torch.float64)
    error = {name: np.linalg.norm(r.low_rank - shading) / np.linalg.norm(shading)
             for name, r in (("censored", censored), ("plain", plain))}
    assert error["censored"] < 2e-3 and error["plain"] > 0.1, error


def test_a_value_above_zero_keeps_its_outlier_cost_below_what_it_reads():
    """Headroom lets a value be brighter than it reads, never darker: where X > 0 the interval
    of E = X − Z is [−headroom, 0], and a lower Z is charged as before."""
    v = torch.tensor([[2.0, 2.0]])
    x = torch.tensor([[0.0, 0.5]])
    headroom = torch.tensor([[0.1, 0.1]])
    high = torch.where((x == 0) & (headroom > 0), torch.inf, 0.0).double()
    assert shrink_outside(v.double(), -headroom.double(), high, 0.5).tolist() == [[2.0, 1.5]]


def test_robust_init_is_not_tilted_by_a_dark_8bit_capture_whose_zeros_have_headroom():
    """A sphere exposed to six 8-bit levels (``floor``, read at the middle of each level): with
    its zeros read as no light the robust initialisation is tilted; with them read as light
    below the first level (:func:`unps.inverse.grids.black_headroom`), much less."""
    sphere = render_lambertian("sphere", size=48, n_lights=32, textured=True, seed=3)
    observed = sphere.observed_images()
    levels = np.floor(observed / np.percentile(observed[:, sphere.mask], 99) * 6)
    read = np.where(levels > 0, levels + 0.5, 0) / 255
    dark = sphere.replace(images=(read / sphere.light_intensities[:, None, None]).astype(np.float32))
    headroom = black_headroom(read, sphere.mask, 1, zero_ceiling(read, sphere.mask), sphere.light_intensities)
    errors = {name: angular_error(robust_init(dark, sphere.light_directions, headroom=h).normals,
                                  sphere.normals)[sphere.mask].mean()
              for name, h in (("plain", None), ("headroom", headroom))}
    assert errors["headroom"] < 0.7 * errors["plain"], errors


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

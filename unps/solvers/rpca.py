"""The paper's robust initialisation: partial-sum RPCA by ADMM (supplementary §3.1, Eqs. 4–8).

The image matrix X (pixels × images) is split into a low-rank Z = Nᵀ·L (the Lambertian
part) and sparse outliers E (shadows, highlights):

    minimise ‖Z‖_{r=K} + λ‖E‖₁  subject to  X = Z + E,

where ‖Z‖_{r=K} sums the singular values beyond the K-th (Oh et al., partial sum of
singular values), so the rank-3 subspace keeps its variance instead of being shrunk as
nuclear-norm RPCA would. Normals and albedo then come from Z with the given lights.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import torch

from unps.data.estimate import Estimate
from unps.data.subject import Subject
from unps.device import resolve_device
from unps.errors import InputError
from unps.timing import stage
from unps.solvers.woodham import (lambertian_least_squares, normals_from_scaled,
                                  rgb_albedo, to_maps)

log = logging.getLogger(__name__)


def partial_svt_weights(a: torch.Tensor, rank: int, tau: float) -> torch.Tensor:
    """The (n, n) matrix W with P_{K,τ}[A] = A·W, for a tall (m, n) matrix A.

    P_{K,τ}[A] = U(Σ₁ + S_τ[Σ₂])Vᵀ keeps the top ``rank`` singular values and soft-thresholds
    the others by τ (partial singular-value thresholding). With A = UΣVᵀ this equals
    A·V·diag(f(σ)/σ)·Vᵀ, so the SVD goes through the n×n Gram matrix AᵀA (for an m×96
    image matrix, a 96×96 eigenproblem, solved in float64).

    Args:
        a: (m, n) with m ≥ n.
        rank: K, the number of singular values left untouched.
        tau: the threshold for the rest.
    """
    eigenvalues, vectors = torch.linalg.eigh((a.T @ a).double())       # ascending
    sigma = eigenvalues.flip(0).clamp_min(0).sqrt()
    vectors = vectors.flip(1)
    shrunk = sigma.clone()
    shrunk[rank:] = (sigma[rank:] - tau).clamp_min(0)
    floor = sigma[0] * 1e-10
    ratio = torch.where(sigma > floor, shrunk / sigma.clamp_min(floor), torch.zeros_like(sigma))
    return ((vectors * ratio) @ vectors.T).to(a.dtype)


@dataclass(frozen=True)
class RPCAResult:
    low_rank: np.ndarray      # (m, n) Z
    sparse: np.ndarray        # (m, n) E
    iterations: int
    residual: float           # ‖X − Z − E‖_F / ‖X‖_F at the end


def partial_sum_rpca(x: np.ndarray, rank: int = 3, lam: float | None = None,
                     tol: float = 1e-4, max_iter: int = 500, rho: float = 1.5,
                     dtype: torch.dtype = torch.float32,
                     device: torch.device = torch.device("cpu")) -> RPCAResult:
    """Split X into a matrix whose singular values beyond ``rank`` are small, plus sparse E.

    Inexact augmented Lagrangian / ADMM with an increasing penalty μ (Lin et al. 2010):
    Z ← P_{K,1/μ}[X − E + Y/μ] (Eq. 6), E ← S_{λ/μ}[X − Z + Y/μ] (Eq. 7),
    Y ← Y + μ(X − Z − E) (Eq. 8), μ ← ρμ, until ‖X − Z − E‖_F ≤ tol·‖X‖_F.
    The multiplier is kept scaled, U = Y/μ, and every update is in place: the cost of an
    iteration is two (m, n)×(n, n) products and a few passes over the matrix.

    Args:
        x: (m, n) data, e.g. pixels × images.
        rank: K, singular values kept unpenalised (3 for Lambertian photometric stereo).
        lam: weight of ‖E‖₁; default 1/√max(m, n), the RPCA standard.
        tol: relative residual at which to stop. On DiLiGenT, 1e-4 gives the same normals
            as 1e-7 to 0.001°; float32 cannot go much below 1e-6.
        max_iter: iteration limit.
        rho: growth factor of μ.
        dtype: float32 (fast) or float64.
        device: where the iterations run; the result comes back as numpy.
    """
    transpose = x.shape[0] < x.shape[1]
    x = torch.as_tensor(np.asarray(x).T if transpose else np.asarray(x), dtype=dtype, device=device)
    lam = 1.0 / np.sqrt(max(x.shape)) if lam is None else float(lam)
    norm_x = torch.linalg.norm(x)
    spectral = torch.linalg.eigvalsh((x.T @ x).double())[-1].sqrt().item()
    if spectral == 0:                                   # X = 0: nothing low-rank, nothing sparse
        zeros = np.zeros(tuple(reversed(x.shape)) if transpose else tuple(x.shape))
        return RPCAResult(zeros, zeros.copy(), 0, 0.0)
    mu, mu_max = 1.25 / spectral, 1.25 / spectral * 1e7
    u = x / (max(spectral, x.abs().max().item() / lam) * mu)
    e = torch.zeros_like(x)
    a = torch.empty_like(x)
    z = torch.empty_like(x)
    residual = float("inf")
    for it in range(1, max_iter + 1):
        torch.sub(x, e, out=a).add_(u)                       # X − E + U
        torch.mm(a, partial_svt_weights(a, rank, 1.0 / mu), out=z)
        e = torch.nn.functional.softshrink(a.add_(e).sub_(z), lam / mu)   # X − Z + U
        r = torch.sub(x, z, out=a).sub_(e)
        residual = (torch.linalg.norm(r) / norm_x).item()
        mu_next = min(mu * rho, mu_max)
        u.add_(r).mul_(mu / mu_next)
        mu = mu_next
        if residual < tol:
            break
    else:
        log.warning("partial-sum RPCA stopped after %d iterations at relative residual %.2e "
                    "(tolerance %.1e)", max_iter, residual, tol)
    z, e = z.double().cpu().numpy(), e.double().cpu().numpy()
    return RPCAResult(z.T if transpose else z, e.T if transpose else e, it, residual)


OUTLIER_SHARE_OF_WHITE = 0.01   # an entry of E counts as an outlier in the log above this share of white


def outlier_share(sparse: np.ndarray, x: np.ndarray) -> float:
    """The share of the entries of E (``sparse``, the shape of ``x``) above
    :data:`OUTLIER_SHARE_OF_WHITE` of X's white level (its 99th percentile). The inexact ADMM
    stops with nearly every entry of E non-zero, mostly by far less than a quantisation level,
    so counting the non-zero ones says nothing.

    Example:
        >>> x = np.ones((10, 10)); sparse = np.full((10, 10), 1e-4); sparse[0, :5] = 0.5
        >>> outlier_share(sparse, x)
        0.05
    """
    white = np.percentile(x, 99)
    return float(np.mean(np.abs(sparse) > OUTLIER_SHARE_OF_WHITE * white)) if white > 0 else 0.0


@stage("robust initialisation")
def robust_init(subject: Subject, light_directions: np.ndarray, rank: int = 3,
                lam: float | None = None, tol: float = 1e-4, max_iter: int = 500,
                device: str | torch.device = "auto") -> Estimate:
    """Normals and albedo from the low-rank part of the gray image matrix.

    Args:
        subject: images divided by their intensities.
        light_directions: (n, 3) unit, surface to light, unps frame (given or estimated).
        rank, lam, tol, max_iter: see :func:`partial_sum_rpca`.
        device: where the RPCA iterates (``device=`` option, :func:`unps.device.resolve_device`).
    """
    pixels = subject.images[:, subject.mask]                          # (n, m, 3)
    if not np.any(pixels > 0):
        raise InputError(f"subject {subject.name!r}: every image is black on the object, so there "
                         f"is nothing to solve")
    gray = pixels.mean(-1).T                                          # (m, n)
    result = partial_sum_rpca(gray, rank, lam, tol, max_iter, device=resolve_device(device))
    log.info("robust init: %d ADMM iterations, residual %.1e; %.1f%% of the values lie off the "
             "low-rank part by more than %.0f%% of the white level (shadows, highlights)",
             result.iterations, result.residual,
             100 * outlier_share(result.sparse, gray), 100 * OUTLIER_SHARE_OF_WHITE)
    b = lambertian_least_squares(result.low_rank.T, light_directions)
    normals, _ = normals_from_scaled(b)
    albedo = rgb_albedo(pixels, normals, light_directions)
    return Estimate(to_maps(normals, subject.mask), to_maps(albedo, subject.mask))

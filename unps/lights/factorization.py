"""Lights from the images' low-rank part, aligned with a first guess.

Under distant lights a Lambertian object's images form a rank-3 matrix X = B·Sᵀ (pixels ×
images; B the scaled normals ρn, S the scaled lights e·l). The robust initialisation
(:mod:`unps.solvers.rpca`) recovers that low-rank part Z from the captured images, shadows and
highlights aside. Any factorization Z = B·Sᵀ is the true one up to one invertible 3×3 matrix T,
so every error of the first guess that is not shared by all lights can be read off the images:
the T that turns S's rows most nearly parallel to the first-guess directions leaves only the
per-light errors, whatever the first guess's intensities. What is left is one matrix for all
lights, which self-calibration fits (:mod:`unps.lights.model`).
"""

from __future__ import annotations

import numpy as np

from unps.solvers.rpca import partial_sum_rpca


def aligned_factorization(gray: np.ndarray, directions: np.ndarray, rank: int = 3
                          ) -> tuple[np.ndarray, np.ndarray]:
    """The low-rank part of the image matrix, factored into scaled normals and scaled lights in
    the frame of the initial lights.

    Args:
        gray: (m, n) pixel × image brightness.
        directions: (n, 3) initial unit light directions (surface to light, unps frame).
        rank: the low-rank part's rank (3: Lambertian).

    Returns:
        (m, 3) scaled normals B and (n, 3) scaled lights S with B·Sᵀ the low-rank part and S's
        rows as nearly parallel to ``directions`` as one 3×3 matrix can make them; |s_i| is the
        intensity of light i relative to the others, and the frame is that of ``directions``.
    """
    low_rank = partial_sum_rpca(gray, rank).low_rank                          # (m, n)
    u, sigma, vt = np.linalg.svd(low_rank, full_matrices=False)
    lights = vt[:3].T * np.sqrt(sigma[:3])                                    # (n, 3), up to T
    lights = lights @ parallel_transform(lights, np.asarray(directions, dtype=np.float64))
    normals = np.linalg.lstsq(lights, low_rank.T, rcond=None)[0].T            # Z ≈ B Sᵀ
    return normals, lights


def held_factorization(gray: np.ndarray, scaled_lights: np.ndarray, rank: int = 3) -> np.ndarray:
    """The scaled normals that best explain the low-rank part of the image matrix under lights
    held as given.

    Args:
        gray: (m, n) pixel × image brightness.
        scaled_lights: (n, 3) directions × relative intensities.

    Returns:
        (m, 3) scaled normals B with B·Sᵀ nearest the low-rank part in least squares.
    """
    low_rank = partial_sum_rpca(gray, rank).low_rank
    return np.linalg.lstsq(np.asarray(scaled_lights, np.float64), low_rank.T, rcond=None)[0].T


def parallel_transform(lights: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """The 3×3 T (scaled to a mean |s_i T| of 1) that makes each row s_i T most nearly parallel to
    d_i: the least-squares solution of (I − d_i d_iᵀ)·Tᵀ s_i = 0, with the sign that points the
    rows along the d_i.

    Args:
        lights: (n, 3) rows s_i, n ≥ 4; directions: (n, 3) unit d_i.
    """
    across = np.eye(3)[None] - directions[:, :, None] * directions[:, None, :]   # (n, 3, 3)
    rows = np.einsum("nij,nk->nijk", across, lights).reshape(-1, 9)              # acts on vec(Tᵀ)
    transform = np.linalg.svd(rows)[2][-1].reshape(3, 3).T
    aligned = lights @ transform
    sign = np.sign(np.sum(aligned * directions)) or 1.0
    return sign * transform / np.linalg.norm(aligned, axis=1).mean()

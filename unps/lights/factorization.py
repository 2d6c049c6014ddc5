"""The surface the images' low-rank part gives under lights held as they are.

Under distant lights a Lambertian object's images form a rank-3 matrix X = B·Sᵀ (pixels ×
images; B the scaled normals ρn, S the scaled lights e·l). The robust initialisation
(:mod:`unps.solvers.rpca`) recovers that low-rank part Z from the captured images, shadows and
highlights aside; with S given, B = Z·S⁺ᵀ. Self-calibration starts its surface there
(:mod:`unps.lights.selfcal`).
"""

from __future__ import annotations

import numpy as np

from unps.solvers.rpca import partial_sum_rpca


def normals_under(gray: np.ndarray, scaled_lights: np.ndarray, rank: int = 3) -> np.ndarray:
    """The scaled normals that best explain the low-rank part of the image matrix under lights
    held as given.

    Args:
        gray: (m, n) pixel × image brightness.
        scaled_lights: (n, 3) directions × relative intensities (unps frame, surface to light).

    Returns:
        (m, 3) scaled normals B with B·Sᵀ nearest the low-rank part in least squares.

    >>> rng = np.random.default_rng(0)
    >>> normals = rng.normal(size=(50, 3)); lights = rng.normal(size=(8, 3))
    >>> bool(np.allclose(normals_under(normals @ lights.T, lights), normals, atol=1e-6))
    True
    """
    low_rank = partial_sum_rpca(gray, rank).low_rank
    return np.linalg.lstsq(np.asarray(scaled_lights, np.float64), low_rank.T, rcond=None)[0].T

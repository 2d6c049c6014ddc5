"""What a method returns: every method is ``method(subject, light_directions, **options) -> Estimate``.

Frame: x right, y up, z toward the camera; maps are (H, W, C) on the subject's grid.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Rendering:
    """What a rendering method explains, on its working grid (h, w).

    Attributes:
        mask: (h, w) bool.
        observed, reconstruction, reflectance: (n, h, w, 3) float32: the images divided by their
            intensities, the model's rendering of them, and its reflectance maps.
    """

    mask: np.ndarray
    observed: np.ndarray
    reconstruction: np.ndarray
    reflectance: np.ndarray


@dataclass(frozen=True)
class Estimate:
    """A method's answer for one subject.

    Attributes:
        normals: (H, W, 3) float32 unit normals (zero off the mask).
        albedo: (H, W, 3) float32 RGB albedo (zero off the mask).
        light_directions: (n, 3) unit directions the method ended with when it refined the
            lights it was given (``method.refine_lights``), else None.
        light_scales: (n,) the intensity factors it found with them (geometric mean 1), else None.
        rendering: the per-image maps of a rendering method, else None.
        info: the method's own figures for ``metrics.json`` (steps, grid, timings, …).
    """

    normals: np.ndarray
    albedo: np.ndarray
    light_directions: np.ndarray | None = None
    light_scales: np.ndarray | None = None
    rendering: Rendering | None = None
    info: dict = field(default_factory=dict)

"""The occluding contour fixes the rotation that estimated lights leave free.

Rotating every light and every normal by the same R leaves Lambertian shading n·l unchanged, so
the images alone cannot tell lights rotated by R from the true ones, and a light network's
global rotation error passes straight into the normals. On the object's outline, though, the
surface turns away from the camera: the true normals there are perpendicular to the view axis
and point outward, across the outline. :func:`contour_rotation` finds the R that best turns
the normals estimated with the lights onto those directions (Kabsch), and
:class:`ContourAlignment` applies it to the lights.

Frame: x right (+col), y up (−row), z toward the camera.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from scipy.ndimage import binary_erosion

from unps.data.lights import Verdict
from unps.data.subject import Subject
from unps.geometry import outward_directions
from unps.lights import Lights, with_lights
from unps.metrics import angular_error
from unps.solvers.rpca import robust_init

MIN_CONTOUR_PIXELS = 50
MAX_CONTOUR_MISFIT = 45.0   # degrees: median angle left on the contour after the best rotation
MIN_ROTATION = 5.0          # degrees: smaller rotations are within the estimate's own error
MAX_ROTATION = 45.0         # degrees: larger ones are the outline's error, not the estimate's


def outward_normals(mask: np.ndarray, band: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """The occluding contour's pixels and the normals a smooth surface has there.

    Args:
        mask: (H, W) bool object mask.
        band: width in pixels of the contour band inside the mask.

    Returns:
        (H, W) bool, the band's pixels, leaving out those within ``band`` of the image border
        (an object cut by the frame has no contour there); (H, W, 3) unit normals
        (:func:`unps.geometry.outward_directions` in the image plane, z = 0).
    """
    band_pixels = mask & ~binary_erosion(mask, iterations=band, border_value=1)
    inner = np.zeros_like(mask)
    inner[band:-band, band:-band] = True
    across = outward_directions(mask)
    outward = np.concatenate([across, np.zeros(mask.shape + (1,))], -1)
    return band_pixels & inner & (np.linalg.norm(across, axis=-1) > 0.5), outward


def contour_rotation(normals: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray | None, str]:
    """The rotation R that best turns the contour's estimated normals onto the outward ones.

    Args:
        normals: (H, W, 3) unit normals estimated with the lights to correct.
        mask: (H, W) bool.

    Returns:
        (3, 3) proper rotation maximising Σ tᵢ·(R nᵢ) over the contour, and what it rests on; or
        None and why not: the contour has fewer than ``MIN_CONTOUR_PIXELS`` pixels, or even
        rotated the normals there stay more than ``MAX_CONTOUR_MISFIT`` from facing sideways
        (median), so the outline is not an occluding contour (a rim, a break) or the normals
        are too wrong to say.
    """
    contour, outward = outward_normals(mask)
    count = int(contour.sum())
    if count < MIN_CONTOUR_PIXELS:
        return None, f"{count} pixels of occluding contour off the image border, fewer than " \
                     f"{MIN_CONTOUR_PIXELS}"
    estimated = normals[contour].astype(np.float64)
    rotation = best_rotation(estimated, outward[contour])
    misfit = float(np.median(angular_error(estimated @ rotation.T, outward[contour])))
    if misfit > MAX_CONTOUR_MISFIT:
        return None, f"the outline's normals stay {misfit:.1f}° (median) from facing sideways " \
                     f"after the best rotation, more than {MAX_CONTOUR_MISFIT:.0f}°"
    return rotation, f"{count} contour pixels, median misfit {misfit:.1f}°"


def best_rotation(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(3, 3) proper rotation R maximising Σ tᵢ·(R sᵢ) (Kabsch), for rows sᵢ of ``source`` and
    tᵢ of ``target``, both (n, 3); for unit vectors it minimises Σ‖R sᵢ − tᵢ‖²."""
    u, _, vt = np.linalg.svd(target.T @ source)                                 # Σ t sᵀ
    return u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))]) @ vt


def rotation_angle(rotation: np.ndarray) -> float:
    """Degrees a (3, 3) rotation turns by."""
    return float(np.degrees(np.arccos(np.clip((np.trace(rotation) - 1) / 2, -1, 1))))


@dataclass(frozen=True)
class ContourAlignment:
    """The light stage that rotates estimated lights so that the robust initialisation's normals
    with them face outward on the occluding contour (off by default: on DiLiGenT's cat it turned
    a good estimate by 17.6°, ``experiments/light_estimation/README.md``).

    Rotations under ``min_rotation`` are left undone: on DiLiGenT's ground-truth normals the
    contour itself asks for up to 4.8° (cat), since its band is not everywhere an occluding
    contour, so smaller rotations are as likely to be its error as the network's. Nor is one over
    ``max_rotation`` applied: the broken rim of BrokenPot, no occluding contour, asks to turn
    lights that cast shadows have put right by 179°.

    Attributes:
        min_rotation, max_rotation: degrees.
        device: where the robust initialisation runs (the run's ``device=``).
    """

    name: ClassVar[str] = "contour"
    min_rotation: float = MIN_ROTATION
    max_rotation: float = MAX_ROTATION
    device: str = "auto"

    def __call__(self, subject: Subject, lights: Lights) -> tuple[Lights, Verdict]:
        """The lights with every direction rotated by :func:`contour_rotation` (intensities
        unchanged), or as given when that finds no rotation it can trust; and the verdict."""
        normals = robust_init(with_lights(subject, lights), lights.directions, device=self.device).normals
        rotation, basis = contour_rotation(normals, subject.mask)
        if rotation is None:
            return lights, Verdict(self.name, "declined", basis)
        angle = rotation_angle(rotation)
        evidence = {"rotation_deg": angle}
        if angle > self.max_rotation:
            return lights, Verdict(self.name, "declined", f"the occluding contour asks for a rotation "
                                   f"of {angle:.1f}°, more than the {self.max_rotation:.0f}° it is "
                                   f"trusted to correct: the outline is unlikely to be an occluding "
                                   f"contour ({basis})", evidence)
        if angle < self.min_rotation:
            return lights, Verdict(self.name, "kept", f"the occluding contour asks for a rotation of "
                                   f"{angle:.2f}°, under the {self.min_rotation:.0f}° it can tell "
                                   f"apart ({basis})", evidence)
        directions = (lights.directions.astype(np.float64) @ rotation.T).astype(np.float32)
        moved = float(angular_error(directions, lights.directions).mean())
        return dataclasses.replace(lights, directions=directions), Verdict(
            self.name, "changed", f"rotated the lights by {angle:.2f}° to the occluding contour "
            f"(moved by {moved:.2f}° on average; {basis})", evidence)

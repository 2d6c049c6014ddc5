"""Where a fit's lights come from (the ``light=`` config group)."""

from __future__ import annotations

import numpy as np

from unps.data.lights import Lights
from unps.data.subject import Subject
from unps.errors import InputError
from unps.io.files import atomic_path
from unps.metrics import light_direction_mae, light_intensity_error, light_slant_bias

__all__ = ["Lights", "ground_truth", "light_errors", "with_lights", "write_lights"]


def ground_truth(subject: Subject) -> Lights:
    """The subject's own calibrated lights (``light=gt``)."""
    if not subject.calibrated:
        raise InputError(f"subject {subject.name!r} has no light directions, so light=gt cannot "
                         f"be used: put a light_directions.txt (n×3, one row per image) in its "
                         f"folder")
    return Lights(subject.light_directions, subject.light_intensities, "gt")


def with_lights(subject: Subject, lights: Lights) -> Subject:
    """The subject as the method must see it with these lights: captured images divided by
    their intensities, and the lights in place of any known ones."""
    observed = subject.observed_images()
    intensities = lights.intensities
    images = observed / intensities[:, None, None, :] if intensities is not None else observed
    return subject.replace(images=images, light_directions=lights.directions,
                           light_intensities=intensities)


def light_errors(lights: Lights, subject: Subject) -> dict[str, float]:
    """``light_dir_mae`` and ``light_slant_bias`` (degrees; :func:`unps.metrics.light_slant_bias`:
    < 0 where the lights are read nearer the view axis than they are) and ``light_int_err``
    (scale-invariant, on the mean of RGB) of ``lights`` against the subject's own, those it has."""
    errors = {}
    if subject.light_directions is not None:
        errors["light_dir_mae"] = light_direction_mae(lights.directions, subject.light_directions)
        errors["light_slant_bias"] = light_slant_bias(lights.directions, subject.light_directions)
    if subject.light_intensities is not None and lights.intensities is not None:
        errors["light_int_err"] = light_intensity_error(lights.intensities.mean(1),
                                                        subject.light_intensities.mean(1))
    return errors


def write_lights(path, lights: Lights) -> None:
    """Write lights as text, one image per row: ``lx ly lz e_r e_g e_b``, atomically."""
    intensities = lights.intensities
    if intensities is None:
        intensities = np.ones_like(lights.directions)
    header = (f"lights ({lights.source}); one row per image: lx ly lz (unit, surface to "
              f"light; x right, y up, z toward the camera) e_r e_g e_b (RGB intensity)")
    with atomic_path(path) as tmp:
        np.savetxt(tmp, np.hstack([lights.directions, intensities]), fmt="%.6f", header=header)

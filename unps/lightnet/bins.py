"""Light directions and intensities as classification bins (LCNet / SDPS-Net).

Frame: x right, y up, z toward the camera; directions point from the surface to the light
(z > 0). Azimuth = atan(x / z) and elevation = atan(y / √(x² + z²)), both in [−90°, 90°],
each split into 36 bins of 5°. Intensities are relative to the mean of their stack and split
into 20 bins over [0.2, 2].
"""

from __future__ import annotations

import math

import torch

ANGLE_BINS = 36
ANGLE_RANGE = (-math.pi / 2, math.pi / 2)
INTENSITY_BINS = 20
INTENSITY_RANGE = (0.2, 2.0)


def direction_to_angles(directions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(..., 3) unit directions → azimuth, elevation (...) in radians.

    Example:
        >>> az, el = direction_to_angles(torch.tensor([0.0, 0.0, 1.0]))
        >>> float(az), float(el)
        (0.0, 0.0)
    """
    x, y, z = directions.unbind(-1)
    return torch.atan2(x, z), torch.atan2(y, torch.sqrt(x ** 2 + z ** 2))


def angles_to_direction(azimuth: torch.Tensor, elevation: torch.Tensor) -> torch.Tensor:
    """Inverse of :func:`direction_to_angles`: (...) radians → (..., 3) unit directions."""
    c = torch.cos(elevation)
    return torch.stack([c * torch.sin(azimuth), torch.sin(elevation), c * torch.cos(azimuth)], -1)


def bin_centres(count: int, low: float, high: float, device: torch.device | None = None) -> torch.Tensor:
    """(count,) float32 centres of ``count`` equal bins over [low, high], made on ``device`` (a
    GPU copying them from the CPU at every training step would wait for its queue each time)."""
    width = (high - low) / count
    return low + width * (torch.arange(count, dtype=torch.float32, device=device) + 0.5)


def to_bin(values: torch.Tensor, count: int, low: float, high: float) -> torch.Tensor:
    """Index of the bin holding each value; values outside [low, high] go to the end bins."""
    index = torch.floor((values - low) / (high - low) * count).long()
    return index.clamp(0, count - 1)


def decode(logits: torch.Tensor, low: float, high: float, soft: bool) -> torch.Tensor:
    """(..., count) logits → (...) values: the arg-max bin's centre, or the soft-arg-max
    (softmax-weighted mean of the centres, as GCNet decodes)."""
    centres = bin_centres(logits.shape[-1], low, high, logits.device).to(logits.dtype)
    if soft:
        return (torch.softmax(logits, -1) * centres).sum(-1)
    return centres[logits.argmax(-1)]


def encode_lights(directions: torch.Tensor, intensities: torch.Tensor
                  ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Targets for the classifier.

    Args:
        directions: (..., n, 3) unit.
        intensities: (..., n) per-image scalars (any common scale).

    Returns:
        azimuth, elevation and intensity bin indices, each (..., n). Intensities are divided
        by the mean over the n images first.
    """
    az, el = direction_to_angles(directions)
    relative = intensities / intensities.mean(-1, keepdim=True)
    return (to_bin(az, ANGLE_BINS, *ANGLE_RANGE), to_bin(el, ANGLE_BINS, *ANGLE_RANGE),
            to_bin(relative, INTENSITY_BINS, *INTENSITY_RANGE))


def decode_lights(azimuth_logits: torch.Tensor, elevation_logits: torch.Tensor,
                  intensity_logits: torch.Tensor, soft: bool = True
                  ) -> tuple[torch.Tensor, torch.Tensor]:
    """Logits (..., bins) → directions (..., 3) unit and intensities (...)."""
    az = decode(azimuth_logits, *ANGLE_RANGE, soft)
    el = decode(elevation_logits, *ANGLE_RANGE, soft)
    return angles_to_direction(az, el), decode(intensity_logits, *INTENSITY_RANGE, soft)

"""The eight symmetries of the square: each maps a photometric-stereo stack onto another exact one.

Turning the images by a quarter about the view axis, or mirroring them, shows the same object
turned or mirrored, lit by lights turned or mirrored the same way; with an orthographic camera
and isotropic materials (shadows, interreflections and highlights included) the images are
exactly those of that scene. The light network need not have learnt this, so estimating under
all eight and mapping each answer back gives eight estimates of the same lights: their mean is a
better estimate and their spread says how far the network can be trusted on this subject.

Frame: x right, y up, z toward the camera; images are (..., H, W) with row 0 at the top.
"""

from __future__ import annotations

import torch

SYMMETRIES: tuple[tuple[int, bool], ...] = tuple((turns, mirror) for mirror in (False, True)
                                                 for turns in range(4))


def transform_images(images: torch.Tensor, turns: int, mirror: bool) -> torch.Tensor:
    """Mirror left-right (when ``mirror``), then turn ``turns`` quarters counter-clockwise as
    displayed; (..., H, W) → (..., W, H) for odd ``turns``."""
    if mirror:
        images = images.flip(-1)
    return torch.rot90(images, turns, dims=(-2, -1))


def frame_matrix(turns: int, mirror: bool) -> torch.Tensor:
    """(3, 3) M: the scene seen in :func:`transform_images`'s output has normals and lights M·v.

    Example:
        >>> frame_matrix(1, False) @ torch.tensor([1.0, 0.0, 0.5])   # right turns to up
        tensor([0.0000, 1.0000, 0.5000])
    """
    quarter = torch.tensor([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    m = torch.diag(torch.tensor([-1.0 if mirror else 1.0, 1.0, 1.0]))
    return torch.linalg.matrix_power(quarter, turns) @ m


def mean_direction(directions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Unit mean of S estimates of n directions, and their spread.

    Args:
        directions: (S, n, 3) unit.

    Returns:
        (n, 3) unit mean directions and (n,) spread: the mean angle in degrees between each
        estimate and the mean.
    """
    mean = torch.nn.functional.normalize(directions.mean(0), dim=-1)
    cos = (directions * mean).sum(-1).clamp(-1, 1)
    return mean, torch.rad2deg(torch.acos(cos)).mean(0)

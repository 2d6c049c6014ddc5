"""The symmetries of the square map a stack onto an exact stack of the turned or mirrored scene."""

import numpy as np
import pytest
import torch

from unps.lightnet.estimate import network_lights
from unps.lightnet.symmetry import SYMMETRIES, frame_matrix, mean_direction, transform_images
from unps.lightnet.shapes import maps_from_depth


def lopsided_depth(size: int = 33) -> torch.Tensor:
    """A height field with no symmetry of the square: two bumps of different widths, a tilt."""
    y, x = torch.meshgrid(torch.linspace(1, -1, size), torch.linspace(-1, 1, size), indexing="ij")
    return (0.6 * torch.exp(-((x - 0.3) ** 2 + (y - 0.4) ** 2) / 0.1)
            + 0.3 * torch.exp(-((x + 0.5) ** 2 + (y + 0.2) ** 2) / 0.05) + 0.2 * x - 0.1 * y)


@pytest.mark.parametrize("turns, mirror", SYMMETRIES)
def test_the_turned_height_field_has_the_turned_normals(turns, mirror):
    depth = lopsided_depth()
    full = torch.ones_like(depth, dtype=torch.bool)
    normals = maps_from_depth(depth, full).normals                           # (H, W, 3)
    seen = maps_from_depth(transform_images(depth, turns, mirror), full).normals
    expected = transform_images(normals.permute(2, 0, 1), turns, mirror).permute(1, 2, 0)
    torch.testing.assert_close(seen, expected @ frame_matrix(turns, mirror).T, atol=1e-5, rtol=0)


def test_the_eight_frames_are_distinct_rotations_and_reflections():
    matrices = torch.stack([frame_matrix(t, m) for t, m in SYMMETRIES])
    torch.testing.assert_close(matrices @ matrices.transpose(1, 2), torch.eye(3).expand(8, 3, 3))
    assert len({tuple(m.flatten().tolist()) for m in matrices}) == 8
    assert all(float(torch.linalg.det(frame_matrix(t, m))) == (-1 if m else 1) for t, m in SYMMETRIES)


def test_mean_direction_and_spread():
    a = torch.tensor([[1.0, 0.0, 1.0]]) / np.sqrt(2)
    b = torch.tensor([[-1.0, 0.0, 1.0]]) / np.sqrt(2)
    mean, spread = mean_direction(torch.stack([a, b]))
    torch.testing.assert_close(mean, torch.tensor([[0.0, 0.0, 1.0]]))
    torch.testing.assert_close(spread, torch.tensor([45.0]))


def test_the_default_estimate_is_symmetric_and_reports_its_spread_one_pass_does_not(sphere):
    symmetric, _ = network_lights(sphere)
    one_pass, _ = network_lights(sphere, symmetric=False, framings=[1.0])
    assert symmetric.spread_deg.shape == (sphere.n_images,) and (symmetric.spread_deg >= 0).all()
    assert one_pass.spread_deg is None
    np.testing.assert_allclose(np.linalg.norm(symmetric.directions, axis=1), 1, atol=1e-5)
    np.testing.assert_allclose(symmetric.intensities.mean(), 1, atol=1e-5)


def test_the_default_passes_show_each_symmetry_once_and_each_framing_mirrored_and_not():
    from unps.lightnet.estimate import FRAMINGS, paired
    passes = paired(FRAMINGS, SYMMETRIES)
    assert len(passes) == 8 and sorted(frame for _, frame in passes) == sorted(SYMMETRIES)
    for fill in FRAMINGS:
        assert sorted(mirror for f, (_, mirror) in passes if f == fill) == [False, True]

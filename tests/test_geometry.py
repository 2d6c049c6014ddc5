import numpy as np
import pytest
import torch

from unps.data.analytic import height_field
from unps.grid import Frame
from unps import geometry
from unps.geometry import depth_to_mesh, integrate_normals
from unps.io.mesh import write_ply


@pytest.mark.parametrize("shape, tolerance", [("sphere", 1e-4), ("bumps", 0.05)])
def test_integration_recovers_an_analytic_surface(shape, tolerance):
    depth, normals, mask = height_field(shape, 64, seed=4)
    z = integrate_normals(normals, mask)
    truth = depth[mask] - depth[mask].mean()
    assert np.isnan(z[~mask]).all()
    assert np.abs(z[mask] - truth).max() < tolerance * np.ptp(truth) + 1e-4
    assert abs(z[mask].mean()) < 1e-6


def test_each_part_of_the_mask_gets_zero_mean():
    normals = np.zeros((4, 9, 3))
    normals[..., 0], normals[..., 2] = -0.6, 0.8        # dz/dx = 0.75 everywhere
    mask = np.zeros((4, 9), bool)
    mask[:, :3] = mask[:, 5:] = True
    z = integrate_normals(normals, mask)
    np.testing.assert_allclose(z[0, :3], [-0.75, 0, 0.75], atol=1e-9)
    np.testing.assert_allclose(z[0, 5:], [-1.125, -0.375, 0.375, 1.125], atol=1e-9)


def test_mesh_faces_point_to_the_camera_and_follow_the_frame(tmp_path):
    depth = np.zeros((3, 3), np.float32)
    mask = np.ones((3, 3), bool)
    mask[2, 2] = False                                   # one block of three pixels
    v, f = depth_to_mesh(depth, mask)
    assert len(v) == 8 and len(f) == 2 + 2 + 2 + 1
    normal = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    assert (normal[:, 2] > 0).all()
    v2, _ = depth_to_mesh(depth + 1, mask, Frame((20, 20), top=4, left=6, step=2))
    np.testing.assert_allclose(v2[0], [6.5, -4.5, 2.0])   # centre of the source block, z × step

    write_ply(tmp_path / "m.ply", v, f, normals=np.tile([0, 0, 1.0], (8, 1)).astype(np.float32))
    data = (tmp_path / "m.ply").read_bytes()
    header, body = data.split(b"end_header\n")
    assert b"element vertex 8" in header and b"element face 7" in header
    verts = np.frombuffer(body[: 8 * 24], "<f4").reshape(8, 6)
    np.testing.assert_array_equal(verts[:, :3], v)
    faces = np.frombuffer(body[8 * 24:], dtype=[("n", "u1"), ("v", "<i4", (3,))])
    np.testing.assert_array_equal(faces["v"], f)


def marched_everywhere(depth, mask, lights, pitch, steps):
    """Reference shadows: every object pixel, every light, every sample along the diagonal."""
    h, w = depth.shape
    out = np.zeros((len(lights), h, w), bool)
    distances = np.linspace(1, np.hypot(h, w), steps)
    for k, (lx, ly, lz) in enumerate(lights):
        planar = max(np.hypot(lx, ly), 1e-6)
        for row, col in zip(*np.nonzero(mask)):
            for d in distances:
                r, c = int(np.round(row - d * ly / planar)), int(np.round(col + d * lx / planar))
                if 0 <= r < h and 0 <= c < w and mask[r, c] and \
                        depth[r, c] > depth[row, col] + d * pitch * lz / planar + 1e-3:
                    out[k, row, col] = True
                    break
    return out


def test_cast_shadows_match_marching_every_sample_along_every_ray():
    rng = np.random.default_rng(3)
    y, x = np.mgrid[-1:1:24j, -1:1:24j]
    depth = (0.6 * np.exp(-((x - 0.2) ** 2 + y ** 2) / 0.05) - 0.4 * np.exp(-((x + 0.4) ** 2 + (y - 0.3) ** 2) / 0.1)
             + 0.05 * rng.standard_normal((24, 24))).astype(np.float32)
    mask = np.hypot(x, y) < 0.95
    lights = rng.standard_normal((12, 3))
    lights[:, 2] = np.abs(lights[:, 2]) + np.linspace(0, 3, 12)     # grazing to nearly overhead
    lights[0] = [0, 0, 1]
    lights /= np.linalg.norm(lights, axis=1, keepdims=True)
    for pitch in (2 / 23, 0.5):
        got = geometry.cast_shadows(torch.as_tensor(depth), torch.as_tensor(mask),
                                    torch.as_tensor(lights, dtype=torch.float32), pitch, steps=20, chunk=5)
        expected = marched_everywhere(depth, mask, lights.astype(np.float32), pitch, 20)
        assert expected.any() and not expected[0].any()
        np.testing.assert_array_equal(got.numpy(), expected)

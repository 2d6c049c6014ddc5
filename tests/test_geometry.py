import numpy as np
import pytest

from unps.data.analytic import height_field
from unps.grid import Frame
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

import numpy as np
import pytest
import torch
from scipy.ndimage import binary_dilation, binary_erosion

from unps.data.analytic import height_field
from unps.grid import Frame
from unps import geometry
from unps.geometry import continue_surface, depth_to_mesh, integrate_normals
from unps.io.mesh import write_ply
from unps.metrics import angular_error


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


def test_a_hole_without_normals_is_spanned_from_its_rim():
    """Pixels without a normal (0, as for pixels black in every image) next to one another left
    the equations singular, and the whole depth NaN; now the hole is spanned from its rim."""
    depth, normals, mask = height_field("sphere", 64, seed=4)
    hole = np.zeros_like(mask)
    hole[28:36, 28:36] = True
    holed = normals.copy()
    holed[hole] = 0.0
    z = integrate_normals(holed, mask)
    assert np.isfinite(z[mask]).all()
    truth = depth - depth[mask].mean()
    seen = mask & ~hole
    assert np.abs((z - truth)[seen]).max() < 0.02 * np.ptp(truth[mask])
    rim = binary_dilation(hole) & ~hole
    assert z[rim].min() - 0.5 <= z[hole].min() and z[hole].max() <= truth[hole].max() + 0.5


def test_a_normal_that_is_not_finite_counts_as_none():
    depth, normals, mask = height_field("sphere", 32, seed=4)
    spoilt = normals.copy()
    spoilt[16, 16] = np.nan
    z = integrate_normals(spoilt, mask)
    assert np.isfinite(z[mask]).all()
    truth = depth - depth[mask].mean()
    assert np.abs((z - truth)[mask]).max() < 0.02 * np.ptp(truth[mask])


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


def test_shadows_of_a_batch_are_each_image_s_shadows():
    """Several depth maps under their own lights, one empty mask among them: the batch march gives
    bit for bit what each map's own march gives, whatever the share of work marched at once."""
    rng = np.random.default_rng(5)
    y, x = np.mgrid[-1:1:20j, -1:1:20j]
    depths, masks = [], []
    for k in range(4):
        bump = 0.8 * np.exp(-((x - 0.3 * k + 0.4) ** 2 + y ** 2) / 0.08) + 0.05 * rng.standard_normal((20, 20))
        depths.append(torch.as_tensor(bump, dtype=torch.float32))
        masks.append(torch.as_tensor(np.hypot(x, y) < 0.9 - 0.1 * k) if k < 3 else torch.zeros(20, 20, dtype=bool))
    lights = torch.as_tensor(rng.standard_normal((4, 7, 3)), dtype=torch.float32)
    lights[..., 2] = lights[..., 2].abs() + 0.2
    lights = lights / lights.norm(dim=-1, keepdim=True)
    each = torch.stack([geometry.cast_shadows(d, m, light, 0.1, steps=16)
                        for d, m, light in zip(depths, masks, lights)])
    assert each[:3].any() and not each[3].any()
    for budget in (1, 2 ** 12, None):
        plan = geometry.plan_shadows(torch.stack(depths), torch.stack(masks), lights, 0.1, steps=16)
        batch = geometry.march_shadows(plan, torch.device("cpu"), budget=budget)
        assert torch.equal(batch, each)


def sphere_normals(size: int = 48) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(H, W, 3) unit normals of a sphere of radius 1 over [−1, 1]², its mask (r² < 0.8), and x."""
    y, x = np.mgrid[-1:1:size * 1j, -1:1:size * 1j]
    mask = x ** 2 + y ** 2 < 0.8
    normals = np.stack([x, -y, np.sqrt(np.clip(1 - x ** 2 - y ** 2, 0, None))], -1)   # y up = −row
    return normals / np.linalg.norm(normals, axis=-1, keepdims=True), mask, x


def test_a_region_the_images_miss_is_continued_from_the_surface_around_it():
    """A band of scrambled normals across a sphere comes back within a few degrees of the sphere's;
    every other pixel is kept as it was; with nothing unseen, nothing changes."""
    sphere, mask, x = sphere_normals()
    band = mask & (np.abs(x - 0.1) < 0.15)
    scrambled = sphere.copy()
    scrambled[band] = [0.6, 0.0, 0.8]
    continued = continue_surface(scrambled, mask, band)
    np.testing.assert_array_equal(continued[~band], scrambled[~band].astype(np.float32))
    assert angular_error(scrambled[band], sphere[band]).mean() > 20
    assert angular_error(continued[band], sphere[band]).mean() < 5
    np.testing.assert_array_equal(continue_surface(scrambled, mask, np.zeros_like(mask)),
                                  scrambled.astype(np.float32))


@pytest.mark.parametrize("seen_from", ["outside", "inside"])
def test_a_surface_continued_to_the_outline_leans_across_it_as_the_seen_outline_does(seen_from):
    """A sphere's left cap unseen up to its outline: continued with the occluding contour it comes
    back within 5°; the least-curved surface alone runs on flat to the outline, 13° off. The same
    for the sphere seen from inside (a shell, its outline leaning inward)."""
    sphere, mask, x = sphere_normals(64)
    if seen_from == "inside":
        sphere = sphere * [-1, -1, 1]
    cap = mask & (x < -0.45)
    start = np.where(cap[..., None], [0.0, 0.0, 1.0], sphere)
    with_outline = continue_surface(start, mask, cap)
    without = continue_surface(start, mask, cap, outline=False)
    assert angular_error(with_outline[cap], sphere[cap]).mean() < 5
    assert angular_error(without[cap], sphere[cap]).mean() > 10
    np.testing.assert_array_equal(with_outline[~cap], start[~cap].astype(np.float32))


@pytest.mark.parametrize("radius", [8.0, 18.0, 40.0])
def test_outward_directions_on_a_pixelated_disc_are_radial(radius):
    size = int(2 * radius + 12)
    r, c = np.mgrid[0:size, 0:size] - size / 2
    disc = np.hypot(r, c) <= radius
    outline = disc & ~binary_erosion(disc)
    outward = geometry.outward_directions(disc)[outline]
    radial = np.stack([c, -r], -1)[outline]
    radial /= np.linalg.norm(radial, axis=-1, keepdims=True)
    off = np.degrees(np.arccos(np.clip((outward * radial).sum(-1), -1, 1)))
    assert off.mean() < 1.2 and off.max() < 4


def test_an_outline_that_leans_no_one_way_is_left_alone():
    """A tilted plane leans outward across one side of its outline and inward across the other:
    nothing to continue there, and the plane comes back as it is. An outline seen on less than a
    tenth of its length says nothing either, nor one whose normals face away from the camera."""
    _, mask, x = sphere_normals(64)
    plane = np.broadcast_to(np.array([0.3, 0.2, np.sqrt(0.87)]), mask.shape + (3,))
    cap = mask & (x < -0.45)
    assert geometry.outline_normals(plane, mask, cap) is None
    continued = continue_surface(np.where(cap[..., None], [0.0, 0.0, 1.0], plane), mask, cap)
    assert angular_error(continued[cap], plane[cap]).max() < 0.1
    sphere, _, _ = sphere_normals(64)
    assert geometry.outline_normals(sphere, mask, mask & (x > -0.86)) is None       # 5 % of it seen
    away = sphere * [1, 1, -1]                    # the seen outline facing away from the camera: noise
    assert geometry.outline_normals(away, mask, cap) is None


def test_an_unseen_region_at_the_image_border_is_continued_without_wrapping_around():
    """A bowl z = 0.01·(col² + row²) filling the frame, its last three columns unseen: their
    normals come back from the columns before them (straight on: the bowl's curvature is not
    continued), not from the frame's other side."""
    rows, cols = np.mgrid[0:20, 0:24].astype(float)
    normals = np.stack([-0.02 * cols, 0.02 * rows, np.ones_like(rows)], -1)   # (−∂z/∂col, ∂z/∂row, 1)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    full = np.ones((20, 24), bool)
    unseen = np.zeros_like(full)
    unseen[:, -3:] = True
    continued = continue_surface(np.where(unseen[..., None], [0.0, 0.0, 1.0], normals), full, unseen)
    assert angular_error(continued[unseen], normals[unseen]).max() < 8     # wrapped around: > 40°

"""The occluding-contour alignment of estimated lights (unps.lights.contour)."""

import numpy as np
from scipy.spatial.transform import Rotation

from unps.data.analytic import render_lambertian
from unps.lights import Lights
from unps.metrics import angular_error
from unps.lights.contour import ContourAlignment, contour_rotation, outward_normals, rotation_angle


def disc(size=48, radius=18.0, centre=(24, 24)):
    r, c = np.mgrid[0:size, 0:size]
    return (r - centre[0]) ** 2 + (c - centre[1]) ** 2 <= radius ** 2


def test_outward_normals_point_away_from_the_centre_and_skip_the_image_border():
    mask = disc()
    contour, outward = outward_normals(mask)
    rows, cols = np.nonzero(contour)
    radial = np.stack([cols - 24.0, -(rows - 24.0), 0 * rows], 1)      # x right, y up
    assert contour.sum() > 100 and not contour[~mask].any()
    assert angular_error(outward[contour], radial).max() < 6
    assert (outward[contour][:, 2] == 0).all()
    cut = disc(centre=(24, 2))                                           # runs off the left edge
    contour, _ = outward_normals(cut)
    assert contour.any() and not contour[:, :2].any()


def test_contour_rotation_undoes_a_rotation_of_a_spheres_normals():
    sphere = render_lambertian("sphere", size=64, n_lights=8)
    turn = Rotation.from_euler("xyz", [10, -6, 15], degrees=True).as_matrix()
    turned = sphere.normals @ turn.T
    rotation, basis = contour_rotation(turned, sphere.mask)
    assert rotation_angle(rotation @ turn) < 2.5 and "contour pixels" in basis
    identity, _ = contour_rotation(sphere.normals, sphere.mask)
    assert rotation_angle(identity) < 1


def test_contour_rotation_declines_what_it_cannot_trust():
    mask = disc()
    facing = np.zeros(mask.shape + (3,))
    facing[..., 2] = 1                       # a flat disc facing the camera: no occluding contour
    rotation, why = contour_rotation(facing, mask)
    assert rotation is None and "from facing sideways" in why
    rotation, why = contour_rotation(facing, np.ones_like(mask))   # the object fills the frame
    assert rotation is None and "fewer than" in why


def test_contour_alignment_corrects_globally_rotated_lights():
    sphere = render_lambertian("sphere", size=64, n_lights=16)
    turn = Rotation.from_euler("xyz", [-8, 12, 10], degrees=True).as_matrix()
    estimate = Lights((sphere.light_directions @ turn.T).astype(np.float32), sphere.light_intensities,
                      "estimated")
    aligned, verdict = ContourAlignment()(sphere, estimate)
    assert verdict.outcome == "changed" and verdict.evidence["rotation_deg"] > 10
    before = angular_error(estimate.directions, sphere.light_directions).mean()
    after = angular_error(aligned.directions, sphere.light_directions).mean()
    assert before > 10 and after < before / 3
    np.testing.assert_array_equal(aligned.intensities, estimate.intensities)
    assert aligned.source == "estimated"


def test_contour_alignment_keeps_lights_that_are_off_by_less_than_it_can_tell():
    sphere = render_lambertian("sphere", size=64, n_lights=16)
    turn = Rotation.from_euler("z", 2, degrees=True).as_matrix()
    estimate = Lights((sphere.light_directions @ turn.T).astype(np.float32), sphere.light_intensities,
                      "estimated")
    kept, verdict = ContourAlignment()(sphere, estimate)
    assert kept is estimate and verdict.outcome == "kept" and "under the 5°" in verdict.reason


def test_contour_alignment_keeps_lights_it_would_turn_by_more_than_it_is_trusted_to():
    sphere = render_lambertian("sphere", size=64, n_lights=16)
    turn = Rotation.from_euler("z", 90, degrees=True).as_matrix()
    estimate = Lights((sphere.light_directions @ turn.T).astype(np.float32), sphere.light_intensities,
                      "estimated")
    kept, verdict = ContourAlignment()(sphere, estimate)
    assert kept is estimate and verdict.outcome == "declined" and "trusted to correct" in verdict.reason

import numpy as np
import pytest

from unps.metrics import (angular_error, light_direction_mae, light_intensity_error, light_slant_bias,
                          normal_metrics, slant_bias)


def test_angular_error_known_values():
    z = np.array([0, 0, 1.0])
    assert angular_error(z, [0, 1, 1.0]) == pytest.approx(45)
    assert angular_error(z, -z) == pytest.approx(180)
    assert angular_error(z, 5 * z) == pytest.approx(0)


def test_normal_metrics_over_the_mask_only():
    gt = np.zeros((1, 4, 3))
    gt[..., 2] = 1
    tilt = np.radians([0, 20, 40, 80])
    pred = np.stack([np.sin(tilt), 0 * tilt, np.cos(tilt)], -1)[None]
    mask = np.array([[True, True, True, False]])
    m = normal_metrics(pred, gt, mask)
    assert m["normal_mae"] == pytest.approx(20)
    assert m["normal_median"] == pytest.approx(20)
    assert (m["acc_11_25"], m["acc_30"], m["acc_45"]) == pytest.approx((1 / 3, 2 / 3, 1))
    assert np.isnan(m["slant_bias"])       # a surface facing the camera has no slant direction


def normal(slant_deg, tilt_deg):
    slant, tilt = np.radians(slant_deg), np.radians(tilt_deg)
    return np.array([np.sin(slant) * np.cos(tilt), np.sin(slant) * np.sin(tilt), np.cos(slant)])


def test_slant_bias_is_signed_and_exact_for_a_change_of_slant():
    gt = np.array([[normal(30, 0), normal(30, 250)]])
    mask = np.ones((1, 2), bool)
    assert slant_bias(np.array([[[0, 0, 1.0], [0, 0, 2.0]]]), gt, mask) == pytest.approx(-30)
    steeper = np.array([[normal(34, 0), 3 * normal(34, 250)]])
    assert slant_bias(steeper, gt, mask) == pytest.approx(4)
    turned = np.array([[normal(30, 1), normal(30, 249)]])
    assert slant_bias(turned, gt, mask) == pytest.approx(0, abs=0.01)


def test_slant_bias_does_not_read_errors_that_point_every_way_as_steepening():
    """Eight 3° errors around each true normal, one in every direction of its tangent plane: on
    a surface nearly facing the camera the slants themselves grow by ~3° on average."""
    truths, preds = [], []
    for slant, tilt in [(0.5, 40), (40, 100)]:
        n = normal(slant, tilt)
        e_slant = np.array([np.cos(np.radians(slant)) * np.cos(np.radians(tilt)),
                            np.cos(np.radians(slant)) * np.sin(np.radians(tilt)), -np.sin(np.radians(slant))])
        e_turn = np.cross(n, e_slant)
        for phi in np.radians(np.arange(0, 360, 45)):
            sigma = np.radians(3)
            truths.append(n)
            preds.append(np.cos(sigma) * n + np.sin(sigma) * (np.cos(phi) * e_slant + np.sin(phi) * e_turn))
    gt, pred = np.array(truths)[None], np.array(preds)[None]
    mask = np.ones(gt.shape[:2], bool)
    assert angular_error(pred, gt) == pytest.approx(3)
    assert slant_bias(pred, gt, mask) == pytest.approx(0, abs=1e-9)
    view = np.array([0, 0, 1.0])
    assert (angular_error(pred[0, :8], view) - 0.5).mean() > 2     # what the slants themselves say


def test_light_direction_mae():
    assert light_direction_mae(np.array([[0, 0, 1.0], [1, 0, 0]]),
                               np.array([[0, 0, 1.0], [0, 0, 1]])) == pytest.approx(45)


def test_light_slant_bias_reads_lights_pulled_toward_the_view_axis_and_lands_in_light_errors():
    """Lights read 3° nearer the view axis than they are, or turned about it: −3° and 0°; the
    light stages' errors (``metrics.json``) carry it."""
    from unps.data.lights import Lights
    from unps.data.subject import Subject
    from unps.lights import light_errors
    true = np.array([normal(slant, tilt) for slant, tilt in [(20, 0), (35, 120), (50, 250)]])
    flattened = np.array([normal(slant - 3, tilt) for slant, tilt in [(20, 0), (35, 120), (50, 250)]])
    turned = np.array([normal(slant, tilt + 2) for slant, tilt in [(20, 0), (35, 120), (50, 250)]])
    assert light_slant_bias(flattened, true) == pytest.approx(-3)
    assert light_slant_bias(turned, true) == pytest.approx(0, abs=0.02)
    subject = Subject("three lights", np.ones((3, 2, 2, 3), np.float32), np.ones((2, 2), bool),
                      light_directions=true.astype(np.float32))
    errors = light_errors(Lights(flattened.astype(np.float32), None, "estimated"), subject)
    assert errors["light_slant_bias"] == pytest.approx(-3, abs=1e-4)
    assert errors["light_dir_mae"] == pytest.approx(3, abs=1e-3)


def test_intensity_error_is_scale_invariant():
    gt = np.array([1.0, 2.0, 4.0])
    assert light_intensity_error(3 * gt, gt) == pytest.approx(0, abs=1e-12)
    pred = np.array([1.0, 2.0, 2.0])
    s = (gt @ pred) / (pred @ pred)                      # 13/9
    expected = np.mean(np.abs(gt - s * pred) / gt)
    assert light_intensity_error(7 * pred, gt) == pytest.approx(expected)

import numpy as np
import pytest

from unps.metrics import (angular_error, light_direction_mae, light_intensity_error, normal_metrics,
                          slant_bias)


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
    assert m["slant_bias"] == pytest.approx(20)          # every tilt is away from the camera


def test_slant_bias_is_signed_and_ignores_azimuth():
    tilt = np.radians(30)
    gt = np.array([[[np.sin(tilt), 0, np.cos(tilt)], [0, -np.sin(tilt), np.cos(tilt)]]])
    flatter = np.array([[[0, 0, 1.0], [0, 0, 2.0]]])
    turned = np.array([[[0, np.sin(tilt), np.cos(tilt)], [np.sin(tilt), 0, np.cos(tilt)]]])
    mask = np.ones((1, 2), bool)
    assert slant_bias(flatter, gt, mask) == pytest.approx(-30)
    assert slant_bias(turned, gt, mask) == pytest.approx(0, abs=1e-9)


def test_light_direction_mae():
    assert light_direction_mae(np.array([[0, 0, 1.0], [1, 0, 0]]),
                               np.array([[0, 0, 1.0], [0, 0, 1]])) == pytest.approx(45)


def test_intensity_error_is_scale_invariant():
    gt = np.array([1.0, 2.0, 4.0])
    assert light_intensity_error(3 * gt, gt) == pytest.approx(0, abs=1e-12)
    pred = np.array([1.0, 2.0, 2.0])
    s = (gt @ pred) / (pred @ pred)                      # 13/9
    expected = np.mean(np.abs(gt - s * pred) / gt)
    assert light_intensity_error(7 * pred, gt) == pytest.approx(expected)

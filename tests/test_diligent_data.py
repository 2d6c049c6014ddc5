"""Checks on the real DiLiGenT data in ../shared/data; each skips when it is absent."""

import numpy as np
import pytest

from conftest import diligent_object
from unps.data.diligent import read_diligent
from unps.data.writer import write_diligent
from unps.metrics import normal_metrics
from unps.solvers.rpca import robust_init
from unps.solvers.woodham import woodham


@pytest.fixture(scope="module")
def ball():
    return read_diligent(diligent_object("pmsData/ballPNG"))


def mae(subject, estimate):
    return normal_metrics(estimate.normals, subject.normals, subject.mask)["normal_mae"]


def test_ball_is_read_at_16_bits_and_divided_by_intensities(ball):
    assert ball.n_images == 96 and ball.resolution == (512, 612)
    levels = np.round(ball.observed_images()[0] * 65535)
    assert (levels % 256 != 0).any(), "16-bit PNG was truncated to 8 bits"
    assert np.abs(ball.light_intensities[0] - [1.2909, 1.5776, 2.1336]).max() < 1e-6
    assert ball.mask.sum() == 15791


def test_woodham_matches_the_reference_on_ball(ball):
    assert mae(ball, woodham(ball, ball.light_directions)) == pytest.approx(4.29, abs=0.01)


@pytest.mark.slow
def test_robust_init_on_ball_meets_its_target(ball):
    assert mae(ball, robust_init(ball, ball.light_directions)) <= 3.3


@pytest.mark.slow
@pytest.mark.parametrize("name, reference", [("catPNG", 8.77), ("pot1PNG", 10.08)])
def test_crops_woodham_reference_and_robust_init_below_it(name, reference):
    s = read_diligent(diligent_object(f"pmsData_crop/{name}"))
    woodham_mae = mae(s, woodham(s, s.light_directions))
    assert woodham_mae == pytest.approx(reference, abs=0.01)
    assert mae(s, robust_init(s, s.light_directions)) < woodham_mae


@pytest.mark.slow
@pytest.mark.parametrize("name", ["catPNG", "pot1PNG"])
def test_reading_the_crops_as_truncated_lowers_both_errors(name):
    rounded = read_diligent(diligent_object(f"pmsData_crop/{name}"))
    floored = read_diligent(diligent_object(f"pmsData_crop/{name}"), quantization="floor")
    for solve in (woodham, robust_init):
        assert (mae(floored, solve(floored, floored.light_directions))
                < mae(rounded, solve(rounded, rounded.light_directions)) - 0.3), solve.__name__


def test_the_folder_path_reads_the_crops_as_made(caplog):
    folder = diligent_object("pmsData_crop/catPNG")
    with caplog.at_level("INFO"):
        auto = read_diligent(folder, drop=["4-95"], quantization="auto")
    np.testing.assert_array_equal(auto.images, read_diligent(folder, drop=["4-95"], quantization="floor").images)
    assert "read as quantization=floor" in caplog.text


def test_a_crop_round_trips_bit_for_bit(tmp_path):
    s = read_diligent(diligent_object("pmsData_crop/catPNG"), drop=["8-95"])
    write_diligent(s, tmp_path / "cat")
    back = read_diligent(tmp_path / "cat")
    for field in ("images", "mask", "light_directions", "light_intensities", "normals"):
        np.testing.assert_array_equal(getattr(back, field), getattr(s, field), err_msg=field)

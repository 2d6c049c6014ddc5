import logging

import numpy as np
import pytest

from unps.data.prepare import parse_indices, prepare
from unps.data.subject import Subject
from unps.errors import InputError
from unps.grid import Frame
from unps.pipeline.run import without_pixels


def make(n=4, h=6, w=5, **kw):
    args = dict(name="t", images=np.ones((n, h, w, 3), np.float32), mask=np.ones((h, w), bool),
                light_directions=np.tile([0, 0, 1.0], (n, 1)))
    args.update(kw)
    return Subject(**args)


def test_valid_subject_defaults():
    s = make()
    assert s.n_images == 4 and s.resolution == (6, 5) and s.calibrated
    assert s.frame == Frame((6, 5)) and s.filenames == ("001", "002", "003", "004")
    assert s.images.dtype == np.float32


@pytest.mark.parametrize("kw, message", [
    (dict(mask=np.zeros((6, 5), bool)), "mask is empty"),
    (dict(mask=np.ones((5, 5), bool)), "mask has shape (5, 5), expected the image size (6, 5)"),
    (dict(light_directions=np.array([[0, 0, 1.0]] * 3 + [[np.nan, 0, 1]])), "light direction in row 4 (of 4) is not finite"),
    (dict(light_directions=np.array([[0, 0, 1.0]] * 3 + [[0, 0, 0]])), "light direction in row 4 (of 4) has zero length"),
    (dict(light_directions=np.zeros((3, 3)) + [0, 0, 1]), "expected 4 light directions"),
    (dict(light_intensities=np.array([[1, 1, 1.0]] * 3 + [[1, 0, 1]])), "must be finite and > 0; row 4 (of 4)"),
    (dict(normals=np.zeros((6, 4, 3))), "ground-truth normals have shape (6, 4, 3), expected (6, 5, 3)"),
    (dict(depth=np.zeros((2, 2))), "ground-truth depth has shape"),
    (dict(images=np.full((4, 6, 5, 3), np.inf, np.float32)), "images contain NaN or Inf"),
    (dict(images=np.ones((4, 6, 5), np.float32)), "images must have shape (n, H, W, 3)"),
])
def test_bad_subject_is_refused_with_a_clear_message(kw, message):
    with pytest.raises(InputError, match=None) as info:
        make(**kw)
    assert message in str(info.value)
    assert "subject 't'" in str(info.value)


def test_non_unit_directions_are_normalised_with_a_warning(caplog):
    with caplog.at_level(logging.WARNING):
        s = make(light_directions=np.tile([0, 0, 2.0], (4, 1)))
    np.testing.assert_allclose(s.light_directions, np.tile([0, 0, 1.0], (4, 1)))
    assert "not unit length" in caplog.text


def test_observed_images_undo_the_intensity_division():
    e = np.array([[1, 2, 3.0]] * 4)
    s = make(light_intensities=e)
    np.testing.assert_allclose(s.observed_images()[:, 0, 0], e)


def test_select_keeps_lights_with_their_images():
    dirs = np.eye(3)[[0, 1, 2, 2]] + [0, 0, 1]
    s = make(light_directions=dirs).select([3, 0])
    np.testing.assert_allclose(s.light_directions, (dirs / np.linalg.norm(dirs, axis=1)[:, None])[[3, 0]], atol=1e-7)
    assert s.filenames == ("004", "001")


def test_crop_to_mask_records_the_offset():
    mask = np.zeros((20, 30), bool)
    mask[5:9, 10:14] = True
    s = make(h=20, w=30, mask=mask).crop_to_mask(2)
    assert s.resolution == (8, 8)
    assert s.frame == Frame((20, 30), top=3, left=8)
    assert s.mask.sum() == 16
    rows, cols = s.frame.source_coords(np.array([2]), np.array([2]))
    assert mask[int(rows[0]), int(cols[0])]


def test_crop_margin_stays_inside_the_image():
    mask = np.zeros((10, 10), bool)
    mask[0:3, 8:10] = True
    s = make(h=10, w=10, mask=mask).crop_to_mask(5)
    assert s.frame.top == 0 and s.frame.left == 3 and s.resolution == (8, 7)


def test_downsample_averages_object_pixels_only_and_pads():
    images = np.zeros((1, 5, 5, 3), np.float32)
    images[0, :2, :2] = [[[1], [3]], [[5], [7]]]
    mask = np.zeros((5, 5), bool)
    mask[:2, :2] = True
    mask[0, 0] = False                       # the block keeps 3 of 4 object pixels
    normals = np.zeros((5, 5, 3), np.float32)
    normals[..., 2] = 1
    normals[0, 1] = [1, 0, 0]                # averaged with two (0,0,1) -> renormalised
    s = make(n=1, h=5, w=5, images=images, mask=mask, normals=normals,
             light_directions=[[0, 0, 1.0]]).downsample(2)
    assert s.resolution == (3, 3)            # 5 padded to 6, nothing dropped
    assert s.frame.step == 2
    assert s.mask[0, 0] and not s.mask[1, 1]
    np.testing.assert_allclose(s.images[0, 0, 0], [5.0] * 3)   # (3 + 5 + 7) / 3
    np.testing.assert_allclose(np.linalg.norm(s.normals[0, 0]), 1, rtol=1e-6)
    np.testing.assert_allclose(s.normals[0, 0], np.array([1, 0, 2]) / np.sqrt(5), rtol=1e-6)


def test_downsample_keeps_depth_finite_where_background_is_nan():
    mask = np.zeros((4, 4), bool)
    mask[:3, :3] = True
    depth = np.where(mask, 2.0, np.nan)
    s = make(n=1, h=4, w=4, mask=mask, depth=depth, light_directions=[[0, 0, 1.0]]).downsample(2)
    assert s.mask.tolist() == [[True, True], [True, False]]
    np.testing.assert_allclose(s.depth[s.mask], 1.0)            # 2 pixels of depth at pitch ×2


def test_downsample_rejects_bad_factors():
    with pytest.raises(InputError, match="whole number >= 1, got 0"):
        make().downsample(0)


def test_parse_indices_ranges_and_errors():
    assert parse_indices([0, "2-4", 3], 10, "drop") == [0, 2, 3, 4]
    assert parse_indices(["0-19"], 96, "drop") == list(range(20))
    with pytest.raises(InputError, match="index 12 is outside the 10 images"):
        parse_indices([12], 10, "drop")
    with pytest.raises(InputError, match="'x' is neither an index nor a range"):
        parse_indices(["x"], 10, "drop")


def test_prepare_order_and_refusing_to_drop_everything():
    mask = np.zeros((8, 8), bool)
    mask[2:6, 2:6] = True
    s = prepare(make(h=8, w=8, mask=mask), drop=["1-2"], crop_margin=0, downsample=2)
    assert s.n_images == 2 and s.resolution == (2, 2) and s.frame == Frame((8, 8), 2, 2, 2)
    with pytest.raises(InputError, match="drop removes all 4 images"):
        prepare(make(), drop=["0-3"])


def test_a_subject_kept_without_its_pixels_keeps_its_lights_and_holds_no_image():
    """What ``python -m unps.fit`` keeps of the subject as read once the method has its own images:
    its lights, mask and count of images, and no pixel values (a view of one zero)."""
    subject = make(light_intensities=np.full((4, 3), 2.0, np.float32))
    kept = without_pixels(subject)
    assert kept.n_images == 4 and kept.resolution == subject.resolution
    np.testing.assert_array_equal(kept.light_directions, subject.light_directions)
    np.testing.assert_array_equal(kept.light_intensities, subject.light_intensities)
    assert kept.images.strides == (0, 0, 0, 0) and not kept.images.any()
    assert subject.images.all()                                # the subject as read is untouched


def test_a_nan_in_any_image_is_refused():
    images = np.ones((4, 6, 5, 3), np.float32)
    images[3, 5, 4, 2] = np.nan
    with pytest.raises(InputError, match="images contain NaN or Inf"):
        make(images=images)

"""Masks found from the images (unps.data.automask) and how a folder without one is read."""

import logging

import numpy as np
import pytest
from scipy import ndimage

from conftest import diligent_object
from unps.data.analytic import render_lambertian
from unps.data.automask import auto_mask, otsu_threshold
from unps.data.diligent import read_diligent, read_folder
from unps.data.writer import write_diligent
from unps.errors import InputError


def noisy(images, sigma=0.003, seed=0):
    rng = np.random.default_rng(seed)
    return np.clip(images + sigma * rng.standard_normal(images.shape), 0, None).astype(np.float32)


def iou(a, b):
    return (a & b).sum() / (a | b).sum()


def inner(mask):
    """The object less its outline, which the automatic mask leaves out (mixed pixels)."""
    return ndimage.binary_erosion(mask)


def test_otsu_splits_two_groups_between_them():
    values = np.r_[np.random.default_rng(0).normal(0, 0.1, 500), np.random.default_rng(1).normal(5, 0.1, 300)]
    threshold, separation = otsu_threshold(values)
    assert values[:500].max() < threshold < values[500:].min() and separation > 0.95


def test_a_sphere_on_a_dark_background_is_found():
    sphere = render_lambertian("sphere", size=64, n_lights=16, seed=1)
    found = auto_mask(noisy(sphere.observed_images()))
    assert iou(found.mask, inner(sphere.mask)) > 0.97 and found.contrast > 5


def test_a_hole_through_the_object_stays_open_and_a_dark_patch_on_it_is_filled():
    sphere = render_lambertian("sphere", size=64, n_lights=16, seed=1)
    r, c = np.mgrid[0:64, 0:64]
    hole = (r - 32) ** 2 + (c - 32) ** 2 < 6 ** 2               # the background through a ring
    patch = (r - 32) ** 2 + (c - 18) ** 2 < 5 ** 2              # a nearly black paint
    images = sphere.observed_images() * np.where(patch, 0.06, 1.0)[None, ..., None]
    images[:, hole] = 0
    found = auto_mask(noisy(images))
    ring = sphere.mask & ~hole
    assert not found.mask[hole].any()
    assert found.mask[patch].all()
    assert iou(found.mask, inner(ring)) > 0.95


def test_a_lit_floor_that_changes_less_than_the_object_is_left_out():
    sphere = render_lambertian("sphere", size=64, n_lights=16, seed=1)
    floor = 0.3 * np.clip(sphere.light_directions[:, 2], 0, None)[:, None, None, None]
    images = np.where(sphere.mask[None, ..., None], sphere.observed_images(), floor)
    assert iou(auto_mask(noisy(images)).mask, inner(sphere.mask)) > 0.95


def test_a_stack_without_an_object_gives_a_low_contrast_and_a_warning(tmp_path, caplog):
    rng = np.random.default_rng(3)
    images = rng.uniform(0.2, 0.8, (12, 32, 32, 1)).repeat(3, -1).astype(np.float32)
    assert auto_mask(images).contrast < 2
    sphere = render_lambertian("sphere", size=32, n_lights=12, seed=2)
    write_diligent(sphere.replace(images=images, light_intensities=None), tmp_path / "noise")
    (tmp_path / "noise" / "mask.png").unlink()
    with caplog.at_level(logging.WARNING):
        read_folder(tmp_path / "noise")
    assert "the automatic mask is unsure" in caplog.text


def test_a_stack_that_cannot_show_the_object_is_refused():
    sphere = render_lambertian("sphere", size=16, n_lights=4)
    with pytest.raises(InputError, match="at least 2 images"):
        auto_mask(sphere.observed_images()[:1])
    with pytest.raises(InputError, match="black"):
        auto_mask(np.zeros((4, 16, 16, 3), np.float32))
    with pytest.raises(InputError, match="no pixel changes"):
        auto_mask(np.full((4, 16, 16, 3), 0.5, np.float32))


def test_a_folder_without_a_mask_gets_one_from_its_images(tmp_path, caplog):
    sphere = render_lambertian("sphere", size=48, n_lights=12, seed=2)
    folder = tmp_path / "capture"
    write_diligent(sphere, folder)
    (folder / "mask.png").unlink()
    with caplog.at_level(logging.INFO):
        found = read_folder(folder)
    assert iou(found.mask, inner(sphere.mask)) > 0.97
    assert "mask was found from the images" in caplog.text
    assert read_folder(folder, mask="none").mask.all()
    np.testing.assert_array_equal(read_folder(folder, mask="auto").mask, found.mask)
    with pytest.raises(InputError, match="other.png: mask file not found"):
        read_folder(folder, mask="other.png")


def test_the_development_objects_masks_are_found_to_within_a_few_percent():
    for name, least in (("pmsData/ballPNG", 0.97), ("pmsData_crop/catPNG", 0.96), ("pmsData_crop/pot1PNG", 0.96)):
        subject = read_diligent(diligent_object(name), quantization="auto")
        assert iou(auto_mask(subject.observed_images()).mask, subject.mask) > least, name


def test_a_lit_table_that_joins_the_mask_at_the_images_edge_is_warned_of(tmp_path, caplog):
    sphere = render_lambertian("sphere", size=48, n_lights=12, seed=2)
    assert auto_mask(noisy(sphere.observed_images())).at_edge == 0
    r, c = np.mgrid[0:48, 0:48]
    table = (r >= 38) & ~sphere.mask                                  # under the sphere, to the edge
    facing = np.array([0.0, 0.6, 0.8])                                # tilted toward the camera
    lit = 0.7 * np.clip(sphere.light_directions @ facing, 0, None)
    images = sphere.observed_images().copy()
    images[:, table] = lit[:, None, None]
    found = auto_mask(noisy(images))
    assert found.mask[table].mean() > 0.5 and found.at_edge > 0
    write_diligent(sphere.replace(images=noisy(images), light_intensities=None), tmp_path / "pot")
    (tmp_path / "pot" / "mask.png").unlink()
    with caplog.at_level(logging.WARNING):
        read_folder(tmp_path / "pot")
    assert f"the automatic mask reaches the image's edge on {found.at_edge} pixels" in caplog.text

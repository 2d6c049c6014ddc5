import json
import logging

import cv2
import numpy as np
import pytest
import scipy.io

from unps.data.checks import (FAINT_LEVELS, FAINT_SHARE, MIN_CLIPPED_VALUES, TOP_LEVEL, black_everywhere,
                              clipped_values, faintly_lit, first_level, value_levels, zero_ceiling)
from unps.data.diligent import read_diligent, read_folder
from unps.data.writer import write_diligent
from unps.errors import InputError
from unps.grid import block_mean
from unps.inverse.grids import MOSTLY_ZERO, black_headroom
from unps.io.files import atomic_path
from unps.io.images import read_image, read_mask, srgb_to_linear
from unps.io.pictures import centred_height, shape_figure_png


def test_16_bit_png_is_read_at_full_depth(tmp_path):
    levels = np.arange(0, 65536, 257 * 3, dtype=np.uint16)[:84].reshape(4, 7, 3)
    levels[0, 0] = [1, 2, 65535]             # values an 8-bit reader cannot tell apart
    cv2.imwrite(str(tmp_path / "a.png"), levels[..., ::-1])
    rgb = read_image(tmp_path / "a.png")
    np.testing.assert_array_equal(rgb, levels.astype(np.float32) / 65535)
    assert rgb[0, 0, 0] != rgb[0, 0, 1]


def test_8_bit_and_gray_images(tmp_path):
    cv2.imwrite(str(tmp_path / "g.png"), np.full((3, 4), 51, np.uint8))
    np.testing.assert_allclose(read_image(tmp_path / "g.png"), 0.2)


def test_floor_quantization_reads_a_level_as_the_middle_of_its_interval(tmp_path):
    cv2.imwrite(str(tmp_path / "8.png"), np.array([[0, 1, 51, 255]], np.uint8))
    cv2.imwrite(str(tmp_path / "16.png"), np.array([[0, 1, 65535]], np.uint16))
    np.testing.assert_allclose(read_image(tmp_path / "8.png")[0, :, 0], [0, 1 / 255, 0.2, 1])
    np.testing.assert_allclose(read_image(tmp_path / "8.png", "floor")[0, :, 0],
                               [0, 1.5 / 255, 51.5 / 255, 255.5 / 255])   # zero (shadow) stays zero
    np.testing.assert_allclose(read_image(tmp_path / "16.png", "floor")[0, :, 0],
                               [0, 1.5 / 65535, 65535.5 / 65535])
    with pytest.raises(InputError, match="quantization must be round or floor.*'ceil'"):
        read_image(tmp_path / "8.png", "ceil")


def test_a_truncated_dark_capture_is_read_without_bias_with_floor(tmp_path, sphere):
    """8-bit truncation of a dark capture darkens it by half a level on average; floor undoes that."""
    observed = sphere.observed_images()
    dark = observed * (20.0 / observed.max())                     # in levels; the brightest is 20
    folder = write_diligent(sphere, tmp_path / "obj")
    (folder / "unps_subject.json").unlink()
    for name, levels in zip((folder / "filenames.txt").read_text().split(), dark):
        cv2.imwrite(str(folder / name), np.floor(levels[..., ::-1]).astype(np.uint8))
    lit = (dark >= 1).all(-1) & sphere.mask[None]
    bias = {q: (read_diligent(folder, quantization=q).observed_images() * 255 - dark)[lit].mean()
            for q in ("round", "floor")}
    assert bias["round"] == pytest.approx(-0.5, abs=0.05)
    assert abs(bias["floor"]) < 0.05


def test_missing_and_corrupt_images_are_named(tmp_path):
    with pytest.raises(InputError, match="nope.png: image file not found"):
        read_image(tmp_path / "nope.png")
    (tmp_path / "bad.png").write_bytes(b"not a png")
    with pytest.raises(InputError, match="bad.png: not an image OpenCV can read"):
        read_image(tmp_path / "bad.png")


def test_mask_of_the_wrong_size(tmp_path):
    cv2.imwrite(str(tmp_path / "mask.png"), np.full((3, 4), 255, np.uint8))
    with pytest.raises(InputError, match=r"mask.png: mask is 4×3 pixels, but the images are 5×3"):
        read_mask(tmp_path / "mask.png", (3, 5))


def test_srgb_to_linear_known_values():
    np.testing.assert_allclose(srgb_to_linear(np.array([0.0, 0.04045, 0.5, 1.0])),
                               [0, 0.04045 / 12.92, 0.21404, 1.0], rtol=1e-4)


def test_atomic_files_get_the_usual_permissions(tmp_path):
    import os
    import stat

    with atomic_path(tmp_path / "a.json") as tmp:
        tmp.write_text("{}")
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE((tmp_path / "a.json").stat().st_mode) == 0o666 & ~mask


def test_atomic_path_keeps_the_old_file_when_writing_fails(tmp_path):
    target = tmp_path / "metrics.json"
    target.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("killed")
    assert target.read_text() == "old"
    assert list(tmp_path.iterdir()) == [target]


# DiLiGenT layout --------------------------------------------------------------------------

def on_grid(sphere):
    """The sphere subject with observed images quantised to 16 bits, as a real capture is."""
    q = np.round(np.clip(sphere.observed_images(), 0, 1) * 65535).astype(np.float32) / 65535
    return sphere.replace(images=q / sphere.light_intensities[:, None, None, :])


def test_write_then_read_is_exact_for_16_bit_data(tmp_path, sphere):
    original = on_grid(sphere)
    write_diligent(original, tmp_path / "obj")
    back = read_diligent(tmp_path / "obj")
    np.testing.assert_array_equal(back.images, original.images)
    np.testing.assert_array_equal(back.light_directions, original.light_directions)
    np.testing.assert_array_equal(back.light_intensities, original.light_intensities)
    np.testing.assert_array_equal(back.normals, original.normals)
    np.testing.assert_array_equal(back.mask, original.mask)
    np.testing.assert_array_equal(back.depth, original.depth)
    assert back.name == original.name and back.frame == original.frame
    # and once more: reading what was read gives the same bits
    write_diligent(back, tmp_path / "again")
    np.testing.assert_array_equal(read_diligent(tmp_path / "again").images, back.images)


def test_bright_images_are_rescaled_not_clipped(tmp_path, sphere):
    bright = sphere.replace(images=sphere.images * 7)
    write_diligent(bright, tmp_path / "obj")
    meta = json.loads((tmp_path / "obj" / "unps_subject.json").read_text())
    assert meta["image_scale"] > 1
    back = read_diligent(tmp_path / "obj")
    peak = bright.observed_images().max()
    np.testing.assert_allclose(back.observed_images() * meta["image_scale"],
                               bright.observed_images(), atol=peak / 65535)


def test_tiff_is_lossless_to_float32_rounding(tmp_path, sphere):
    noisy = sphere.replace(images=sphere.images + np.float32(0.3) * np.random.default_rng(0)
                           .standard_normal(sphere.images.shape).astype(np.float32))
    write_diligent(noisy, tmp_path / "obj", image_format="tiff32")
    np.testing.assert_allclose(read_diligent(tmp_path / "obj").images, noisy.images, rtol=1e-6, atol=1e-7)


def test_writer_refuses_to_overwrite_and_leaves_nothing_half_written(tmp_path, sphere, monkeypatch):
    write_diligent(sphere, tmp_path / "obj")
    with pytest.raises(FileExistsError):
        write_diligent(sphere, tmp_path / "obj")

    import unps.data.writer as writer
    def failing(path, rgb):
        raise OSError("disk full")
    monkeypatch.setattr(writer, "write_png16", failing)
    with pytest.raises(OSError, match="disk full"):
        write_diligent(sphere, tmp_path / "new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["obj"]


@pytest.fixture
def layout(tmp_path, sphere):
    return write_diligent(on_grid(sphere), tmp_path / "objPNG")


def test_name_defaults_to_the_folder_and_options_apply(layout):
    (layout / "unps_subject.json").unlink()
    full = read_diligent(layout)
    s = read_diligent(layout, drop=["0-1"], crop_margin=1, downsample=2)
    assert s.name == "obj" and s.n_images == 10 and s.frame.step == 2
    assert s.frame.top == np.nonzero(full.mask)[0].min() - 1
    assert s.filenames == full.filenames[2:]


@pytest.mark.parametrize("damage, message", [
    (lambda d: (d / "005.png").unlink(), "005.png: listed image is missing"),
    (lambda d: (d / "filenames.txt").unlink(), "filenames.txt: missing"),
    (lambda d: (d / "005.png").write_bytes(b"garbage"), "005.png: not an image OpenCV can read"),
    (lambda d: cv2.imwrite(str(d / "005.png"), np.zeros((8, 8, 3), np.uint16)),
     "005.png: image is 8×8, but 001.png is 32×32"),
    (lambda d: np.savetxt(d / "light_directions.txt", np.ones((11, 3))),
     "light_directions.txt: expected 12 light directions"),
    (lambda d: np.savetxt(d / "light_directions.txt", np.r_[np.ones((11, 3)), [[np.nan, 0, 1]]]),
     "light_directions.txt: the light direction in row 12 (of 12) is not finite"),
    (lambda d: np.savetxt(d / "light_directions.txt", np.r_[[[0, 0, 0]], np.ones((11, 3))]),
     "light_directions.txt: the light direction in row 1 (of 12) has zero length"),
    (lambda d: (d / "light_directions.txt").write_text("1 2 3\n1 2 x\n"),
     "light_directions.txt: cannot parse light directions as rows of numbers (line 2, column 3: 'x' is not a number)"),
    (lambda d: (d / "light_directions.txt").write_text("1 2 3\n1 2\n"),
     "cannot parse light directions as rows of numbers (line 2 has 2 values, the lines before 3)"),
    (lambda d: np.savetxt(d / "light_intensities.txt", np.r_[np.ones((11, 3)), [[1, -1, 1]]]),
     "light_intensities.txt: light intensities must be finite and > 0; row 12 (of 12)"),
    (lambda d: (d / "light_intensities.txt").unlink(), "light_intensities.txt: missing"),
    (lambda d: cv2.imwrite(str(d / "mask.png"), np.zeros((32, 32), np.uint8)), "mask.png: mask is empty"),
    (lambda d: cv2.imwrite(str(d / "mask.png"), np.full((16, 32), 255, np.uint8)),
     "mask.png: mask is 32×16 pixels, but the images are 32×32"),
    (lambda d: scipy.io.savemat(d / "Normal_gt.mat", {"Normal_gt": np.zeros((32, 31, 3))}),
     "Normal_gt.mat: Normal_gt has shape (32, 31, 3), expected (32, 32, 3)"),
    (lambda d: scipy.io.savemat(d / "Normal_gt.mat", {"N": np.zeros((32, 32, 3))}),
     "Normal_gt.mat: has no variable 'Normal_gt'"),
])
def test_bad_layout_is_refused_naming_the_file(layout, damage, message):
    damage(layout)
    with pytest.raises(InputError) as info:
        read_diligent(layout)
    assert message in str(info.value)


def test_non_unit_directions_in_a_file_are_normalised_with_a_warning(layout, caplog):
    d = np.loadtxt(layout / "light_directions.txt")
    np.savetxt(layout / "light_directions.txt", 3 * d)
    with caplog.at_level(logging.WARNING):
        s = read_diligent(layout)
    assert "light_directions.txt: 12 light directions are not unit length" in caplog.text
    np.testing.assert_allclose(s.light_directions, d, atol=1e-6)


def test_not_a_folder(tmp_path):
    with pytest.raises(InputError, match="not a folder"):
        read_diligent(tmp_path / "missing")


# plain folder -----------------------------------------------------------------------------

def test_folder_without_lights_is_uncalibrated(tmp_path, caplog):
    for i in (10, 2, 1):                        # natural order: 1, 2, 10
        cv2.imwrite(str(tmp_path / f"img{i}.png"), np.full((4, 5, 3), 10 * i, np.uint8))
    with caplog.at_level(logging.INFO):
        s = read_folder(tmp_path)
    assert not s.calibrated and s.light_intensities is None
    assert s.filenames == ("img1.png", "img2.png", "img10.png")
    assert s.mask.all() and "no mask.png in the folder" in caplog.text   # all alike: all object
    np.testing.assert_allclose(s.images[:, 0, 0, 0], [10 / 255, 20 / 255, 100 / 255])


def test_folder_jpegs_are_linearised_and_lights_used_when_present(tmp_path):
    for i in range(3):
        cv2.imwrite(str(tmp_path / f"{i}.jpg"), np.full((8, 8, 3), 128, np.uint8))
    cv2.imwrite(str(tmp_path / "mask.png"), np.full((8, 8), 255, np.uint8))
    np.savetxt(tmp_path / "light_directions.txt", [[0, 0, 1], [0, 1, 1], [1, 0, 1]])
    s = read_folder(tmp_path)
    assert s.calibrated and s.n_images == 3
    np.testing.assert_allclose(s.images[0, 4, 4], srgb_to_linear(np.full(3, 128 / 255)), atol=2e-3)
    assert read_folder(tmp_path, encoding="linear").images[0, 4, 4, 0] == pytest.approx(128 / 255, abs=2e-3)


def test_empty_folder_and_bad_encoding(tmp_path):
    with pytest.raises(InputError, match="no image files"):
        read_folder(tmp_path)
    with pytest.raises(InputError, match="encoding must be auto, linear or srgb"):
        read_folder(tmp_path, encoding="gamma")


def test_a_nan_in_an_image_names_the_file_and_the_pixel(tmp_path, sphere):
    write_diligent(sphere, tmp_path / "obj", image_format="tiff32")
    first = tmp_path / "obj" / (tmp_path / "obj" / "filenames.txt").read_text().split()[0]
    image = cv2.imread(str(first), cv2.IMREAD_UNCHANGED)
    image[2, 5] = np.nan
    cv2.imwrite(str(first), image)
    with pytest.raises(InputError, match=rf"{first.name}: contains NaN or Inf \(first at row 3, column 6"):
        read_diligent(tmp_path / "obj")


@pytest.mark.parametrize("dtype, scale, quantization, black", [
    (np.uint8, 1, "round", [1, 1, 1, 0, 0]), (np.uint8, 1, "floor", [1, 1, 1, 0, 0]),
    (np.uint16, 257, "round", [1, 0, 0, 0, 0])])
def test_black_in_every_image_means_the_stacks_two_lowest_levels(tmp_path, dtype, scale, quantization,
                                                                    black):
    """Pixels whose every value is at most the stack's second level are black, in 8-bit files read
    as round or floor; in a 16-bit capture, whose noise reaches a few of its own levels, the same
    light (8-bit levels times 257) is signal."""
    peaks = np.array([0, 1, 2, 3, 200]) * scale                   # each pixel's brightest value
    rest = np.array([5 if dtype == np.uint16 else 0, 1, 1, 1, 200]) * np.array([1, scale, scale, scale, scale])
    stack = []
    for k in range(3):
        levels = np.repeat((peaks if k == 1 else rest)[None, :, None], 3, -1).astype(dtype)
        cv2.imwrite(str(tmp_path / f"{k}.png"), levels)
        stack.append(read_image(tmp_path / f"{k}.png", quantization))
    mask = np.ones((1, 5), bool)
    np.testing.assert_array_equal(black_everywhere(np.stack(stack), mask)[0], np.array(black, bool))
    coarse = np.full((2, 1, 5, 3), 10 / 255)                      # no value below level 10: can't tell
    assert not black_everywhere(coarse, mask).any()


def test_the_checks_read_image_by_image_what_the_whole_stack_says():
    """Each check walks the stack one image at a time (no copy of it); what it finds is what the
    definitions say of the whole stack at once: clipping plateaus per channel, black and nearly
    black pixels, the first levels, the headroom of values read as 0."""
    rng = np.random.default_rng(3)
    albedo = rng.random((40, 50, 1)) ** 4
    stack = np.floor(np.minimum(rng.gamma(0.3, 20, (24, 40, 50, 3)) * albedo * 4, 200)) / 255
    stack[..., 2] *= 0.9                      # blue's plateau lower: each channel has its own top
    stack[3] = 0                              # an image black everywhere
    mask = rng.random((40, 50)) > 0.2
    values = stack[:, mask]                                            # (n, P, 3) the whole stack
    first = values[values > 0].min()
    tops = values.max(axis=(0, 1))
    at_top = values >= TOP_LEVEL * tops
    clipped = np.zeros(stack.shape[:3], bool)
    clipped[:, mask] = (at_top & (at_top.sum(axis=(0, 1)) >= MIN_CLIPPED_VALUES)).any(-1)
    peak, lit = values.max(axis=(0, 2)), (values.max(-1) > first * (1 + 1e-4)).sum(0)
    black = np.zeros(mask.shape, bool)
    black[mask] = peak <= 2 * first * (1 + 1e-4)
    faint = np.zeros(mask.shape, bool)
    faint[mask] = (peak <= FAINT_LEVELS * first * (1 + 1e-4)) & (lit <= FAINT_SHARE * len(stack))
    faint &= ~black
    second = values[values > first * (1 + 1e-3)].min()
    assert 0 < clipped.mean() and 0.1 < black[mask].mean() < 0.9 and 0.05 < faint[mask].mean() < 0.9

    assert first_level(stack, mask) == first
    assert zero_ceiling(stack, mask) == first - min(second - first, first) / 2
    np.testing.assert_array_equal(clipped_values(stack, mask), clipped)
    np.testing.assert_array_equal(black_everywhere(stack, mask), black)
    np.testing.assert_array_equal(faintly_lit(stack, mask), faint)
    shares = value_levels(stack, mask)
    np.testing.assert_array_equal(shares[0], clipped[:, mask].mean(1))
    np.testing.assert_array_equal(shares[1], (values == 0).all(-1).mean(1))
    zeros = (stack == 0) & mask[None, ..., None]
    zeros &= (zeros.all(-1).mean(0) <= MOSTLY_ZERO)[None, ..., None]
    intensities = rng.random((24, 3)) + 0.5
    for factor in (1, 3):
        share = zeros if factor == 1 else np.stack([block_mean(z, mask, factor)[0] for z in zeros])
        np.testing.assert_allclose(black_headroom(stack, mask, factor, 0.5 / 255, intensities),
                                   share * 0.5 / 255 / intensities[:, None, None], rtol=1e-6)
    assert black_headroom(stack + 1 / 255, mask, 3, 0.5 / 255, None) is None


def sphere_cap(size: int = 60) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) heights toward the camera of a sphere's cap, and its (H, W) disc mask."""
    r, c = (np.mgrid[0:size, 0:size] - (size - 1) / 2) / (0.45 * size)
    mask = r ** 2 + c ** 2 < 1
    return np.where(mask, np.sqrt(np.clip(1 - r ** 2 - c ** 2, 0, None)) * 0.45 * size, np.nan), mask


@pytest.mark.parametrize("sign", [1, -1])
def test_the_shape_pictures_profiles_bulge_for_a_dome_and_sag_for_a_bowl(sign):
    depth, mask = sphere_cap()
    height, (top, left) = centred_height(sign * depth, mask)
    middle_row = height[height.shape[0] // 2]
    ends, middle = middle_row[[0, -1]], middle_row[len(middle_row) // 2]
    assert np.all(sign * (middle - ends) > 20)
    assert np.nanmean(height[mask[top:top + height.shape[0], left:left + height.shape[1]]]) == pytest.approx(0, abs=1e-9)


@pytest.mark.parametrize("shape", [(1, 1), (1, 20), (20, 1), (30, 40)])
def test_the_shape_picture_is_drawn_for_any_mask_even_a_line_of_pixels(shape):
    mask = np.pad(np.ones(shape, bool), 3)
    picture = cv2.imdecode(np.frombuffer(shape_figure_png(np.where(mask, 1.0, np.nan), mask, "line"),
                                         np.uint8), cv2.IMREAD_COLOR)
    assert picture is not None and picture.shape[1] > picture.shape[0] > 100

"""Every bad input a user can give gets a message naming the value or file: one check each."""

import numpy as np
import pytest
import torch

from unps.data.analytic import dome_lights, render_lambertian
from unps.data.writer import write_diligent
from unps.errors import InputError
from unps.lightnet.brdf import read_neural_brdf
from unps.lightnet.shapes import ShapeMaps
from unps.lightnet.synthesis import LightDataset
from unps.synthetic.render import light_dome, mitsuba_bsdf


def test_analytic_subject_settings():
    with pytest.raises(InputError, match="unknown analytic shape 'cube'; known: sphere, bumps"):
        render_lambertian("cube")
    with pytest.raises(InputError, match="size must be at least 8 pixels, got 4"):
        render_lambertian(size=4)
    with pytest.raises(InputError, match="need at least one light, got 0"):
        dome_lights(0, seed=0)


def test_crop_margin_must_not_be_negative(sphere):
    with pytest.raises(InputError, match="crop margin must be >= 0 pixels, got -1"):
        sphere.crop_to_mask(-1)


def test_writer_formats_and_negative_pixels(tmp_path, sphere):
    with pytest.raises(InputError, match="image_format must be one of \\['png16', 'tiff32'\\], got 'exr'"):
        write_diligent(sphere, tmp_path / "a", image_format="exr")
    negative = sphere.replace(images=sphere.images - 0.5)
    with pytest.raises(InputError, match="images have negative values .* use image_format=tiff32"):
        write_diligent(negative, tmp_path / "b")
    assert not list(tmp_path.iterdir())


def test_light_dome_intensity_range():
    with pytest.raises(InputError, match="intensity_range must be 0 < low <= high, got \\(2, 1\\)"):
        light_dome(4, 60, (2, 1), 0.05, seed=0)


def test_a_texture_needs_an_rgb_base_colour():
    with pytest.raises(InputError, match="a texture needs a material with an RGB base colour"):
        mitsuba_bsdf({"type": "roughconductor", "alpha": 0.2}, {"seed": 0})


def test_a_foreign_h5_is_not_a_neural_brdf(tmp_path):
    import h5py

    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["weights"] = np.zeros(3)
    with pytest.raises(InputError, match="other.h5: not a neural BRDF fit with layers dense_1…dense_3"):
        read_neural_brdf(tmp_path / "other.h5")
    with pytest.raises(InputError, match="neural BRDF file not found"):
        read_neural_brdf(tmp_path / "none.h5")


def test_mesh_views_must_match_the_data_resolution():
    maps = ShapeMaps(torch.zeros(64, 64, 3), torch.zeros(64, 64), torch.ones(64, 64, dtype=torch.bool))
    ds = LightDataset(2, resolution=32, images=2, meshes=[maps], mesh_fraction=1.0)
    with pytest.raises(InputError, match="mesh views are 64 px, data 32 px"):
        ds[0]


def test_resuming_from_a_missing_or_foreign_checkpoint(tmp_path):
    from hydra import compose, initialize_config_module

    from unps.train import train

    def config(path):
        with initialize_config_module(config_module="unps.conf", version_base="1.3"):
            return compose("train", overrides=[f"paths.output_dir={tmp_path / 'run'}",
                                               f"ckpt_path={path}"])

    with pytest.raises(InputError, match="none.ckpt: checkpoint to resume from not found"):
        train(config(tmp_path / "none.ckpt"))
    torch.save({"state_dict": {}}, tmp_path / "foreign.ckpt")
    with pytest.raises(InputError, match="foreign.ckpt: not a unps.train checkpoint"):
        train(config(tmp_path / "foreign.ckpt"))


def test_black_images_and_non_numeric_noise(sphere):
    from unps.data.prepare import add_noise
    from unps.solvers.rpca import partial_sum_rpca, robust_init

    black = sphere.replace(images=np.zeros_like(sphere.images))
    with pytest.raises(InputError, match="every image is black on the object"):
        robust_init(black, sphere.light_directions)
    empty = partial_sum_rpca(np.zeros((20, 6)))
    assert empty.low_rank.shape == (20, 6) and not empty.low_rank.any() and not empty.sparse.any()
    with pytest.raises(InputError, match="noise must be a number .* got 'abc'"):
        add_noise(sphere, "abc", seed=0)

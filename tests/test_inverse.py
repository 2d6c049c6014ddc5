"""The neural inverse rendering (method=unps): its pieces at tiny sizes, a short fit, resume."""

import json
import logging
import re

import numpy as np
import pytest
import torch
from conftest import TINY, rendered, tiny_fit
from hydra import compose, initialize_config_module
from omegaconf import OmegaConf

from unps.data.analytic import render_lambertian
from unps.device import native_bfloat16
from unps.errors import Diverged, InputError
from unps.data.checks import clipped_values
from unps.geometry import continue_surface
from unps.grid import block_mean
from unps.fit import fit
from unps.inverse.pixels import NOISE_LIMIT
from unps.inverse.fit import (FAR_FROM_START_DEG, build_system, distance_from_start, held_from_solve,
                              interreflection_bend, neural_inverse_rendering, solved_per_pixel, unit,
                              unshaded, with_read_out_rules, with_surface_continued)
from unps.inverse.settings import InterreflectionModel, Preset
from unps.inverse.grids import (black_headroom, unclipped, upsample_normals, upsample_with_detail,
                               working_factor)
from unps.inverse.interreflection import Interreflection
from unps.inverse.networks import NormalNet, ReflectanceNet, normal_net_input, shading, specular_map
from unps.inverse.system import InverseRendering, residual_weight, visibility
from unps.lights.contour import best_rotation, rotation_angle
from unps.metrics import angular_error, slant_bias
from unps.pipeline.run import learns_lights

NAYAR = dict(downsample=2, occlusion=True, albedo=None)


def config(tmp_path, *overrides):
    with initialize_config_module(config_module="unps.conf", version_base="1.3"):
        return compose("fit", overrides=[f"paths.output_dir={tmp_path}", *overrides])


def tiny_overrides(steps=20, every=10):
    return ["subject=lambertian", "subject.size=24", "subject.n_lights=12", "method=unps",
            "preset.width=16", "preset.depth=3", "preset.reflectance_width=8", f"preset.steps={steps}",
            f"preset.lr_drop_at={steps - 2}", "preset.images_per_step=6", f"preset.update_every={every}",
            "interreflection.downsample=2"]


def test_specular_map_matches_a_hand_computed_value():
    n = torch.tensor([0.0, 0.6, 0.8]).view(1, 3, 1, 1)
    lights = torch.tensor([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]])
    # v·(2(n·l)n − l): l = z → 2·0.8·0.8 − 1 = 0.28; l = (0.6, 0, 0.8) → 2·0.64·0.8 − 0.8 = 0.224
    np.testing.assert_allclose(specular_map(n, lights).flatten().numpy(), [0.28, 0.224], atol=1e-6)
    # the mirror direction of a light along the normal is the light itself
    assert specular_map(torch.tensor([0.0, 0, 1]).view(1, 3, 1, 1), torch.tensor([[0.0, 0, 1]])).item() == 1
    with pytest.raises(ValueError, match=r"lights must be \(B, 3\)"):
        specular_map(n, torch.ones(2, 2))


def test_shading_is_clamped_lambertian():
    n = torch.tensor([0.0, 0.0, 1.0]).view(1, 3, 1, 1)
    lights = torch.tensor([[0.6, 0.0, 0.8], [0.0, 0.0, -1.0]])
    np.testing.assert_allclose(shading(n, lights).flatten().numpy(), [0.8, 0.0])


def test_networks_shapes_unit_normals_and_initialisation():
    net = NormalNet(n_images=5, width=24, depth=4)
    normals, features = net(normal_net_input(torch.rand(5, 3, 9, 11), torch.ones(9, 11)))
    assert normals.shape == (1, 3, 9, 11) and features.shape == (1, 24, 9, 11)
    torch.testing.assert_close(normals.norm(dim=1), torch.ones(1, 9, 11))
    weights = torch.cat([m.weight.flatten() for m in net.modules() if isinstance(m, torch.nn.Conv2d)])
    assert abs(weights.std().item() - 0.02) < 0.002 and abs(weights.mean().item()) < 0.002
    refl = ReflectanceNet(feature_width=24, width=8)
    out = refl(torch.rand(3, 3, 9, 11), torch.rand(3, 1, 9, 11), refl.global_term(features))
    assert out.shape == (3, 3, 9, 11) and (out >= 0).all()


def test_batch_norm_reads_out_with_the_statistics_it_was_fitted_with():
    """Taniai & Maehara normalise with the batch's own statistics, in the fit and the read-out
    alike: eval mode must not switch to running averages the fit never used."""
    net = NormalNet(n_images=4, width=8, depth=3, batch_norm=True)
    refl = ReflectanceNet(feature_width=8, width=4, batch_norm=True, branch=3)
    assert sum(isinstance(m, torch.nn.BatchNorm2d) for m in [*net.modules(), *refl.modules()]) == 2 + 4
    inputs = normal_net_input(torch.rand(4, 3, 6, 7), torch.ones(6, 7))
    images, spec = torch.rand(2, 3, 6, 7), torch.rand(2, 1, 6, 7)
    trained = [net(inputs)[0], refl(images, spec, refl.global_term(net(inputs)[1]))]
    net.eval(), refl.eval()
    read_out = [net(inputs)[0], refl(images, spec, refl.global_term(net(inputs)[1]))]
    for a, b in zip(trained, read_out):
        torch.testing.assert_close(a, b)
    assert (read_out[1] >= 0).all() and read_out[1].shape == (2, 3, 6, 7)


@pytest.mark.parametrize("field, value, message", [
    ("reflectance_branch", 0, "preset.reflectance_branch must be a whole number >= 1, got 0"),
    ("reflectance_branch", 2.5, "preset.reflectance_branch must be a whole number >= 1, got 2.5"),
    ("feature_scale_width", 0, "preset.feature_scale_width must be a whole number >= 1 or null, got 0"),
    ("feature_scale_width", 48.5, "preset.feature_scale_width must be a whole number >= 1 or null, got 48.5"),
    ("batch_norm", "yes", "preset.batch_norm must be true or false, got 'yes'"),
    ("cast_shadows", 1, "preset.cast_shadows must be true or false, got 1"),
    ("continue_black", "yes", "preset.continue_black must be true or false, got 'yes'"),
    ("continue_outline", "yes", "preset.continue_outline must be true or false, got 'yes'"),
    ("continue_held", 1.5, "preset.continue_held must be a share in [0, 1], got 1.5"),
    ("continue_held", True, "preset.continue_held must be a share in [0, 1], got True"),
    ("refine_pixels", "no", "preset.refine_pixels must be true or false, got 'no'"),
    ("highlights", 0, "preset.highlights must be true or false, got 0"),
    ("init", "woodham", "preset.init must be one of robust, least_squares, got 'woodham'"),
    ("residual", "l2", "preset.residual must be one of absolute, sqrt, relative, albedo, got 'l2'"),
    ("dark_hold", -0.1, "preset.dark_hold must be a number >= 0, got -0.1"),
    ("highlight_hold", "strong", "preset.highlight_hold must be a number >= 0, got 'strong'"),
    ("hold_light_frame", "yes", "preset.hold_light_frame must be true or false, got 'yes'"),
    ("censor_black", 1, "preset.censor_black must be true or false, got 1"),
    ("precision", "16-mixed", "preset.precision must be one of auto, 32-true, bf16-mixed, got '16-mixed'")])
def test_a_preset_names_a_bad_network_setting(field, value, message):
    with pytest.raises(InputError, match=re.escape(message)):
        Preset.from_config(**{field: value})


def test_a_relative_residual_weighs_a_dark_material_as_much_as_a_bright_one():
    """Half the object ten times darker: its pixels weigh ten times more (√10 with ``sqrt``), the weights average 1
    over the object, a black pixel is held at ten times the median's weight, off-object is 0."""
    images = torch.full((4, 3, 2, 6), 0.8)
    images[..., 3:] = 0.08
    images[..., 0, 5] = 0.0
    mask = torch.ones(1, 1, 2, 6)
    mask[..., 1, 0] = 0
    assert torch.equal(residual_weight(images, mask, "absolute"), torch.ones_like(mask))
    weight = residual_weight(images, mask, "relative")[0, 0]
    assert weight[0, 4] / weight[0, 0] == pytest.approx(10)
    assert weight[0, 5] / weight[0, 0] == pytest.approx(0.8 / (0.1 * 0.08))   # floor: 0.1 × median
    assert (weight * mask[0, 0]).sum() / mask.sum() == pytest.approx(1)
    assert weight[1, 0] == 0
    halfway = residual_weight(images, mask, "sqrt")[0, 0]
    assert halfway[0, 4] / halfway[0, 0] == pytest.approx(10 ** 0.5)
    assert (halfway * mask[0, 0]).sum() / mask.sum() == pytest.approx(1)


def test_an_albedo_residual_weighs_by_the_material_not_by_how_lit_a_pixel_is():
    """Same images, but the right half is dark because the shape hides it (its albedo as bright
    as the left's): ``albedo`` leaves it at weight 1 where ``relative`` gives it 10; a material
    ten times darker gets 10."""
    images = torch.full((4, 3, 2, 6), 0.8)
    images[..., 3:] = 0.08
    mask = torch.ones(1, 1, 2, 6)
    albedo = torch.full((1, 1, 2, 6), 0.5)
    assert torch.allclose(residual_weight(images, mask, "albedo", albedo), mask)
    albedo[..., 4:] = 0.05
    weight = residual_weight(images, mask, "albedo", albedo)[0, 0]
    assert weight[0, 5] / weight[0, 0] == pytest.approx(10)
    assert weight.mean() == pytest.approx(1)
    with pytest.raises(ValueError, match="needs the albedo"):
        residual_weight(images, mask, "albedo")


def test_the_global_term_equals_concatenating_the_features_to_every_image():
    refl = ReflectanceNet(feature_width=6, width=4)
    features, images, spec = torch.rand(1, 6, 7, 7), torch.rand(2, 3, 7, 7), torch.rand(2, 1, 7, 7)
    weight = torch.cat([refl.image_in.weight, refl.feature_in.weight], 1)
    joint = torch.nn.functional.conv2d(
        torch.nn.functional.pad(torch.cat([images, spec, features.expand(2, -1, -1, -1)], 1),
                                (1, 1, 1, 1)), weight, refl.image_in.bias)
    split = refl.image_in(torch.cat([images, spec], 1)) + refl.global_term(features)
    torch.testing.assert_close(joint, split)


def test_a_wide_normal_networks_features_are_scaled_down_in_f_sp_and_a_48_wide_ones_are_not():
    """The paper preset's 384 channels enter f_sp at 48/384 of their weight; the fast preset's 48
    as Taniai & Maehara have them, so its fits are unchanged by the option."""
    features = torch.rand(1, 384, 5, 6)
    plain = ReflectanceNet(feature_width=384, width=4)
    scaled = ReflectanceNet(feature_width=384, width=4, feature_scale=Preset(width=384).feature_scale())
    scaled.load_state_dict(plain.state_dict())
    torch.testing.assert_close(scaled.global_term(features), plain.global_term(features) / 8)
    assert Preset.from_config(width=48).feature_scale() == 1.0
    assert Preset.from_config(width=384, feature_scale_width=None).feature_scale() == 1.0


def test_paper_preset_has_the_papers_size():
    preset = Preset()
    nets = [NormalNet(96, preset.width, preset.depth, preset.first_kernel),
            ReflectanceNet(preset.width, preset.reflectance_width, preset.reflectance_depth)]
    count = sum(p.numel() for net in nets for p in net.parameters())
    assert 3.5e6 < count < 3.9e6          # "≈ 3.7 million parameters"


def groove_normals(size=8, slope=1.0):
    """(size, size, 3) normals of a V-groove along y, concave toward the camera."""
    c = np.arange(size) - (size - 1) / 2
    n = np.stack([-slope * np.sign(c), 0 * c, np.ones_like(c)], -1)
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    return np.repeat(n[None], size, 0)


def test_interreflection_solve_is_differentiable_float64():
    normals = groove_normals()
    mask = np.ones(normals.shape[:2], bool)
    solver = Interreflection(mask, np.full(mask.shape, 0.8), downsample=2)
    solver.update(normals)
    x = torch.tensor(normals, dtype=torch.float64).permute(2, 0, 1)[None].requires_grad_()
    assert torch.autograd.gradcheck(solver, (x,), eps=1e-6, atol=1e-6)


def test_interreflection_bends_groove_normals_toward_each_other_and_leaves_a_plane():
    normals = groove_normals(12)
    mask = np.ones(normals.shape[:2], bool)
    solver = Interreflection(mask, np.full(mask.shape, 0.9), downsample=2)
    solver.update(normals)
    x = torch.tensor(normals, dtype=torch.float32).permute(2, 0, 1)[None]
    pseudo = solver(x)[0].permute(1, 2, 0).numpy()
    # each wall receives light from the other, so its pseudo normal turns toward the groove's axis
    assert (np.abs(pseudo[:, :6, 0]) < np.abs(normals[:, :6, 0]) - 1e-3).all()
    flat = np.zeros_like(normals)
    flat[..., 2] = 1
    solver.update(flat)
    torch.testing.assert_close(solver(torch.tensor(flat).permute(2, 0, 1)[None]),
                               torch.tensor(flat).permute(2, 0, 1)[None])


def test_interreflection_bend_is_the_angle_between_rendered_and_fitted_normals():
    normals = groove_normals(12)
    mask = np.ones(normals.shape[:2], bool)
    solver = Interreflection(mask, np.full(mask.shape, 0.9), downsample=2)
    solver.update(normals)
    pseudo = solver(torch.tensor(normals, dtype=torch.float32).permute(2, 0, 1)[None])[0]
    bend = interreflection_bend(normals, pseudo.permute(1, 2, 0).numpy(), mask)
    assert 0.5 < bend["mean"] < bend["max"] < 45
    tilted = np.zeros_like(normals)
    tilted[..., 1:] = np.sqrt(0.5)          # 45° from +z
    flat = np.zeros_like(normals)
    flat[..., 2] = 1
    assert interreflection_bend(flat, tilted, mask) == pytest.approx({"mean": 45.0, "max": 45.0})


def test_working_factor_and_upsampled_normals():
    assert working_factor(1000, None) == 1 and working_factor(1000, 1000) == 1
    assert working_factor(1001, 1000) == 2 and working_factor(45200, 16000) == 2
    normals = np.zeros((4, 4, 3), np.float32)
    normals[..., 2] = 1
    mask = np.zeros((4, 4), bool)
    mask[1:3, 1:3] = True
    up = upsample_normals(normals, mask, (7, 8), 2)
    assert up.shape == (7, 8, 3)
    np.testing.assert_allclose(up[..., 2], 1, atol=1e-6)


def test_detail_is_added_to_the_upsampled_fit():
    rng = np.random.default_rng(0)
    fine = rng.normal(size=(8, 8, 3)) + [0, 0, 3]
    fine /= np.linalg.norm(fine, axis=-1, keepdims=True)
    coarse = fine.reshape(4, 2, 4, 2, 3).mean((1, 3))
    coarse /= np.linalg.norm(coarse, axis=-1, keepdims=True)
    mask = np.ones((4, 4), bool)
    # a fit equal to the coarse initialisation gets the fine initialisation back exactly
    np.testing.assert_allclose(upsample_with_detail(coarse, coarse, fine, mask, 2), fine, atol=1e-6)
    # a fit that differs keeps its own shape: a tilt survives, with the detail on top
    tilted = np.broadcast_to(np.array([0.6, 0, 0.8]), (4, 4, 3))
    out = upsample_with_detail(tilted, coarse, fine, mask, 2)
    np.testing.assert_allclose(np.linalg.norm(out, axis=-1), 1, atol=1e-6)
    assert np.mean(out[..., 0]) > 0.5 and not np.allclose(out, out[0, 0])


def test_a_fit_on_a_coarser_working_grid_returns_full_resolution_normals(sphere):
    estimate = neural_inverse_rendering(sphere, sphere.light_directions,
                                        Preset.from_config(**TINY, max_pixels=int(sphere.mask.sum()) // 3),
                                        InterreflectionModel(**NAYAR))
    assert estimate.info["fit_downsample"] == 2
    assert estimate.normals.shape == sphere.normals.shape
    np.testing.assert_allclose(np.linalg.norm(estimate.normals[sphere.mask], axis=-1), 1, atol=1e-5)
    assert not estimate.normals[~sphere.mask].any()
    assert angular_error(estimate.normals, sphere.normals)[sphere.mask].mean() < 30


@pytest.mark.parametrize("init", ["robust", "least_squares"])
def test_the_fit_starts_from_the_initialisation_the_preset_names(sphere, init):
    from unps.solvers.rpca import robust_init
    from unps.solvers.woodham import woodham

    start = {"robust": robust_init, "least_squares": woodham}[init](sphere, sphere.light_directions)
    other = {"robust": woodham, "least_squares": robust_init}[init](sphere, sphere.light_directions)
    system, _ = build_system(sphere, sphere.light_directions, Preset.from_config(**TINY, init=init),
                             InterreflectionModel(enabled=False), False, "test")
    init_normals = system.init_normals[0].permute(1, 2, 0).numpy()[sphere.mask]
    np.testing.assert_allclose(init_normals, start.normals[sphere.mask], atol=1e-6)
    assert angular_error(init_normals, other.normals[sphere.mask]).mean() > 0.5   # measured: 1.9°


def test_the_albedo_residual_is_weighed_by_the_initialisations_albedo(sphere):
    """A sphere painted half ten times darker: ``preset.residual=albedo`` weighs its dark half up by
    about ten, from the robust initialisation's albedo, not from the images' brightness."""
    from unps.solvers.rpca import robust_init

    half = sphere.resolution[1] // 2
    shade = np.where(np.arange(sphere.resolution[1]) < half, 1.0, 0.1)
    painted = sphere.replace(images=sphere.images * shade[None, None, :, None])
    system, _ = build_system(painted, painted.light_directions,
                             Preset.from_config(**TINY, residual="albedo"),
                             InterreflectionModel(enabled=False), False, "test")
    albedo = robust_init(painted, painted.light_directions).albedo.mean(-1)
    expected = residual_weight(system.images, system.mask, "albedo",
                               torch.as_tensor(albedo, dtype=torch.float32)[None, None])
    torch.testing.assert_close(system.pixel_weight, expected)
    weight = system.pixel_weight[0, 0].numpy()
    left, right = sphere.mask.copy(), sphere.mask.copy()
    left[:, half:] = False
    right[:, :half] = False
    assert np.median(weight[right]) / np.median(weight[left]) == pytest.approx(10, rel=0.05)


def dark_quarter(sphere):
    """``sphere`` with its left quarter painted 20 times darker, and that quarter's mask."""
    quarter = sphere.resolution[1] // 4
    shade = np.where(np.arange(sphere.resolution[1]) < quarter, 0.05, 1.0)
    dark = sphere.mask.copy()
    dark[:, quarter:] = False
    return sphere.replace(images=sphere.images * shade[None, None, :, None]), dark


def test_after_the_prior_a_dark_material_stays_near_its_start_and_a_bright_one_moves_as_before(sphere):
    """A sphere whose left quarter is painted 20 times darker, the prior on for 10 of 60 steps:
    with ``preset.dark_hold`` the dark quarter ends far nearer the initialisation than without,
    and the rest, whose albedo is above 0.2 of the median, is not held; the fit's
    ``dark_share`` is the dark quarter's share of the object."""
    import lightning as L

    painted, dark = dark_quarter(sphere)
    bright = sphere.mask & ~dark
    moved = {}
    for hold in (0.0, 1.0):
        L.seed_everything(0, verbose=False)
        preset = Preset.from_config(**{**TINY, "steps": 60, "lr_drop_at": 58, "prior_steps": 10,
                                       "dark_hold": hold})
        system, _ = build_system(painted, painted.light_directions, preset,
                                 InterreflectionModel(enabled=False), False, "test")
        weight = system.dark_weight[0, 0].numpy()
        assert weight[bright].max() == 0 and weight[dark].min() > 0.5
        L.Trainer(max_steps=60, logger=False, enable_checkpointing=False, enable_progress_bar=False,
                  enable_model_summary=False).fit(system)
        with torch.no_grad():
            normals = system.render(torch.arange(painted.n_images), noise=False)["normals"]
        start = system.init_normals[0].permute(1, 2, 0).numpy()
        angle = angular_error(normals[0].permute(1, 2, 0).numpy(), start)
        moved[hold] = angle[dark].mean(), angle[bright].mean()
    assert moved[1.0][0] < 0.5 * moved[0.0][0], moved     # measured: 106° without, 7° with
    assert moved[1.0][1] > 0.5 * moved[0.0][1], moved     # measured: 3.8° and 4.0°
    assert tiny_fit(painted).info["dark_share"] == pytest.approx(dark.sum() / sphere.mask.sum())
    assert tiny_fit(painted, dark_hold=0.0).info["dark_share"] is None


def test_the_pixels_the_fit_held_dark_keep_the_fit_when_each_pixel_is_solved(sphere):
    """The painted sphere fitted on a ×2 grid: its dark quarter, held toward N_init, is marked on
    the subject's grid to keep the upsampled fit, the bright rest to be solved from its own images;
    without the hold nothing is marked."""
    painted, dark = dark_quarter(sphere)
    work = painted.downsample(2)
    for hold in (0.1, 0.0):
        system, _ = build_system(work, work.light_directions, Preset.from_config(**TINY, dark_hold=hold),
                                 InterreflectionModel(enabled=False), False, "test")
        held = held_from_solve(system, work.mask, sphere.mask.shape, 2)
        if hold:
            assert held.shape == sphere.mask.shape
            assert held[dark].mean() > 0.8 and not held[sphere.mask & ~dark].any()
        else:
            assert held is None


def test_a_held_dark_stripe_is_taken_toward_the_surface_continued_across_it(caplog):
    """A sphere with a vertical stripe of a dark material whose images are a Lambertian sphere's
    turned 40° (a sheen the model cannot render): the fit holds the stripe near its wrong start;
    with ``preset.continue_held=1`` the read-out continues the surface across it from the rest,
    which stays as it was, and with 0.5 it takes the stripe half-way there (the normalised mean of
    the two); the share continued is reported and logged."""
    sphere = render_lambertian("sphere", size=32, n_lights=24, seed=4)
    angle = np.radians(40)
    turn = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
    sheen = np.clip(np.einsum("hwc,nc->nhw", sphere.normals @ turn.T, sphere.light_directions), 0, None)
    stripe = sphere.mask.copy()
    stripe[:, :13] = stripe[:, 19:] = False
    images = np.where(stripe[None, ..., None], 0.05 * sheen[..., None], sphere.images)
    painted = sphere.replace(images=images.astype(np.float32))
    caplog.set_level("INFO")
    fits = {share: tiny_fit(painted, continue_held=share) for share in (0.0, 0.5, 1.0)}
    errors = {share: angular_error(fit.normals, sphere.normals) for share, fit in fits.items()}
    assert errors[0.0][stripe].mean() > 20                                  # measured: 79°
    assert errors[1.0][stripe].mean() < 0.5 * errors[0.0][stripe].mean()   # measured: 7.3°
    rest = sphere.mask & ~stripe
    held = sphere.mask & (fits[1.0].normals != fits[0.0].normals).any(-1)
    assert not (held & rest).any() and held.sum() > 0.8 * stripe.sum()
    half_way = unit(fits[0.0].normals[held] + fits[1.0].normals[held])
    np.testing.assert_allclose(fits[0.5].normals[held], half_way, atol=1e-5)
    assert fits[1.0].info["continued_held_share"] == pytest.approx(held.sum() / sphere.mask.sum())
    assert fits[0.0].info["continued_held_share"] is None
    assert "of a dark material the fit held and no highlight lights" in caplog.text


def test_black_pixels_are_continued_as_before_whatever_the_held_ones_become():
    """A sphere's normals with a black band and a held band 30° off beside it: the black band is
    continued exactly as without held pixels (the held ones are among its anchors as they are), the
    held band moves toward the sphere by the share asked, and nothing else moves."""
    sphere = render_lambertian("sphere", size=32, n_lights=12, seed=2)
    mask, normals = sphere.mask, sphere.normals.astype(np.float32)
    black, held = mask.copy(), mask.copy()
    black[:, :10] = black[:, 14:] = False
    held[:, :16] = held[:, 20:] = False
    tilt = np.array([np.sin(np.radians(30)), 0, np.cos(np.radians(30))]) - [0, 0, 1]
    start = np.where(held[..., None], unit(normals + tilt), normals).astype(np.float32)
    alone = continue_surface(start, mask, black)
    for share in (0.0, 0.25, 1.0):
        out = with_surface_continued(start, mask, black, held, share)
        np.testing.assert_array_equal(out[black], alone[black])
        np.testing.assert_array_equal(out[mask & ~black & ~held], start[mask & ~black & ~held])
        error = angular_error(out, sphere.normals)[held].mean()
        if share == 0:
            np.testing.assert_array_equal(out[held], start[held])
        elif share == 0.25:
            assert error < 0.9 * angular_error(start, sphere.normals)[held].mean()
        else:
            assert error < 10                                                  # measured: 5.3° (from 30°)


def test_the_read_out_rules_continue_black_pixels_only_when_asked_and_leave_their_inputs_alone():
    """:func:`unps.inverse.fit.with_read_out_rules` on a sphere's normals 20° off in a black band:
    with every rule off nothing moves and no share is reported; with ``continue_black`` the band
    is the surface continued across it, and nothing else moves. The faint mask it is given stays
    as it was, though its one pixel, whose values follow Lambert's cosine, is not counted faint."""
    sphere = render_lambertian("sphere", size=32, n_lights=12, seed=2)
    mask = sphere.mask
    black = mask.copy()
    black[:, :12] = black[:, 18:] = False
    faint = np.zeros_like(mask)
    faint[10, 10] = True
    tilt = np.array([np.sin(np.radians(20)), 0, np.cos(np.radians(20))]) - [0, 0, 1]
    normals = np.where(black[..., None], unit(sphere.normals + tilt), sphere.normals).astype(np.float32)
    lights, scales = sphere.light_directions, np.ones(sphere.n_images)
    off = Preset(highlights=False, continue_black=False, continue_held=0.0)
    kept, shares = with_read_out_rules(sphere, normals, lights, scales, off, black, faint, None)
    np.testing.assert_array_equal(kept, normals)
    assert shares["highlight_share"] is None and shares["continued_held_share"] is None
    assert shares["black_share"] == pytest.approx(black.sum() / mask.sum())
    assert shares["faint_share"] == 0                       # its values follow Lambert's cosine
    on = Preset(highlights=False, continue_black=True, continue_held=0.0)
    continued, _ = with_read_out_rules(sphere, normals, lights, scales, on, black, faint, None)
    np.testing.assert_array_equal(continued[mask & ~black], normals[mask & ~black])
    np.testing.assert_allclose(continued[black],
                               continue_surface(normals, mask, black, outline=on.continue_outline)[black])
    assert angular_error(continued, sphere.normals)[black].mean() < 0.5 * 20     # from 20° off
    assert faint.sum() == 1 and faint[10, 10]


def test_a_held_pixel_keeps_the_upsampled_fit_and_the_others_are_solved(caplog):
    """Normals 6° off and clean images: the held left half keeps its start bit for bit, the right
    half is put right, and the log counts the held pixels."""
    sphere = render_lambertian("sphere", size=32, n_lights=24, seed=4)
    tilt = np.array([np.sin(np.radians(6)), 0, np.cos(np.radians(6))])
    start = np.where(sphere.mask[..., None], unit(sphere.normals + tilt - [0, 0, 1]), sphere.normals)
    start = start.astype(np.float32)
    held = sphere.mask.copy()
    held[:, 16:] = False
    _, coarse = block_mean(np.zeros((32, 32, 1)), sphere.mask, 2)
    caplog.set_level("INFO")
    normals, _ = solved_per_pixel(sphere.replace(light_intensities=None), start, np.zeros_like(start),
                                  np.full((24, *coarse.shape, 3), 0.8, np.float32), sphere.light_directions,
                                  np.ones(24, np.float32), coarse, 2, np.ones((24, 32, 32), bool), held)
    np.testing.assert_array_equal(normals[held], start[held])
    solved = sphere.mask & ~held
    assert angular_error(normals, sphere.normals)[solved].mean() < 0.5
    assert f"{held.sum()} of a dark material keep the fit" in caplog.text

def sphere_system(prior_weight, refine_lights=False, light_directions=None, **preset):
    subject = render_lambertian("sphere", size=24, n_lights=12, seed=1)
    lights = subject.light_directions if light_directions is None else light_directions
    images = torch.as_tensor(subject.images / subject.images[:, subject.mask].mean()).permute(0, 3, 1, 2)
    flat = np.zeros(subject.mask.shape + (3,), np.float32)
    flat[..., 2] = 1
    preset = Preset.from_config(**{**TINY, "prior_weight": prior_weight, "pixel_keep": 1.0, **preset})
    return InverseRendering(
        NormalNet(12, 16, 3, 1), ReflectanceNet(16, 8), images, subject.mask,
        torch.as_tensor(lights, dtype=torch.float32), torch.as_tensor(flat).permute(2, 0, 1), None,
        preset.schedule, refine_lights=refine_lights,
        true_normals=torch.as_tensor(subject.normals).permute(2, 0, 1)), subject


def test_twenty_steps_on_a_tiny_sphere_lower_the_loss_and_the_error():
    """No prior: the rendering loss alone must drive the normals toward the sphere's."""
    import lightning as L

    L.seed_everything(0, verbose=False)
    system, subject = sphere_system(prior_weight=0.0)

    def state():
        with torch.no_grad():
            out = system.render(torch.arange(12), noise=False)
            loss = ((out["reconstruction"] - out["observed"]).abs() * system.mask).sum().item()
            return loss, system.normal_mae(out["normals"]).item()

    loss0, mae0 = state()
    L.Trainer(max_steps=20, logger=False, enable_checkpointing=False, enable_progress_bar=False,
              enable_model_summary=False).fit(system)
    loss1, mae1 = state()
    assert loss1 < 0.8 * loss0         # measured: 10172 → 6983
    assert mae1 < 0.5 * mae0           # measured: 72° → 22°


def cpu_with(monkeypatch, amx: bool, avx512_bf16: bool) -> None:
    """Make torch's checks report a CPU with (or without) AMX tiles and AVX512-BF16 instructions."""
    monkeypatch.setattr(torch.cpu, "_is_amx_tile_supported", lambda: amx)
    monkeypatch.setattr(torch.cpu, "_is_avx512_bf16_supported", lambda: avx512_bf16)


def test_the_networks_precision_is_bfloat16_where_the_hardware_has_it_unless_chosen(monkeypatch):
    auto, chosen = Preset.from_config(), Preset.from_config(precision="bf16-mixed")
    assert auto.precision == "auto"
    for amx, avx512_bf16, precision in ((False, False, "32-true"), (True, False, "bf16-mixed"),
                                        (False, True, "bf16-mixed"), (True, True, "bf16-mixed")):
        cpu_with(monkeypatch, amx, avx512_bf16)
        assert auto.network_precision(torch.device("cpu")) == precision
        assert Preset.from_config(precision="32-true").network_precision(torch.device("cpu")) == "32-true"
    cpu_with(monkeypatch, amx=False, avx512_bf16=False)
    assert auto.network_precision(torch.device("cuda", 1)) == "bf16-mixed"
    assert chosen.network_precision(torch.device("cpu")) == "bf16-mixed"
    assert Preset.from_config(precision="32-true").network_precision(torch.device("cuda")) == "32-true"
    with initialize_config_module(config_module="unps.conf", version_base="1.3"):
        for preset in ("fast", "paper"):
            assert compose("fit", overrides=[f"preset={preset}"]).preset.precision == "auto"


def test_the_fast_preset_solves_each_pixel_and_the_paper_preset_keeps_its_networks_normals():
    """The fast preset inherits the paper preset's settings but solves each pixel from its own
    images (detail finer than its working grid); the paper preset keeps its full-resolution
    network's normals (cat's full fit 5.00° → 5.77° with the solve: experiments/calibrated)."""
    with initialize_config_module(config_module="unps.conf", version_base="1.3"):
        solves = {preset: compose("fit", overrides=[f"preset={preset}"]).preset.refine_pixels
                  for preset in ("fast", "paper")}
    assert solves == {"fast": True, "paper": False}


def test_bf16_on_a_cpu_warns_only_where_the_cpu_lacks_bfloat16_hardware(sphere, caplog, monkeypatch):
    """A CPU with AMX or AVX512-BF16 runs bfloat16 convolutions faster than float32
    (experiments/speed): the fit says so; one with neither is warned that they may run several
    times slower."""
    said_native = "on a CPU with bfloat16 instructions (AMX or AVX512-BF16)"
    for precision, amx, avx512_bf16, said in (("bf16-mixed", True, False, said_native),
                                              ("auto", True, False, said_native),
                                              ("auto", False, True, said_native),
                                              ("bf16-mixed", False, False, "no bfloat16 instructions")):
        preset = Preset.from_config(**TINY, precision=precision)
        cpu_with(monkeypatch, amx, avx512_bf16)
        native = amx or avx512_bf16
        assert native_bfloat16(torch.device("cpu")) is native
        caplog.clear()
        with caplog.at_level(logging.INFO):
            system, _ = build_system(sphere, sphere.light_directions, preset, InterreflectionModel(enabled=False),
                                     False, "")
        assert system.networks_in_bf16
        [record] = [r for r in caplog.records if f"preset.precision={precision}" in r.getMessage()]
        assert said in record.getMessage()
        assert record.levelno == (logging.INFO if native else logging.WARNING)
    cpu_with(monkeypatch, amx=False, avx512_bf16=False)
    caplog.clear()
    with caplog.at_level(logging.INFO):      # auto without either: float32, nothing to say
        system, _ = build_system(sphere, sphere.light_directions, Preset.from_config(**TINY),
                                 InterreflectionModel(enabled=False), False, "")
    assert not system.networks_in_bf16 and "preset.precision" not in caplog.text
    assert native_bfloat16(torch.device("cuda"))


def test_networks_in_bf16_render_float32_maps_close_to_the_float32_ones(sphere, caplog, monkeypatch):
    """``preset.precision=bf16-mixed`` reaches the system; its networks then compute in bfloat16
    (the maps differ from float32's) and hand float32 maps to the physics: unit normals within a
    degree of float32's on average, reflectance within a percent (measured: 0.43°, 0.11 %)."""
    torch.manual_seed(0)
    cpu_with(monkeypatch, amx=False, avx512_bf16=False)
    system, _ = build_system(sphere, sphere.light_directions, Preset.from_config(**TINY, precision="bf16-mixed"),
                             InterreflectionModel(enabled=False), False, "")
    assert system.networks_in_bf16
    assert "preset.precision=bf16-mixed on cpu: this CPU has no bfloat16 instructions" in caplog.text
    index = torch.arange(sphere.n_images)
    with torch.no_grad():
        half = system.render(index, noise=False)
        system.networks_in_bf16 = False
        full = system.render(index, noise=False)
    for key in ("normals", "reflectance", "reconstruction"):
        assert half[key].dtype == torch.float32
        assert not torch.equal(half[key], full[key])
    assert torch.allclose(half["normals"].norm(dim=1), torch.ones(1), atol=1e-5)
    degrees = angular_error(half["normals"][0].permute(1, 2, 0).numpy()[sphere.mask],
                            full["normals"][0].permute(1, 2, 0).numpy()[sphere.mask])
    assert degrees.mean() < 1.0
    relative = (half["reflectance"] - full["reflectance"]).abs().sum() / full["reflectance"].abs().sum()
    assert relative < 0.01


def test_lights_learnt_in_the_fit_keep_their_frame_unless_it_is_freed():
    """Lights handed to the fit turned 10° about the view axis: the fit may move each light, but
    with ``hold_light_frame`` not all of them together; freed, it turns them."""
    import lightning as L

    turn = np.radians(10)
    about_view = np.array([[np.cos(turn), -np.sin(turn), 0], [np.sin(turn), np.cos(turn), 0], [0, 0, 1]])
    given = render_lambertian("sphere", size=24, n_lights=12, seed=1).light_directions @ about_view.T
    rotation = {}
    for hold in (True, False):
        L.seed_everything(0, verbose=False)
        system, _ = sphere_system(0.1, refine_lights=True, light_directions=given, hold_light_frame=hold)
        L.Trainer(max_steps=60, logger=False, enable_checkpointing=False, enable_progress_bar=False,
                  enable_model_summary=False).fit(system)
        learnt = system.lights()[0].detach().numpy()
        assert np.degrees(np.arccos(np.clip((learnt * given).sum(1), -1, 1))).mean() > 0.1   # 1.2° / 1.1°
        rotation[hold] = rotation_angle(best_rotation(given, learnt))
    assert rotation[True] < 0.05 and rotation[False] > 5 * rotation[True]     # measured: 0.003° / 0.18°


def test_fit_writes_the_unps_outputs(tmp_path):
    metrics = fit(config(tmp_path, *tiny_overrides(), "light=gt"))
    for name in ("reflectance.npy", "reconstruction.npy", "reflectance.png", "reconstruction.png",
                 "normals.npy", "mesh.ply", "checkpoints/last.ckpt", "metrics.json"):
        assert (tmp_path / name).exists(), name
    saved = json.loads((tmp_path / "metrics.json").read_text())
    assert saved["method"] == "unps" and saved["fit_steps"] == 20 and saved["facets"] > 0
    assert saved["network_precision"] == ("bf16-mixed" if native_bfloat16(torch.device("cpu")) else "32-true")
    assert np.load(tmp_path / "reflectance.npy").shape == (12, *saved["fit_resolution"], 3)
    assert metrics["normal_mae"] < 30


@pytest.mark.parametrize("shadows", [[], ["preset.cast_shadows=true"]], ids=["plain", "cast_shadows"])
def test_a_killed_fit_resumes_from_its_last_checkpoint_and_a_finished_one_reads_out_again(
        tmp_path, monkeypatch, shadows):
    step = InverseRendering.training_step

    def dies_at_25(self, batch, batch_idx):
        if self.global_step == 25:
            raise RuntimeError("killed")   # as a crash; SIGKILL leaves the folder in the same state
        return step(self, batch, batch_idx)

    overrides = [*tiny_overrides(steps=40), "light=gt", *shadows]
    monkeypatch.setattr(InverseRendering, "training_step", dies_at_25)
    cfg = config(tmp_path, *overrides)
    with pytest.raises(RuntimeError, match="killed"):
        fit(cfg)
    assert (tmp_path / "checkpoints" / "last.ckpt").is_file()
    assert not (tmp_path / "metrics.json").exists()
    monkeypatch.setattr(InverseRendering, "training_step", step)
    metrics = fit(cfg)
    assert metrics["resumed_from_step"] == 20 and metrics["normal_mae"] < 30
    uninterrupted = tmp_path / "uninterrupted"
    fit(config(uninterrupted, *overrides))
    np.testing.assert_array_equal(np.load(tmp_path / "normals.npy"), np.load(uninterrupted / "normals.npy"))
    rerun = fit(config(uninterrupted, *overrides))   # a finished folder
    assert rerun["resumed_from_step"] == 40
    np.testing.assert_array_equal(np.load(tmp_path / "normals.npy"), np.load(uninterrupted / "normals.npy"))
    read_out = fit(config(uninterrupted, *overrides, "preset.refine_pixels=false", "preset.continue_held=0"))
    assert read_out["resumed_from_step"] == 40      # settings of the read-out alone: no step is run again
    other = config(tmp_path, *overrides, "preset.lr=1e-3")
    with pytest.raises(InputError, match="belongs to another run"):
        fit(other)


def test_ctrl_c_says_where_the_fit_stopped_and_the_same_command_resumes(tmp_path, monkeypatch):
    import signal

    from unps.errors import Interrupted

    step = InverseRendering.training_step

    def stopped_at_25(self, batch, batch_idx):
        if self.global_step == 25:
            raise KeyboardInterrupt
        return step(self, batch, batch_idx)

    monkeypatch.setattr(InverseRendering, "training_step", stopped_at_25)
    cfg = config(tmp_path, *tiny_overrides(steps=40), "light=gt")
    handler = signal.getsignal(signal.SIGINT)
    try:
        with pytest.raises(Interrupted, match="interrupted at step 25 of 40: the same command resumes "
                                              "from the checkpoint of step 20"):
            fit(cfg)
    finally:
        signal.signal(signal.SIGINT, handler)          # Lightning ignores Ctrl-C once it has seen one
    monkeypatch.setattr(InverseRendering, "training_step", step)
    assert fit(cfg)["resumed_from_step"] == 20


def test_a_diverging_fit_stops_with_a_clear_message(tmp_path, monkeypatch):
    render = InverseRendering.render

    def poisoned(self, index, noise=True):
        out = render(self, index, noise)
        if self.global_step >= 12:
            out["reconstruction"] = out["reconstruction"] * float("nan")
        return out

    monkeypatch.setattr(InverseRendering, "render", poisoned)
    with pytest.raises(Diverged, match="became nan at step 12.*last.ckpt"):
        fit(config(tmp_path, *tiny_overrides(), "light=gt"))
    assert torch.load(tmp_path / "checkpoints" / "last.ckpt", weights_only=False)["global_step"] == 10
    assert not (tmp_path / "metrics.json").exists()


def test_refined_lights_are_reported_and_need_method_unps(tmp_path):
    metrics = fit(config(tmp_path / "a", *tiny_overrides(), "light=refine"))
    assert metrics["light"] == "refine" and "light_dir_mae" in metrics
    fitted = metrics["light_stages"][-1]
    assert fitted["stage"] == "fit" and fitted["outcome"] == "changed" and fitted["evidence"]["moved_deg"] > 0
    assert fitted["light_dir_mae"] == pytest.approx(metrics["light_dir_mae"])
    with pytest.raises(InputError, match="light=refine .* needs method=unps"):
        fit(config(tmp_path / "b", "subject=lambertian", "method=rpca", "light=refine"))


def test_the_self_calibrated_lights_are_learnt_further_where_the_method_can(tmp_path):
    def nodes(*overrides):
        cfg = config(tmp_path, *overrides)
        return cfg.light, cfg.method

    assert learns_lights(*nodes("light=selfcal", "method=unps"))
    assert not learns_lights(*nodes("light=selfcal", "method=rpca"))
    assert not learns_lights(*nodes("light=estimated", "method=unps"))
    assert not learns_lights(*nodes("light=gt", "method=unps"))
    assert learns_lights(*nodes("light=refine", "method=unps"))
    with pytest.raises(InputError, match="light.refine=maybe: expected true, false or auto"):
        learns_lights(OmegaConf.create({"refine": "maybe"}), nodes("method=unps")[1])


def test_interreflection_off_and_in_memory_fits(sphere):
    for enabled in (False, True):
        estimate = neural_inverse_rendering(sphere, sphere.light_directions, Preset.from_config(**TINY),
                                            InterreflectionModel(**NAYAR, enabled=enabled))
        mae = angular_error(estimate.normals, sphere.normals)[sphere.mask].mean()
        assert estimate.normals.shape == sphere.normals.shape and mae < 30
        info = estimate.info
        assert info["interreflection"] is enabled
        assert (info["interreflection_bend_deg"] >= 0) if enabled else info["interreflection_bend_deg"] is None
        assert info["moved_from_start_deg"] > 0


def test_pixels_black_in_every_image_get_the_surface_continued(caplog):
    """An 8-bit sphere with a band black in all its images: with ``continue_black`` (default) the
    band's normals are the fitted ones continued across it and the rest are the same as without;
    ``black_share`` is the band's share either way; ``continue_outline=false`` continues it without
    the occluding contour where the band meets the outline."""
    sphere = render_lambertian("sphere", size=32, n_lights=12, seed=2)
    images = np.round(sphere.images / sphere.images.max() * 255) / 255
    band = sphere.mask & (np.abs(np.arange(32) - 18) < 3)[None, :]
    images[:, band] = np.where(np.arange(12)[:, None, None] % 2, 1 / 255, 0)   # levels 0 and 1
    dark = sphere.replace(images=images.astype(np.float32), light_intensities=None)   # as captured
    caplog.set_level("INFO")
    continued, plain = tiny_fit(dark, continue_black=True), tiny_fit(dark, continue_black=False)
    share = band.sum() / sphere.mask.sum()
    assert continued.info["black_share"] == plain.info["black_share"] == pytest.approx(share)
    np.testing.assert_array_equal(continued.normals[~band], plain.normals[~band])
    expected = continue_surface(plain.normals, sphere.mask, band)
    np.testing.assert_allclose(continued.normals[band], expected[band], atol=1e-4)
    assert angular_error(continued.normals[band], plain.normals[band]).mean() > 1
    assert "of the object is black in every image" in caplog.text and "continued" in caplog.text
    straight = tiny_fit(dark, continue_black=True, continue_outline=False)
    expected = continue_surface(plain.normals, sphere.mask, band, outline=False)
    np.testing.assert_allclose(straight.normals[band], expected[band], atol=1e-4)
    assert angular_error(straight.normals[band], continued.normals[band]).mean() > 0.5



def test_faintly_lit_pixels_get_the_surface_continued_as_black_ones_do(caplog):
    """An 8-bit sphere with two dim bands: one at 8 levels in 3 of its 12 images (faintly lit:
    :func:`unps.data.checks.faintly_lit`), one at 8 levels in 9 (lit, if dimly). With
    ``continue_black`` the faint band's normals are the fitted ones continued across it, and
    nothing else moves (the dim band, a dark material, is not taken toward the continued surface
    either: ``continue_held=0``); ``faint_share`` is its share either way."""
    sphere = render_lambertian("sphere", size=32, n_lights=12, seed=2)
    images = np.round(sphere.images / sphere.images.max() * 255) / 255
    columns = np.arange(32)[None, :]
    faint = sphere.mask & (np.abs(columns - 18) < 3)
    dim = sphere.mask & (np.abs(columns - 9) < 2)
    images[:, faint] = np.where(np.arange(12)[:, None, None] < 3, 8 / 255, 0)
    images[:, dim] = np.where(np.arange(12)[:, None, None] < 9, 8 / 255, 0)
    dark = sphere.replace(images=images.astype(np.float32), light_intensities=None)   # as captured
    caplog.set_level("INFO")
    continued, plain = (tiny_fit(dark, continue_black=black, continue_held=0) for black in (True, False))
    share = faint.sum() / sphere.mask.sum()
    assert continued.info["faint_share"] == plain.info["faint_share"] == pytest.approx(share)
    assert continued.info["black_share"] == 0
    np.testing.assert_array_equal(continued.normals[~faint], plain.normals[~faint])
    expected = continue_surface(plain.normals, sphere.mask, faint)
    np.testing.assert_allclose(continued.normals[faint], expected[faint], atol=1e-4)
    assert angular_error(continued.normals[faint], plain.normals[faint]).mean() > 1
    assert "of the object is faintly lit" in caplog.text


def test_a_dark_diffuse_material_keeps_its_shading_and_speckle_holds_none():
    """:func:`unps.inverse.fit.unshaded`: a dark diffuse material quantised to 8 levels under 96
    lights still follows Lambert's cosine (its faint pixels keep the fit's normals); values at
    random levels in random images (a dark glossy material's speckle) do not."""
    rng = np.random.default_rng(0)
    lights = rng.normal(size=(96, 3))
    lights[:, 2] = np.abs(lights[:, 2]) + 0.5
    lights /= np.linalg.norm(lights, axis=1, keepdims=True)
    normals = rng.normal(size=(200, 3))
    normals[:, 2] = np.abs(normals[:, 2]) + 1
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    shading = np.clip(lights @ normals.T, 0, None)
    dark = np.round(shading / shading.max(0) * 8) / 255
    speckle = np.where(rng.random((96, 200)) < 0.2, rng.integers(1, 9, (96, 200)), 0) / 255
    assert not unshaded(dark, lights).any()
    assert unshaded(speckle, lights).mean() > 0.9

@pytest.mark.parametrize("max_pixels, factor", [(400, 2), (None, 1)])
def test_each_pixel_of_the_subject_is_solved_from_its_own_images(caplog, max_pixels, factor):
    """A 40×40 Lambertian sphere fitted on a ×2 grid, and at full resolution: each pixel's normal
    solved from its own images under the fitted reflectance is nearer the truth than the fit's
    (upsampled) normals, which ``refine_pixels=false`` returns."""
    sphere = render_lambertian("sphere", size=40, n_lights=16, seed=1)
    caplog.set_level("INFO")

    refined, plain = (tiny_fit(sphere, max_pixels=max_pixels, refine_pixels=refine) for refine in (True, False))
    assert refined.info["fit_downsample"] == factor
    error = {name: angular_error(e.normals, sphere.normals)[sphere.mask].mean()
             for name, e in (("refined", refined), ("plain", plain))}
    assert error["refined"] < 0.5 * error["plain"]
    assert "each pixel's normal solved from its own images" in caplog.text


def test_each_pixel_is_solved_for_the_normal_the_fit_renders_and_brought_back(caplog):
    """Rendered with interreflected normals N_ny = N_o + d (d, the fit's N_ny − N_o), each pixel's
    solve finds N_ny and takes d off again: N_o, which the images alone would not give."""
    sphere = render_lambertian("sphere", size=24, n_lights=16, seed=3)
    offset = np.broadcast_to(np.array([0.08, -0.03, 0.0], np.float32), sphere.normals.shape)
    rendered = unit(sphere.normals + offset)
    shading = np.clip(np.einsum("hwc,nc->nhw", rendered, sphere.light_directions), 0, None)
    images = (np.full(3, 0.8) * shading[..., None] * sphere.mask[None, ..., None]).astype(np.float32)
    subject = sphere.replace(images=images, light_intensities=None)
    _, coarse = block_mean(np.zeros((24, 24, 1)), sphere.mask, 2)
    reflectance = np.full((16, *coarse.shape, 3), 0.8, np.float32)
    caplog.set_level("INFO")

    def solved(interreflected):
        return solved_per_pixel(subject, sphere.normals, interreflected, reflectance, sphere.light_directions,
                                np.ones(16, np.float32), coarse, 2, np.ones((16, 24, 24), bool))[0][sphere.mask]

    truth = sphere.normals[sphere.mask]
    assert angular_error(solved(offset), truth).mean() < 0.3      # the offset is taken off unit vectors
    assert angular_error(solved(np.zeros_like(offset)), truth).mean() > 3
    assert "each pixel's normal solved from its own images" in caplog.text


def test_a_pixel_the_solve_leaves_out_keeps_the_upsampled_fit_exactly():
    """No usable value anywhere: every pixel keeps its start, bit for bit, interreflection
    offset or not (taking the offset off a start it was added to does not give the start back)."""
    sphere = render_lambertian("sphere", size=16, n_lights=8, seed=2)
    offset = np.broadcast_to(np.array([0.2, -0.1, 0.0], np.float32), sphere.normals.shape)
    _, coarse = block_mean(np.zeros((16, 16, 1)), sphere.mask, 2)
    kept, _ = solved_per_pixel(sphere, sphere.normals, offset, np.ones((8, *coarse.shape, 3), np.float32),
                               sphere.light_directions, np.ones(8, np.float32), coarse, 2,
                               np.zeros((8, 16, 16), bool))
    np.testing.assert_array_equal(kept[sphere.mask], sphere.normals[sphere.mask])


@pytest.mark.parametrize("sigma, solved", [(0.0, True), (0.3, False)])
def test_the_images_noise_decides_whether_each_pixel_is_solved(caplog, sigma, solved):
    """A sphere's normals 6° off: clean images put each pixel right; images with noise of 0.3 of
    their white level are read as that noisy (as a share of the noisy images' 99th percentile),
    and the fit's normals are kept, with a warning."""
    sphere = render_lambertian("sphere", size=32, n_lights=24, seed=4)
    rng = np.random.default_rng(0)
    images = sphere.images + rng.normal(0, sigma * np.percentile(sphere.images[:, sphere.mask], 99),
                                        sphere.images.shape).astype(np.float32) * sphere.mask[None, ..., None]
    subject = sphere.replace(images=images.astype(np.float32), light_intensities=None)
    tilt = np.array([np.sin(np.radians(6)), 0, np.cos(np.radians(6))])
    start = np.where(sphere.mask[..., None], unit(sphere.normals + tilt - [0, 0, 1]), sphere.normals)
    _, coarse = block_mean(np.zeros((32, 32, 1)), sphere.mask, 2)
    caplog.set_level("INFO")
    normals, noise = solved_per_pixel(subject, start.astype(np.float32), np.zeros_like(start),
                                      np.full((24, *coarse.shape, 3), 0.8, np.float32),   # its albedo
                                      sphere.light_directions, np.ones(24, np.float32), coarse, 2,
                                      np.ones((24, 32, 32), bool))
    error = angular_error(normals, sphere.normals)[sphere.mask].mean()
    if solved:
        assert noise < 0.05 and error < 0.5
    else:
        added = sigma * np.percentile(sphere.images[:, sphere.mask], 99)    # in image units
        assert noise * np.percentile(images[:, sphere.mask], 99) == pytest.approx(added, rel=0.2)
        assert noise > NOISE_LIMIT
        np.testing.assert_array_equal(normals, start.astype(np.float32))
        assert "hold more noise than detail" in caplog.text


@pytest.mark.parametrize("tilt, warned", [(5.0, False), (30.0, True)])
def test_a_fit_that_ends_far_from_its_start_says_so(caplog, tilt, warned):
    mask = np.ones((4, 5), bool)
    mask[0, 0] = False
    start = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (4, 5, 3))
    angle = np.radians(tilt)
    fitted = np.broadcast_to(np.array([np.sin(angle), 0.0, np.cos(angle)]), (4, 5, 3)).copy()
    fitted[0, 0] = [1.0, 0.0, 0.0]                       # off the mask: not counted
    caplog.set_level("WARNING")
    assert distance_from_start(fitted, start, mask, "least_squares") == pytest.approx(tilt)
    said = [r.getMessage() for r in caplog.records if "from its start" in r.getMessage()]
    assert said == ([f"the fit ended {tilt:.1f}° on average from its start, the least squares "
                     f"initialisation (more than {FAR_FROM_START_DEG:.0f}°): where the images hardly "
                     f"pin the normals (dark or glossy materials, wrong lights) it can drift; compare "
                     f"with method=rpca, or try preset.residual=relative"] if warned else [])


def test_clipped_values_are_left_out_of_the_loss():
    """A value marked unusable is no target: the loss barely moves however wrong it is (it still
    reaches the reflectance network as an input); marking none is the same loss as no marks."""
    system, subject = sphere_system(prior_weight=0.0)
    usable = torch.ones(12, 1, *subject.mask.shape)
    usable[:, :, 8:14, 8:14] = 0
    marked, _ = sphere_system(prior_weight=0.0)
    marked.load_state_dict(system.state_dict())
    marked.usable = usable
    all_marked, _ = sphere_system(prior_weight=0.0)
    all_marked.load_state_dict(system.state_dict())
    all_marked.usable = torch.ones_like(usable)

    def loss(s):
        torch.manual_seed(3)
        with torch.no_grad():               # step 0 logs nothing (figures_read), so needs no trainer
            return s.training_step(None, 0).item()

    assert loss(all_marked) == loss(system)
    before = loss(marked)
    marked.images[:, :, 8:14, 8:14] = 50.0          # what a clipped highlight can no longer tell
    assert abs(loss(marked) - before) < 0.01 * before
    system.images[:, :, 8:14, 8:14] = 50.0
    assert loss(system) > 2 * before


def test_clipped_values_are_found_on_the_working_grid():
    subject = render_lambertian("sphere", size=24, n_lights=12, seed=1)
    top = np.percentile(subject.images[:, subject.mask], 95)
    clipped = subject.replace(images=np.minimum(subject.images, top))
    cropped, plain = clipped.crop_to_mask(4), subject.crop_to_mask(4)
    usable = unclipped(clipped_values(cropped.observed_images(), cropped.mask), cropped.mask, 2)
    assert usable is not None and 0 < (usable == 0).mean() < 0.5
    assert unclipped(clipped_values(plain.observed_images(), plain.mask), plain.mask, 1) is None


def test_a_values_headroom_is_its_blocks_share_of_zeros_times_the_ceiling_over_the_intensity():
    """A pixel read as 0 in most of its images (a dark material) gets none."""
    observed = np.full((2, 4, 4, 3), 0.2, np.float32)
    observed[0, 0, 0] = 0                  # one pixel of the first image's top-left block, every channel
    observed[0, 1, 1, 0] = 0               # another of that block, red only
    observed[1, 3, 3] = 0                  # off the mask: no reading at all
    observed[:, 2, 0] = 0                  # read as 0 in every image: a dark material, left as read
    mask = np.ones((4, 4), bool)
    mask[3, 3] = False
    intensities = np.array([[1, 2, 4], [1, 1, 1]], np.float32)
    headroom = black_headroom(observed, mask, 2, 0.01, intensities)
    assert headroom.shape == (2, 2, 2, 3)
    np.testing.assert_allclose(headroom[0, 0, 0], [0.5 * 0.01, 0.25 * 0.01 / 2, 0.25 * 0.01 / 4])
    headroom[0, 0, 0] = 0
    assert not headroom.any()
    at_full_size = black_headroom(observed, mask, 1, 0.01, None)
    np.testing.assert_allclose(at_full_size[0, 1, 1], [0.01, 0, 0])
    assert at_full_size.sum() == pytest.approx(0.01 * 4)
    assert black_headroom(observed + 0.1, mask, 2, 0.01, intensities) is None


def test_values_read_as_zero_cost_only_what_the_rendering_puts_above_their_headroom():
    """A headroom of 0 is the plain L1 loss, bit for bit; one wider than any rendering takes the
    values read as 0 out of what the loss charges, whatever is rendered there."""
    torch.manual_seed(0)
    system, subject = sphere_system(prior_weight=0.0)
    system.images[:, :, 8:14, 8:14] = 0.0

    def loss(headroom):
        system.headroom = headroom
        torch.manual_seed(3)
        with torch.no_grad():               # step 0 logs nothing (figures_read), so needs no trainer
            return system.training_step(None, 0).item()

    plain = loss(None)
    assert loss(torch.zeros_like(system.images)) == plain
    wide = torch.zeros_like(system.images)
    wide[:, :, 8:14, 8:14] = 50.0
    censored = loss(wide)
    assert censored < plain
    with torch.no_grad():
        system.reflectance_net.out.bias += 2.0      # renders brighter everywhere, the zeros included
    assert loss(None) - loss(wide) > 2 * (plain - censored)


@pytest.mark.slow
def test_a_dark_8bit_capture_is_not_fitted_steeper_than_it_is_when_zeros_are_censored():
    """A sphere exposed to six 8-bit levels (floor, as DiLiGenT's crops): read as no light at
    all, the zeros of its grazing lights pull the normals away from those lights (5° too steep);
    read as light below the first level, they do not. The fit's own normals: each pixel's solve
    in the read-out (``refine_pixels``) leaves values far below the rendering out and would hide
    part of the difference."""
    sphere = render_lambertian("sphere", size=24, n_lights=24, textured=True, seed=3)
    levels = np.floor(sphere.images / np.percentile(sphere.images[:, sphere.mask], 99) * 6)
    dark = sphere.replace(images=(np.where(levels > 0, levels + 0.5, 0) / 255).astype(np.float32))
    fitted = {}
    for censor in (False, True):
        torch.manual_seed(0)
        preset = Preset.from_config(**{**TINY, "steps": 200, "lr_drop_at": 180, "update_every": 50,
                                       "pixel_keep": 1.0, "censor_black": censor,
                                       "refine_pixels": False})
        normals = neural_inverse_rendering(dark, sphere.light_directions, preset,
                                           InterreflectionModel(enabled=False)).normals
        fitted[censor] = (angular_error(normals, sphere.normals)[sphere.mask].mean(),
                          slant_bias(normals, sphere.normals, sphere.mask))
    assert fitted[False][1] > 3 and fitted[False][0] > 4, fitted
    assert abs(fitted[True][1]) < 2 and fitted[True][0] < 0.5 * fitted[False][0], fitted


def scalars(run) -> dict[str, list[tuple[int, float]]]:
    """Every scalar a fit wrote to TensorBoard: tag → [(step, value)]."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(run / "tensorboard")).Reload()
    return {tag: [(e.step, e.value) for e in events.Scalars(tag)] for tag in events.Tags()["scalars"]}


def test_logging_only_the_steps_whose_figures_are_read_writes_what_logging_every_step_did(
        tmp_path, monkeypatch, caplog):
    """update_every=15 is no multiple of the logger's 10 steps: the progress lines at 15 and 30
    and the last step's must carry their own step's figures too."""
    overrides = [*tiny_overrides(steps=33, every=15), "light=refine", "preset.prior_steps=12"]
    with caplog.at_level(logging.INFO, logger="unps.inverse.fit"):
        fit(config(tmp_path / "read", *overrides))
    lines_read = [r.getMessage().split(" (")[0] for r in caplog.records if r.getMessage().startswith("step ")]
    caplog.clear()
    monkeypatch.setattr(InverseRendering, "figures_read", lambda self: True)
    with caplog.at_level(logging.INFO, logger="unps.inverse.fit"):
        fit(config(tmp_path / "every", *overrides))
    lines_every = [r.getMessage().split(" (")[0] for r in caplog.records if r.getMessage().startswith("step ")]
    read, every = scalars(tmp_path / "read"), scalars(tmp_path / "every")
    for tag in ("loss/reconstruction", "mae", "light/offset_deg"):
        assert read[tag] == every[tag], tag
        assert [step for step, _ in every[tag]] == [9, 19, 29]
    # the prior pulls for 12 steps, so step 9 is its one figure written; later writes repeat
    # whichever figure Lightning last saw (step 9's here, step 11's when every step logs)
    assert read["loss/prior"][0] == every["loss/prior"][0] and read["loss/prior"][0][0] == 9
    assert lines_read == lines_every and [line.split(":")[0] for line in lines_every] == [
        "step 15/33", "step 30/33", "step 33/33"]
    assert all("normal error" in line for line in lines_every)


def test_a_slow_fit_logs_a_progress_line_at_least_once_a_minute(monkeypatch, caplog):
    """7 s a step: beside the line every 100 steps, one on the first step whose figures are fresh
    (every 10) once 60 s have passed since the last line; a fast fit gets the 100-step lines only."""
    from types import SimpleNamespace

    import unps.inverse.callbacks as callbacks

    def lines_at(seconds_per_step: float) -> list[int]:
        now = [0.0]
        monkeypatch.setattr(callbacks, "time", SimpleNamespace(perf_counter=lambda: now[0]))
        progress = callbacks.ProgressLog(every=100, at_least_every_s=60.0, fresh_every=10)
        trainer = SimpleNamespace(global_step=0, max_steps=200, callback_metrics={"loss/reconstruction": 0.5})
        progress.on_train_start(trainer, None)
        caplog.clear()
        with caplog.at_level(logging.INFO, logger="unps.inverse.fit"):
            for step in range(1, 201):
                trainer.global_step, now[0] = step, step * seconds_per_step
                progress.on_train_batch_end(trainer, None, None, None, step - 1)
        return [int(re.match(r"step (\d+)/200", r.getMessage()).group(1)) for r in caplog.records]

    assert lines_at(7.0) == [10, 20, 30, 40, 50, 60, 70, 80, 90, 100, 110, 120, 130, 140, 150, 160, 170,
                             180, 190, 200]
    assert lines_at(2.5) == [30, 60, 90, 100, 130, 160, 190, 200]
    assert lines_at(0.1) == [100, 200]


def test_a_fit_that_stops_moving_says_so_and_a_healthy_one_does_not(tmp_path):
    healthy = fit(config(tmp_path / "healthy", *tiny_overrides(steps=40), "light=gt"))
    assert not any("stopped moving" in w for w in healthy["warnings"])
    dead = fit(config(tmp_path / "dead", *tiny_overrides(steps=40), "light=gt", "preset.lr=1e-30"))
    stalled = [w for w in dead["warnings"] if "stopped moving" in w]
    assert len(stalled) == 1 and "at step 20 of 40" in stalled[0], dead["warnings"]


@pytest.mark.parametrize("preset", [TINY, dict(TINY, name="paper-like", width=384, depth=4, first_kernel=3,
                                                reflectance_width=16)])
def test_a_dark_capture_fits_as_the_bright_one_does(sphere, preset):
    """Images scaled by 0.05 (a dark capture) fit as well as the bright ones: the fit works on
    images scaled to their 99th percentile, whatever the exposure. (The two fits differ only
    in float rounding, which a short fit can amplify to ~0.7° between their normals; their
    errors against the truth are what a user sees.)"""
    errors = []
    for brightness in (1.0, 0.05):
        torch.manual_seed(0)
        dark = sphere.replace(images=sphere.images * brightness)
        normals = neural_inverse_rendering(dark, sphere.light_directions, Preset.from_config(**preset),
                                           InterreflectionModel(**NAYAR)).normals
        errors.append(angular_error(normals, sphere.normals)[sphere.mask].mean())
    assert abs(errors[1] - errors[0]) < 0.5, errors


def test_visibility_hides_part_of_a_bowls_lit_side_from_a_low_light_and_none_of_a_domes():
    low = torch.tensor([[0.9, 0.0, 0.43589]])                        # 64° from the view, from +x
    for concave, least, most in ((True, 0.05, 1.0), (False, 0.0, 0.01)):
        subject = rendered(concave=concave)
        hidden = visibility(subject.normals, subject.mask, low)[0, 0].numpy() == 0
        assert hidden.shape == subject.mask.shape
        lit = subject.mask & (subject.normals @ low[0].numpy() > 0.05)   # facing the light
        share = (hidden & lit).sum() / lit.sum()
        assert least <= share <= most, (subject.name, share)
        if concave:                         # the rim nearer the light shades the +x side
            assert np.nonzero(hidden & lit)[1].mean() > subject.mask.shape[1] / 2

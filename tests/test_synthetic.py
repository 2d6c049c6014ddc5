import json
import logging
import subprocess
import sys

import numpy as np
import pytest
from hydra import compose, initialize_config_module
from hydra.utils import instantiate

import unps.synthetic.scenes as scenes
from unps.data.catalogue import subjects
from unps.data.analytic import render_lambertian
from unps.data.prepare import add_noise
from unps.errors import InputError
from unps.fit import fit
from unps.synthetic import shapes, vessels
from unps.synthetic.render import light_dome, render_subject

SUBJECTS = list(subjects("synthetic"))
TINY = ["subject.render.resolution=24", "subject.render.spp=4", "subject.lights.count=3"]


def subject_config(name, cache, *overrides, config="fit"):
    with initialize_config_module(config_module="unps.conf", version_base="1.3"):
        return compose(config, overrides=[f"subject={name}", f"paths.cache_dir={cache}",
                                          "paths.output_dir=unused", *TINY, *overrides])


def load(name, cache, *overrides):
    return instantiate(subject_config(name, cache, *overrides).subject, _partial_=True)(progress=False)


@pytest.mark.parametrize("builder", [shapes.sphere, shapes.golf_ball, shapes.face, shapes.tablet,
                                     shapes.broken_pot, shapes.rose, vessels.vase, vessels.goblet,
                                     vessels.bowl])
def test_shapes_are_deterministic_and_fit_the_view(builder):
    a, b = builder(), builder()
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.faces, b.faces)
    assert np.abs(a.vertices[:, :2]).max() <= 0.95
    assert a.faces.max() < len(a.vertices)


def lambert(subject, albedo):
    return albedo * np.maximum(np.einsum("hwc,nc->nhw", subject.normals, subject.light_directions), 0)


def test_diffuse_sphere_without_interreflection_is_lambertian():
    d, e = light_dome(6, 60, (0.5, 1.5), 0.05, seed=1)
    s = render_subject("sphere", shapes.sphere(), {"type": "diffuse", "reflectance": [0.6] * 3},
                       None, d, e, resolution=32, spp=36, max_depth=2, progress=False)
    error = np.abs(s.images[..., 1] - lambert(s, 0.6))[:, s.mask]
    assert error.mean() < 0.005 and error.max() < 0.03
    np.testing.assert_allclose(np.linalg.norm(s.normals[s.mask], axis=-1), 1, atol=1e-5)
    assert np.isnan(s.depth[~s.mask]).all() and np.isfinite(s.depth[s.mask]).all()


def test_interreflection_brightens_a_concavity_but_not_a_sphere():
    d, e = np.array([[0, 0, 1.0]], np.float32), np.ones((1, 3), np.float32)
    white = {"type": "diffuse", "reflectance": [0.9] * 3}

    def mean_brightness(mesh, depth):
        s = render_subject("s", mesh, white, None, d, e, resolution=32, spp=36, max_depth=depth,
                           progress=False)
        return s.images[0][s.mask].mean()

    pot = shapes.broken_pot(resolution=96)
    assert mean_brightness(pot, 5) > 1.15 * mean_brightness(pot, 2)
    ball = shapes.sphere(subdivisions=3)
    assert mean_brightness(ball, 5) == pytest.approx(mean_brightness(ball, 2), rel=1e-3)


@pytest.mark.parametrize("name", SUBJECTS)
def test_every_subject_renders_and_reads_back(tmp_path, name):
    s = load(name, tmp_path)
    assert s.name == name and s.n_images == 3 and s.resolution == (24, 24)
    assert s.mask.sum() > 20
    np.testing.assert_allclose(np.linalg.norm(s.normals[s.mask], axis=-1), 1, atol=1e-4)
    assert (s.normals[s.mask][:, 2] >= 0).all()                # the side the camera sees
    d, e = light_dome(3, 60, (0.5, 1.5), 0.05, seed=0)
    np.testing.assert_allclose(s.light_directions, d, atol=1e-6)
    ratio = s.light_intensities / e            # one global scale, if the writer had to rescale
    np.testing.assert_allclose(ratio, ratio[0, 0], rtol=1e-5)


def test_cache_is_reused_changed_settings_render_anew(tmp_path, monkeypatch):
    first = load("Sphere", tmp_path)
    monkeypatch.setattr(scenes, "render_subject", lambda *a, **k: pytest.fail("re-rendered"))
    again = load("Sphere", tmp_path)
    np.testing.assert_array_equal(first.images, again.images)
    monkeypatch.undo()
    load("Sphere", tmp_path, "subject.lights.seed=5")
    assert len(list(tmp_path.iterdir())) == 2


@pytest.mark.parametrize("damage", [
    lambda e: (e / "002.png").write_bytes((e / "002.png").read_bytes()[:100]),   # truncated
    lambda e: (e / "light_directions.txt").unlink(),                             # partial
    lambda e: (e / "unps_subject.json").write_text("{"),                         # corrupt
])
def test_a_damaged_cache_entry_is_rendered_again(tmp_path, caplog, damage):
    first = load("Sphere", tmp_path)
    (entry,) = tmp_path.iterdir()
    damage(entry)
    with caplog.at_level(logging.WARNING):
        again = load("Sphere", tmp_path)
    assert "incomplete or corrupt" in caplog.text
    np.testing.assert_array_equal(first.images, again.images)


@pytest.mark.parametrize("override, message", [
    ("subject.lights.count=0", "lights.count must be at least 1"),
    ("subject.lights.max_zenith_deg=95", "so every light is above the horizon"),
    ("subject.render.resolution=0", "render needs resolution >= 4"),
    ("subject.render.variant=cuda_nope", "Mitsuba variant 'cuda_nope' is not available"),
])
def test_impossible_settings_are_refused(tmp_path, override, message):
    with pytest.raises(InputError, match=message):
        load("Sphere", tmp_path, override)
    assert not list(tmp_path.iterdir())


def test_noise_is_relative_to_the_99th_percentile_and_seeded():
    s = render_lambertian(size=32, n_lights=16, seed=0)
    noisy, reference = add_noise(s, 0.1, seed=3)
    assert reference == pytest.approx(np.percentile(s.observed_images()[:, s.mask], 99))
    added = noisy.observed_images() - s.observed_images()
    assert added.std() == pytest.approx(0.1 * reference, rel=0.02)
    assert abs(added.mean()) < 0.01 * reference
    np.testing.assert_array_equal(add_noise(s, 0.1, seed=3)[0].images, noisy.images)
    assert (noisy.images < 0).any()                           # nothing clipped
    assert add_noise(s, 0.0, seed=3)[0] is s
    with pytest.raises(InputError, match="noise must be a standard deviation >= 0"):
        add_noise(s, -0.1, seed=0)


def test_fit_on_a_synthetic_subject_with_noise(tmp_path):
    cfg = subject_config("Vase", tmp_path / "cache", "method=woodham", "light=estimated", "noise=0.05")
    cfg.paths.output_dir = str(tmp_path / "run")
    metrics = fit(cfg)
    saved = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert saved["noise"] == 0.05 and saved["noise_reference"] > 0
    assert np.isfinite(metrics["normal_mae"]) and saved["subject"] == "Vase"


def run(module, *args, cwd):
    return subprocess.run([sys.executable, "-m", module, *args], cwd=cwd, capture_output=True,
                          text=True, timeout=300)


@pytest.mark.slow
def test_render_cli_and_unknown_subjects(tmp_path):
    done = run("unps.render", "subject=Golf-ball", *TINY, f"paths.cache_dir={tmp_path / 'c'}",
               f"hydra.run.dir={tmp_path / 'run'}", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "run" / "preview.png").is_file()
    assert len(list((tmp_path / "c").glob("Golf-ball-*/001.png"))) == 1

    unknown = run("unps.fit", "subject=Teapot", cwd=tmp_path)
    assert unknown.returncode != 0
    assert "Could not find 'subject/Teapot'" in unknown.stderr and "Golf-ball" in unknown.stderr

    real = run("unps.render", "subject=lambertian", f"hydra.run.dir={tmp_path / 'r2'}", cwd=tmp_path)
    assert real.returncode == 2 and "renders synthetic subjects only" in real.stdout + real.stderr


def test_ground_truth_drops_pixels_whose_normals_are_not_finite(monkeypatch):
    from pathlib import Path

    import mitsuba as mi

    import unps.synthetic.render as render

    truth = np.zeros((4, 4, 9), np.float32)
    truth[..., 0] = 1                                   # fully covered
    truth[..., 5] = 1                                   # n = +z
    truth[..., 8] = 3.0                                 # z = 3 (view units)
    truth[1, 2, 3:6] = np.nan                           # what a degenerate mesh face can give
    render.set_variant("scalar_rgb")
    monkeypatch.setattr(render, "_scene", lambda *args, **kwargs: None)
    monkeypatch.setattr(mi, "render", lambda *args, **kwargs: truth)
    normals, depth, mask = render._ground_truth(Path("unused.ply"), 4, seed=0)
    assert not mask[1, 2] and mask.sum() == 15
    assert np.isfinite(normals).all() and np.isnan(depth[1, 2]) and depth[0, 0] == pytest.approx(6.0)

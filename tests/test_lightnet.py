import logging
import math

import numpy as np
import pytest
import torch
from torch.utils.flop_counter import FlopCounterMode
from hydra import compose, initialize_config_module

from conftest import SHARED_DATA, load_script
from unps.errors import InputError
from unps.lightnet import bins
from unps.lightnet.brdf import (AnalyticBRDF, MERL_SHAPE, ggx_lobe, half_diff_angles,
                                read_merl_binary, read_neural_brdf)
from unps.lightnet.estimate import network_input, network_lights
from unps.lightnet.network import LATE_STRIDES, LCNET_STRIDES, LightNet
from unps.lightnet.outline import DIMMED_DOWN_TO, jittered_outlines, outline_rings
from unps.lightnet.shapes import cast_shadows, maps_from_depth
from unps.lightnet.synthesis import LightDataset
from unps.lightnet.system import load_lightnet
from unps.train import train


def unit(v):
    return torch.nn.functional.normalize(torch.as_tensor(v, dtype=torch.float32), dim=-1)


# bins -------------------------------------------------------------------------------------

def test_angles_round_trip():
    d = unit(torch.randn(200, 3).abs() * torch.tensor([1, 1, 1.0]) * torch.tensor([[1, 1, 1]]))
    d[:, :2] *= torch.sign(torch.randn(200, 2))
    np.testing.assert_allclose(bins.angles_to_direction(*bins.direction_to_angles(d)), d, atol=1e-6)


def test_bin_encode_decode_round_trip_within_half_a_bin():
    g = torch.Generator().manual_seed(0)
    d = unit(torch.randn(500, 3, generator=g).abs() * torch.tensor([1, 1, 2.0]))
    d[:, :2] *= torch.sign(torch.randn(500, 2, generator=g))
    e = 0.3 + 1.6 * torch.rand(500, generator=g)
    e = e / e.mean()
    az_bin, el_bin, e_bin = bins.encode_lights(d, e)
    one_hot = lambda index, count: torch.nn.functional.one_hot(index, count).float() * 50  # noqa: E731
    directions, intensities = bins.decode_lights(one_hot(az_bin, 36), one_hot(el_bin, 36),
                                                 one_hot(e_bin, 20), soft=False)
    az, el = bins.direction_to_angles(d)
    az2, el2 = bins.direction_to_angles(directions)
    half = math.radians(2.5) + 1e-6
    assert (az - az2).abs().max() <= half and (el - el2).abs().max() <= half
    inside = (e >= 0.2) & (e <= 2.0)
    assert (intensities - e)[inside].abs().max() <= 0.045 + 1e-6


def test_soft_decoding_interpolates_between_bins():
    logits = torch.full((36,), -1e4)
    logits[[17, 18]] = 0.0                      # equal mass on the two bins around 0°
    assert bins.decode(logits, *bins.ANGLE_RANGE, soft=True).item() == pytest.approx(0, abs=1e-6)
    assert bins.decode(logits, *bins.ANGLE_RANGE, soft=False).item() == pytest.approx(math.radians(-2.5), abs=1e-6)


# BRDFs ------------------------------------------------------------------------------------

def test_half_diff_angles_known_values():
    t = math.radians(30)
    wi, wo = unit([math.sin(t), 0, math.cos(t)]), unit([-math.sin(t), 0, math.cos(t)])
    th, td, pd = half_diff_angles(wi, wo)
    assert th.item() == pytest.approx(0, abs=1e-3) and td.item() == pytest.approx(t, abs=1e-5)
    assert pd.item() == pytest.approx(0, abs=1e-5)


def test_analytic_brdf_is_lambertian_without_a_lobe():
    f = AnalyticBRDF([0.5, 0.25, 0.1], [0, 0, 0], 0.3)
    value = f(unit([0.3, 0.1, 0.9]), unit([0, 0, 1.0]))
    np.testing.assert_allclose(value, np.array([0.5, 0.25, 0.1]) / math.pi, rtol=1e-6)


def test_two_lobes_add_and_a_metal_has_no_fresnel_rise():
    wi, wo = unit([[0.3, 0.1, 0.9], [0.95, 0.0, 0.1]]), unit([[0, 0, 1.0], [-0.2, 0, 0.98]])
    both = AnalyticBRDF([0.2] * 3, [[1.0] * 3, [0.5, 0.4, 0.3]], (0.05, 0.4), (0.04, 0.9))
    sharp = AnalyticBRDF([0.2] * 3, [1.0] * 3, 0.05, 0.04)
    broad = AnalyticBRDF([0.0] * 3, [0.5, 0.4, 0.3], 0.4, 0.9)
    torch.testing.assert_close(both(wi, wo), sharp(wi, wo) + broad(wi, wo))
    def metal_over_coat(wi, wo):
        return float(ggx_lobe(wi, wo, 0.3, 1.0) / ggx_lobe(wi, wo, 0.3, 0.04))

    head_on = unit([[0, 0, 1.0]])
    assert metal_over_coat(head_on, head_on) == pytest.approx(1 / 0.04, rel=1e-4)
    assert metal_over_coat(unit([[0.99, 0, 0.05]]), unit([[-0.99, 0, 0.05]])) < 2   # the coat's rise
    with pytest.raises(ValueError, match="roughness: 3 values for 2 lobes"):
        AnalyticBRDF([0.2] * 3, [[1.0] * 3] * 2, (0.1, 0.2, 0.3))


def test_measured_span_materials_lie_in_the_fitted_ranges():
    from unps.lightnet.brdf import MEASURED_RANGES, random_measured

    g = torch.Generator().manual_seed(0)
    for _ in range(200):
        brdf = random_measured(g)
        (a1, a2), f0 = brdf.roughness, torch.tensor(brdf.fresnel0)
        assert MEASURED_RANGES["alpha1"][0] <= a1 <= a2 <= MEASURED_RANGES["alpha2"][1]
        assert ((f0 >= MEASURED_RANGES["fresnel0"][0]) & (f0 <= MEASURED_RANGES["fresnel0"][1])).all()
        low, high = MEASURED_RANGES["log10_specular_over_diffuse"]
        ratio = math.log10(float(brdf.specular.sum(0).mean() / brdf.diffuse.mean()))
        assert low + math.log10(0.5) - 1e-3 <= ratio <= high + 1e-3     # lobe tints 0.5…1
        value = brdf(unit([[0.2, 0.1, 0.97]]), unit([[0, 0, 1.0]]))
        assert torch.isfinite(value).all() and (value > 0).all()


def test_lobe_fitting_recovers_a_known_two_lobe_material():
    lobes = load_script("merl_lobes", "experiments/light_estimation/merl_lobes.py")
    wi, wo = lobes.direction_pairs(4096)
    truth = AnalyticBRDF([0.3, 0.2, 0.1], [[0.4] * 3, [1.5, 1.2, 1.0]], (0.04, 0.3), (0.05, 0.2))
    with torch.no_grad():
        target = truth(wi, wo)
    fit = lobes.fit_lobes(target, wi, wo, iterations=400)
    assert fit["rms_log"] < 0.05
    np.testing.assert_allclose(fit["alpha"], [0.04, 0.3], rtol=0.25)


def write_merl(path, table):
    with open(path, "wb") as f:
        f.write(np.array(MERL_SHAPE, "<i4").tobytes())
        f.write(table.astype("<f8").tobytes())


def test_merl_binary_reader_known_values_at_known_angles(tmp_path):
    th, td, pd = np.meshgrid(np.arange(90), np.arange(90), np.arange(180), indexing="ij")
    code = (th * 1_000_000 + td * 1_000 + pd).astype(np.float64)
    table = np.stack([code, 2 * code, -np.ones_like(code)])      # blue "unmeasured"
    write_merl(tmp_path / "m.binary", table)
    brdf = read_merl_binary(tmp_path / "m.binary")
    t = math.radians(31.5)                                        # θ_h = 0, θ_d = 31.5°, φ_d = 0
    wi, wo = unit([math.sin(t), 0, math.cos(t)]), unit([-math.sin(t), 0, math.cos(t)])
    rgb = brdf(wi, wo).numpy()
    expected = 31 * 1_000                                         # θ_d bin 31 (31°–32°)
    np.testing.assert_allclose(rgb, [expected / 1500, 2 * expected * 1.15 / 1500, 0], rtol=1e-6)


def test_merl_reader_rejects_other_files(tmp_path):
    (tmp_path / "bad.binary").write_bytes(np.array([1, 2, 3], "<i4").tobytes())
    with pytest.raises(InputError, match="bad.binary: not a MERL BRDF"):
        read_merl_binary(tmp_path / "bad.binary")
    with pytest.raises(InputError, match="not found"):
        read_merl_binary(tmp_path / "none.binary")


def test_neural_brdf_reader_matches_a_plain_evaluation_of_the_weights():
    path = SHARED_DATA / "merl_nbrdf" / "alum-bronze.h5"
    if not path.is_file():
        pytest.skip(f"development data not found at {path}")
    import h5py

    brdf = read_neural_brdf(path)
    wi, wo = unit([[0.3, 0.2, 0.9], [-0.5, 0.1, 0.7]]), unit([[0, 0, 1.0], [0.1, 0, 1]])
    th, td, pd = (a.numpy().astype(np.float64) for a in half_diff_angles(wi, wo))
    x = np.stack([np.sin(th), 0 * th, np.cos(th), np.sin(td) * np.cos(pd), np.sin(td) * np.sin(pd),
                  np.cos(td)], -1)
    with h5py.File(path) as f:
        for k in (1, 2, 3):
            x = x @ f[f"dense_{k}/dense_{k}/kernel:0"][()] + f[f"dense_{k}/dense_{k}/bias:0"][()]
            x = np.maximum(x, 0) if k < 3 else np.expm1(x)
    np.testing.assert_allclose(brdf(wi, wo).numpy(), np.maximum(x, 0), rtol=1e-4, atol=1e-6)


# data -------------------------------------------------------------------------------------

def test_dataset_items_are_a_function_of_seed_and_index():
    ds = LightDataset(10, resolution=32, images=4, seed=3)
    a, b, c = ds[5], ds[5], ds[6]
    for key in ("images", "directions", "intensities", "mask"):
        torch.testing.assert_close(a[key], b[key])
    assert not torch.equal(a["images"], c["images"])
    torch.testing.assert_close(LightDataset(10, resolution=32, images=4, seed=3, offset=5)[1]["images"],
                               c["images"])
    assert a["images"].shape == (4, 3, 32, 32) and (a["directions"][:, 2] > 0).all()
    assert ((a["intensities"] >= 0.2) & (a["intensities"] <= 2)).all()


def test_a_pillar_shadows_the_side_away_from_the_light():
    z = torch.zeros(33, 33)
    z[14:19, 14:19] = 0.5                                        # a tall block in the middle
    maps = maps_from_depth(z, torch.ones(33, 33, dtype=torch.bool))
    shadow = cast_shadows(maps, unit([[0.8, 0, 0.6]]))[0]       # light from +x (the right)
    assert shadow[16, 5:13].all() and not shadow[16, 20:].any()
    assert not cast_shadows(maps, unit([[0, 0, 1.0]])).any()


def test_bad_dataset_settings():
    with pytest.raises(InputError, match="multiple of 32"):
        LightDataset(4, resolution=40)
    with pytest.raises(InputError, match="images per sample must lie in 1…64"):
        LightDataset(4, resolution=32, images=65)
    with pytest.raises(InputError, match="paint is a share of the samples, in 0…1; got 1.5"):
        LightDataset(4, resolution=32, paint=1.5)
    with pytest.raises(InputError, match="second_material is a share of the samples, in 0…1; got -0.5"):
        LightDataset(4, resolution=32, second_material=-0.5)


# training, checkpoints, estimation --------------------------------------------------------

TINY = ["light.width=8", "light.head_width=16", "recipe.resolution=32", "recipe.images=4",
        "recipe.batch_size=2", "recipe.val_samples=2", "recipe.val_every=2", "recipe.workers=0",
        "recipe.log_every=1", "recipe.lr_milestones=[1]", "recipe.max_time=null"]


def train_config(out, *overrides):
    with initialize_config_module(config_module="unps.conf", version_base="1.3"):
        return compose("train", overrides=[f"paths.output_dir={out}", *TINY, *overrides])


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    out = tmp_path_factory.mktemp("train")
    metrics = train(train_config(out, "recipe.max_steps=2"))
    return out, metrics


def test_two_step_training_writes_checkpoints_and_metrics(trained):
    out, metrics = trained
    assert metrics["steps"] == 2 and np.isfinite(metrics["val/direction_mae"])
    assert (out / "checkpoints" / "last.ckpt").is_file() and (out / "metrics.json").is_file()
    assert list((out / "tensorboard").glob("events.out.tfevents.*"))


def test_training_logs_a_progress_line_per_validation_with_its_figures(tmp_path, caplog):
    caplog.set_level(logging.INFO)
    metrics = train(train_config(tmp_path, "recipe.max_steps=4"))       # validations after steps 2 and 4
    assert metrics["train_samples_per_s"] > 0     # steps 3 and 4, the validation between them left out
    lines = [r.getMessage() for r in caplog.records]
    assert any(line.startswith("training LightNet on") for line in lines)
    steps = [line for line in lines if line.startswith("step ")]
    assert [line.split(":")[0] for line in steps] == ["step 2/4", "step 4/4"]
    assert f"validation direction error {metrics['val/direction_mae']:.2f}°" in steps[-1]


def test_the_sample_rate_leaves_out_the_first_steps_and_the_validations(monkeypatch):
    from types import SimpleNamespace

    from unps.lightnet import callbacks

    clock = iter([1.0, 3.0, 4.0, 5.0, 11.0, 12.0, 20.0, 21.0])   # seconds, at each call below
    monkeypatch.setattr(callbacks.time, "perf_counter", lambda: next(clock))
    rate, batch = callbacks.SampleRate(skip=2), {"images": torch.zeros(4, 1)}
    trainer, module = SimpleNamespace(max_steps=4, global_step=0), SimpleNamespace(device=torch.device("cpu"))

    def step():
        trainer.global_step += 1
        rate.on_train_batch_end(trainer, module, None, batch, 0)

    for _ in range(2):
        step()                                                       # start-up: 1 s, 3 s
    step()                                                           # 4 s: 1 s, 4 samples
    rate.on_validation_start(trainer, module)                        # 5 s
    rate.on_validation_end(trainer, module)                          # 11 s
    step()                                                           # 12 s: 8 s, 6 of them validation
    rate.on_validation_start(trainer, module)                        # the last validation: not counted
    rate.on_validation_end(trainer, module)
    assert rate.samples_per_s == pytest.approx(8 / (1 + 2))


def test_a_precision_other_than_float32_or_bfloat16_is_refused_by_name(tmp_path):
    with pytest.raises(InputError, match=r"recipe.precision must be one of 32-true, bf16-mixed; got '16-mixed'"):
        train(train_config(tmp_path, "recipe.precision=16-mixed"))
    assert not any(tmp_path.iterdir())                              # nothing written


def test_the_last_checkpoint_follows_every_validation_not_only_the_best(tmp_path):
    train(train_config(tmp_path, "recipe.max_steps=4", "recipe.lr=0"))   # no validation improves
    saved = {name: torch.load(tmp_path / "checkpoints" / name, weights_only=False)["global_step"]
             for name in ("best.ckpt", "last.ckpt")}
    assert saved == {"best.ckpt": 2, "last.ckpt": 4}


def test_a_run_stopped_by_its_time_limit_says_how_to_go_on(tmp_path, caplog):
    caplog.set_level(logging.INFO)
    metrics = train(train_config(tmp_path, "recipe.max_steps=100000", "recipe.max_time=00:00:00:02"))
    assert 0 < metrics["steps"] < 100000
    stop = [r.getMessage() for r in caplog.records if r.getMessage().startswith("stopped at step")]
    assert len(stop) == 1 and "recipe.max_time=00:00:00:02" in stop[0]
    assert f"ckpt_path={tmp_path / 'checkpoints' / 'last.ckpt'} recipe.max_time=<longer>" in stop[0]


def test_checkpoint_restores_the_same_network(trained):
    out, _ = trained
    saved = torch.load(out / "checkpoints" / "last.ckpt", weights_only=False)
    net, config = load_lightnet(out / "checkpoints" / "last.ckpt")
    assert config["light"]["width"] == 8 and isinstance(net, LightNet)
    reference = LightNet(8, 16, tuple(config["light"]["strides"]))
    reference.load_state_dict({k[4:]: v for k, v in saved["state_dict"].items()})
    x, m = torch.rand(1, 5, 3, 32, 32), torch.ones(1, 1, 32, 32)
    for key, value in reference.eval()(x, m).items():
        torch.testing.assert_close(net(x, m)[key], value)


def test_an_interrupted_run_resumes_with_its_own_config(tmp_path, monkeypatch):
    import signal

    from unps.lightnet.system import LightEstimation

    step = LightEstimation.training_step

    def interrupted(self, batch, index):
        if self.global_step == 3:
            raise KeyboardInterrupt
        return step(self, batch, index)

    monkeypatch.setattr(LightEstimation, "training_step", interrupted)
    handler = signal.getsignal(signal.SIGINT)
    with pytest.raises(SystemExit):                       # Lightning's graceful shutdown
        train(train_config(tmp_path / "first", "recipe.max_steps=4"))
    signal.signal(signal.SIGINT, handler)
    monkeypatch.undo()
    last = tmp_path / "first" / "checkpoints" / "last.ckpt"
    assert torch.load(last, weights_only=False)["global_step"] == 2

    resume = ("light.width=8", f"ckpt_path={last}")     # the run's own width: not a change
    metrics = train(train_config(tmp_path / "again", *resume), resume)
    assert metrics["steps"] == 4
    _, config = load_lightnet(tmp_path / "again" / "checkpoints" / "last.ckpt")
    assert config["recipe"]["max_steps"] == 4 and config["light"]["width"] == 8

    longer = (f"ckpt_path={tmp_path / 'again' / 'checkpoints' / 'last.ckpt'}", "recipe.max_steps=6")
    assert train(train_config(tmp_path / "longer", *longer), longer)["steps"] == 6

    other = (f"ckpt_path={last}", "light.width=16", "recipe.lr=0.1")
    with pytest.raises(InputError, match=r"only recipe.max_steps, recipe.max_time and device may change, but "
                                         r"the command line changes light.width \(8 in the run, 16 "
                                         r"asked\), recipe.lr"):
        train(train_config(tmp_path / "other", *other), other)


def test_estimated_lights_in_a_fit(trained, tmp_path):
    from unps.fit import fit

    out, _ = trained
    with initialize_config_module(config_module="unps.conf", version_base="1.3"):
        cfg = compose("fit", overrides=[f"paths.output_dir={tmp_path}", "subject=lambertian",
                                        "subject.size=32", "light=estimated", "method=rpca",
                                        f"light.checkpoint={out / 'checkpoints' / 'last.ckpt'}"])
    metrics = fit(cfg)
    assert metrics["light"] == "estimated"
    assert 0 <= metrics["light_dir_mae"] <= 180 and np.isfinite(metrics["light_int_err"])
    assert np.loadtxt(tmp_path / "lights.txt").shape == (32, 6)


def test_network_input_crops_to_the_object_and_keeps_its_shape():
    images = np.zeros((2, 40, 60, 3), np.float32)
    mask = np.zeros((40, 60), bool)
    mask[10:30, 20:30] = True
    images[:, mask] = 1
    x, m = network_input(images, mask, 32)
    assert x.shape == (1, 2, 3, 32, 32) and m.shape == (1, 1, 32, 32)
    assert 0.4 < m.mean() < 0.6                             # a 20×10 box in its 20×20 square


def test_network_input_frames_the_object_to_the_share_asked():
    images = np.zeros((1, 50, 70, 3), np.float32)
    mask = np.zeros((50, 70), bool)
    mask[5:25, 30:50] = True                                # a 20×20 box, off-centre
    images[:, mask] = 1
    full, m_full = network_input(images, mask, 64)
    half, m_half = network_input(images, mask, 64, fill=0.5)
    # the box's side is 20 of 21 px at fill 1 and 20 of 42 at fill 0.5
    assert m_full.mean() == pytest.approx((20 / 21) ** 2, abs=0.03)
    assert m_half.mean() == pytest.approx((20 / 42) ** 2, abs=0.03)
    rows, cols = torch.nonzero(m_half[0, 0], as_tuple=True)
    assert rows.float().mean() == pytest.approx(31.5, abs=2) and cols.float().mean() == pytest.approx(31.5, abs=2)
    torch.testing.assert_close(half[0, 0, 0], m_half[0, 0], atol=0.5, rtol=0)  # the images framed alike


@pytest.mark.parametrize("framings", [[], [1.0, 1.5], [0.0], [-0.5], "abc", ["x"], None])
def test_network_lights_refuses_framings_outside_the_unit_interval(framings):
    from unps.data.analytic import render_lambertian
    with pytest.raises(InputError, match="light.framings"):
        network_lights(render_lambertian(size=16, n_lights=4), framings=framings)


def test_several_framings_are_averaged_and_report_their_spread(sphere):
    one, _ = network_lights(sphere, symmetric=False, framings=[1.0])
    three, verdict = network_lights(sphere, symmetric=False, framings=[1.0, 0.85, 0.7])
    assert verdict.stage == "network" and verdict.evidence["spread_median_deg"] > 0
    assert one.spread_deg is None
    assert three.spread_deg.shape == (sphere.n_images,) and (three.spread_deg > 0).all()
    np.testing.assert_allclose(np.linalg.norm(three.directions, axis=1), 1, atol=1e-5)
    np.testing.assert_allclose(three.intensities.mean(), 1, atol=1e-5)
    assert not np.allclose(one.directions, three.directions)


def test_light_estimated_configures_what_the_light_stages_do_by_default():
    import dataclasses
    import inspect

    from hydra.utils import get_class

    from unps.pipeline.lights import estimated_lights
    with initialize_config_module(config_module="unps.conf", version_base="1.3"):
        light = compose("fit", overrides=["light=estimated"]).light
    defaults = inspect.signature(estimated_lights).parameters
    for key in ("checkpoint", "soft_decode", "symmetric", "stages"):
        assert light[key] == (list(defaults[key].default) if key == "stages" else defaults[key].default), key
    assert list(light.framings) == list(defaults["framings"].default)
    for stage in ("reversal", "contour", "selfcal"):
        fields = {f.name: f.default for f in dataclasses.fields(get_class(light[stage]._target_))}
        for key, value in light[stage].items():
            if key != "_target_":
                assert value == (list(fields[key]) if isinstance(fields[key], tuple) else fields[key]), \
                    (stage, key)


def test_missing_or_foreign_weights_are_reported(tmp_path):
    with pytest.raises(InputError, match="weights not found"):
        load_lightnet(tmp_path / "none.pt")
    torch.save({"x": 1}, tmp_path / "foreign.pt")
    with pytest.raises(InputError, match="not a unps light-network checkpoint"):
        load_lightnet(tmp_path / "foreign.pt")


def test_mesh_views_give_normal_and_depth_maps(tmp_path):
    import trimesh

    from unps.lightnet.meshes import mesh_views

    trimesh.creation.icosphere(subdivisions=3).export(tmp_path / "ball.ply")
    (tmp_path / "notes.txt").write_text("not a mesh")
    views = mesh_views(tmp_path, resolution=32, views=2, seed=0)
    assert len(views) == 2
    for maps in views:
        assert maps.normals.shape == (32, 32, 3) and maps.mask.sum() > 300
        np.testing.assert_allclose(maps.normals[maps.mask].norm(dim=-1), 1, atol=1e-4)
        assert maps.depth[maps.mask].max() > 0.5                 # a sphere of radius ~0.9
    ds = LightDataset(4, resolution=32, images=3, meshes=views, mesh_fraction=1.0)
    assert ds[0]["mask"].sum() in (views[0].mask.sum(), views[1].mask.sum())
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="no .obj or .ply meshes"):
        mesh_views(tmp_path / "empty", resolution=32, views=1, seed=0)


def test_material_bank_families_and_errors(tmp_path):
    from unps.lightnet.materials import MaterialBank

    with pytest.raises(InputError, match="merl has weight 1 but its folder"):
        MaterialBank(merl_dir=str(tmp_path / "nowhere"), merl=1)
    with pytest.raises(InputError, match="no .binary files"):
        MaterialBank(merl_dir=str(tmp_path), merl=1)
    folder = SHARED_DATA / "merl_nbrdf"
    if not folder.is_dir():
        pytest.skip(f"development data not found at {folder}")
    bank = MaterialBank(analytic=0, neural_dir=str(folder), neural=1)
    family, brdf = bank.draw(torch.Generator().manual_seed(0))
    assert family == "neural"
    value = brdf(unit([[0.2, 0.1, 0.97]]), unit([[0, 0, 1.0]]))
    assert value.shape == (1, 3) and (value > 0).all()


def test_material_bank_never_draws_the_benchmarks_materials(tmp_path):
    from unps.lightnet.materials import HELD_OUT_MERL, MaterialBank

    names = sorted(HELD_OUT_MERL)[:3] + ["kept-a", "kept-b"]
    for name in names:
        (tmp_path / f"{name}.binary").write_bytes(b"")
    bank = MaterialBank(analytic=0, merl_dir=str(tmp_path), merl=1)
    assert [p.stem for p in bank.files["merl"]] == ["kept-a", "kept-b"]
    everything = MaterialBank(analytic=0, merl_dir=str(tmp_path), merl=1, exclude=frozenset())
    assert len(everything.files["merl"]) == 5
    for name in ("kept-a", "kept-b"):
        (tmp_path / f"{name}.binary").unlink()
    with pytest.raises(InputError, match="HELD_OUT_MERL"):
        MaterialBank(analytic=0, merl_dir=str(tmp_path), merl=1)
    assert len(HELD_OUT_MERL) == 50


def test_shipped_weights_load_by_default_and_estimate_a_sphere():
    from unps.data.analytic import render_lambertian
    from unps.lightnet.system import SHIPPED
    from unps.metrics import light_direction_mae

    assert SHIPPED.is_file() and SHIPPED.stat().st_size <= 20e6
    notes = torch.load(SHIPPED, weights_only=False)["notes"]
    assert notes["command"].startswith("python -m unps.train") and notes["steps"] > 0
    subject = render_lambertian("sphere", size=64, n_lights=24, seed=1)
    lights, _ = network_lights(subject)
    assert light_direction_mae(lights.directions, subject.light_directions) < 8
    np.testing.assert_allclose(lights.intensities.mean(), 1, rtol=1e-5)


def test_fine_tuning_starts_from_given_weights(trained, tmp_path):
    out, _ = trained
    start, _ = load_lightnet(out / "checkpoints" / "last.ckpt")
    cfg = train_config(tmp_path, "recipe.max_steps=1", "recipe.lr=1e-12",
                       f"init_weights={out / 'checkpoints' / 'last.ckpt'}")
    train(cfg)
    tuned, _ = load_lightnet(tmp_path / "checkpoints" / "last.ckpt")
    for a, b in zip(start.parameters(), tuned.parameters()):
        torch.testing.assert_close(a, b, atol=1e-6, rtol=0)
    with pytest.raises(InputError, match="fine-tuning needs the same layers"):
        train(train_config(tmp_path / "other", "light.width=16",
                           f"init_weights={out / 'checkpoints' / 'last.ckpt'}"))


def test_fine_tuning_may_move_the_strides_and_keeps_the_weights(trained, tmp_path):
    out, _ = trained
    start, config = load_lightnet(out / "checkpoints" / "last.ckpt")
    other = LCNET_STRIDES if tuple(config["light"]["strides"]) == LATE_STRIDES else LATE_STRIDES
    train(train_config(tmp_path, "recipe.max_steps=1", "recipe.lr=1e-12",
                       f"light.strides=[{','.join(map(str, other))}]",
                       f"init_weights={out / 'checkpoints' / 'last.ckpt'}"))
    tuned, tuned_config = load_lightnet(tmp_path / "checkpoints" / "last.ckpt")
    assert tuple(tuned_config["light"]["strides"]) == other
    assert tuple(m.stride[0] for m in tuned.extractor.modules() if isinstance(m, torch.nn.Conv2d)) == other
    for a, b in zip(start.parameters(), tuned.parameters()):
        torch.testing.assert_close(a, b, atol=1e-6, rtol=0)


def test_the_strides_say_where_the_extractor_halves_the_resolution(tmp_path):
    x, mask = torch.rand(2, 3, 3, 64, 64), torch.ones(2, 1, 64, 64)
    sizes, flops = {}, {}
    for strides in (LCNET_STRIDES, LATE_STRIDES):
        net = LightNet(8, 16, strides)
        second = net.extractor[:2](torch.rand(1, 4, 64, 64))
        sizes[strides] = second.shape[-1]
        with FlopCounterMode(display=False) as counter:
            logits = net(x, mask)
        flops[strides] = counter.get_total_flops()
        assert logits["azimuth"].shape == (2, 3, bins.ANGLE_BINS)
    assert sizes == {LCNET_STRIDES: 16, LATE_STRIDES: 32}
    assert 1.7 < flops[LATE_STRIDES] / flops[LCNET_STRIDES] < 1.9
    with pytest.raises(InputError, match=r"light.strides: seven, four of them 2 .* got \[2, 2, 2\]"):
        LightNet(8, 16, (2, 2, 2))
    with pytest.raises(InputError, match="light.strides"):          # as the command line reports it
        train(train_config(tmp_path, "light.strides=[2,2,2]"))


def test_weights_saved_before_the_strides_were_named_load_with_the_late_strides():
    from unps.lightnet.system import build_net
    config = {"light": {"_target_": "unps.lightnet.network.LightNet", "width": 8, "head_width": 16}}
    net = build_net(config)
    assert [m.stride[0] for m in net.extractor.modules() if isinstance(m, torch.nn.Conv2d)] == list(LATE_STRIDES)


# outlines as captures draw them (data.outline_jitter) ------------------------------------------

def _disc_batch(b=6, n=3, size=24):
    rows, cols = torch.meshgrid(torch.arange(size), torch.arange(size), indexing="ij")
    mask = (((rows - 11.5) ** 2 + (cols - 11.5) ** 2) < 8 ** 2).float().expand(b, 1, size, size).clone()
    images = (0.2 + torch.rand(b, n, 3, size, size, generator=torch.Generator().manual_seed(1))) * mask[:, None]
    return images, mask


def test_outline_jitter_moves_only_the_outline_and_dims_only_its_pixels():
    images, mask = _disc_batch()
    inner, outer = outline_rings(mask)
    jittered, new_mask = jittered_outlines(images, mask, 1.0, torch.Generator().manual_seed(0))
    changed = new_mask != mask
    assert changed.any() and not (changed & ~(inner | outer)).any()     # a pixel layer, no deeper
    for k in range(len(mask)):                                          # each sample erodes or dilates
        assert not ((new_mask[k] < mask[k]).any() and (new_mask[k] > mask[k]).any())
    new_inner, _ = outline_rings(new_mask)
    ratio = jittered / images.clamp_min(1e-12)
    on_outline = new_inner[:, None].expand_as(images)
    kept_inside = (new_mask > 0.5)[:, None].expand_as(images) & ~on_outline
    assert torch.equal(jittered[kept_inside], images[kept_inside])      # the inside is left alone
    assert ratio[on_outline & (images > 0)].min() >= DIMMED_DOWN_TO - 1e-6
    assert ratio[on_outline & (images > 0)].max() <= 1 + 1e-6
    assert (jittered[(new_mask < 0.5)[:, None].expand_as(images)] == 0).all()   # off the object: black


def test_outline_jitter_is_the_same_for_the_same_draws_and_none_at_share_zero():
    images, mask = _disc_batch()
    first = jittered_outlines(images, mask, 0.5, torch.Generator().manual_seed(1))
    again = jittered_outlines(images, mask, 0.5, torch.Generator().manual_seed(1))
    assert all(torch.equal(a, b) for a, b in zip(first, again))
    untouched = jittered_outlines(images, mask, 0.0, torch.Generator().manual_seed(1))
    assert untouched[0] is images and untouched[1] is mask
    picked = (first[1] != mask).flatten(1).any(1)
    assert 0 < int(picked.sum()) < len(mask)                            # about half the samples


def test_training_with_outline_jitter_runs_and_a_share_outside_zero_to_one_is_refused(tmp_path):
    metrics = train(train_config(tmp_path / "jitter", "recipe.max_steps=2", "data.outline_jitter=1.0"))
    assert metrics["steps"] == 2
    with pytest.raises(InputError, match=r"data.outline_jitter is a share of the samples, in 0…1; got 1.5"):
        train(train_config(tmp_path / "bad", "data.outline_jitter=1.5"))
    assert not (tmp_path / "bad").exists()                          # nothing written

"""The device option, and the torch paths a GPU runs, checked here on the CPU against the CPU's own."""

import numpy as np
import pytest
import torch

from unps.device import resolve_device, trainer_placement
from unps.errors import InputError
from unps.inverse.interreflection import Interreflection
from unps.solvers.nayar import interreflection_kernel, kernel_on_device, visibility, visibility_on_device
from unps.solvers.rpca import partial_sum_rpca

cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")


def test_device_names_resolve_or_are_refused_by_name():
    assert resolve_device("cpu") == torch.device("cpu")
    assert resolve_device("auto").type == ("cuda" if torch.cuda.is_available() else "cpu")
    for bad in ("gpu", "cuda:x", "", 3):
        with pytest.raises(InputError, match="device must be auto, cpu, cuda or cuda:<index>"):
            resolve_device(bad)
    if not torch.cuda.is_available():
        with pytest.raises(InputError, match="sees no CUDA GPU"):
            resolve_device("cuda")
    else:
        with pytest.raises(InputError, match="CUDA GPU"):
            resolve_device(f"cuda:{torch.cuda.device_count()}")


def test_lightning_is_told_the_same_device():
    assert trainer_placement(torch.device("cpu")) == {"accelerator": "cpu", "devices": 1}
    assert trainer_placement(torch.device("cuda", 2)) == {"accelerator": "gpu", "devices": [2]}


def bowl(size=28):
    """A bowl with a wall across it (facets that see, and are hidden from, each other)."""
    c = np.linspace(-1, 1, size)
    x, y = np.meshgrid(c, -c)
    mask = x ** 2 + y ** 2 < 0.95
    depth = 6 * (x ** 2 + y ** 2) + 4 * np.exp(-(x / 0.12) ** 2)
    gy, gx = np.gradient(depth)
    normals = np.stack([-gx, gy, np.ones_like(depth)], -1)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    return np.where(mask, depth, 0), normals, mask


def test_the_gpu_kernel_is_the_cpu_kernel():
    depth, normals, mask = bowl()
    on = dict(dtype=torch.float64)
    args = (torch.as_tensor(depth, **on), torch.as_tensor(normals, **on), torch.as_tensor(mask))
    hidden = ~visibility(depth, mask)
    assert 0.02 < hidden.mean() < 0.5                        # the wall hides a good share
    agree = visibility_on_device(args[0], args[2], chunk=100).numpy() == ~hidden
    assert agree.mean() > 0.9999
    both = agree & agree.T
    k_cpu, k_torch = interreflection_kernel(depth, normals, mask), kernel_on_device(*args).numpy()
    np.testing.assert_allclose(k_torch[both], k_cpu[both], rtol=1e-12, atol=1e-15)


def test_rpca_on_a_device_is_the_default():
    x = np.random.default_rng(0).normal(size=(300, 12)) @ np.diag(np.linspace(3, 0.01, 12))
    default, placed = partial_sum_rpca(x), partial_sum_rpca(x, device=torch.device("cpu"))
    assert np.array_equal(default.low_rank, placed.low_rank)


@cuda
def test_the_interreflection_update_on_a_gpu_solves_as_on_the_cpu():
    depth, normals, mask = bowl()
    albedo = np.full(mask.shape, 0.7)
    solver = Interreflection(mask, albedo, downsample=2)
    scaled = torch.as_tensor(normals, dtype=torch.float32).permute(2, 0, 1)[None]
    solver.update(normals, torch.device("cpu"))
    on_cpu = solver(scaled)
    solver.update(normals, torch.device("cuda"))
    assert solver.lu.device.type == "cuda"
    on_gpu = solver(scaled.cuda()).cpu()
    assert torch.allclose(on_cpu, on_gpu, atol=1e-4)


@cuda
def test_a_whole_uncalibrated_run_on_a_gpu_lands_where_the_cpu_run_does(tmp_path):
    from hydra import compose, initialize_config_module

    from unps.fit import fit

    overrides = ["subject=lambertian", "subject.size=32", "subject.n_lights=16", "method=unps",
                 "preset.steps=60", "preset.lr_drop_at=54", "light=selfcal", "light.selfcal.steps=200"]
    errors = {}
    for device in ("cpu", "cuda"):
        with initialize_config_module(config_module="unps.conf", version_base="1.3"):
            cfg = compose("fit", overrides=[f"paths.output_dir={tmp_path / device}", f"device={device}",
                                            *overrides])
        metrics = fit(cfg)
        assert metrics["device"].startswith(device)
        errors[device] = metrics["normal_mae"]
    assert abs(errors["cuda"] - errors["cpu"]) < 1.0, errors

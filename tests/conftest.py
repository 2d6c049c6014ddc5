import os
from pathlib import Path

import pytest

import numpy as np
import torch

from unps.data.analytic import dome_lights, height_field, render_lambertian
from unps.data.subject import Subject
from unps.geometry import cast_shadows
from unps.lights.reversal import HALF_TURN
from unps.solvers.nayar import interreflection_kernel

SHARED_DATA = Path(os.environ.get("UNPS_SHARED_DATA",
                                  Path(__file__).resolve().parents[2] / "shared" / "data"))
DILIGENT = SHARED_DATA / "DiLiGenT"


def diligent_object(relative: str) -> Path:
    """A DiLiGenT object folder from ../shared/data, or skip the test when it is absent."""
    path = DILIGENT / relative
    if not path.is_dir():
        pytest.skip(f"development data not found at {path}")
    return path


@pytest.fixture
def sphere():
    return render_lambertian("sphere", size=32, n_lights=12, textured=True, seed=3)


def load_script(name, relative):
    """Import a script by path; it is registered under ``name`` while it runs (dataclasses need it)."""
    import importlib.util
    import sys
    spec = importlib.util.spec_from_file_location(name, Path(__file__).parents[1] / relative)
    module = importlib.util.module_from_spec(spec)
    previous = sys.modules.get(name)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    finally:
        if previous is None:
            del sys.modules[name]
        else:
            sys.modules[name] = previous
    return module


def rendered(concave: bool, size: int = 48, n_lights: int = 32) -> Subject:
    """A hemisphere, or the bowl it leaves when pressed into a plane (depth and normals reversed),
    Lambertian with attached and cast shadows."""
    depth, normals, mask = height_field("sphere", size, seed=0)
    if concave:
        depth, normals = -depth, normals @ HALF_TURN.astype(np.float32)
    lights = dome_lights(n_lights, seed=3)
    visible = ~cast_shadows(torch.as_tensor(np.where(mask, depth, 0)), torch.as_tensor(mask),
                            torch.as_tensor(lights), 1.0, 2 * size).numpy()
    shading = np.maximum(np.einsum("hwc,nc->nhw", normals, lights), 0) * visible
    images = np.repeat((0.7 * shading * mask)[..., None], 3, -1).astype(np.float32)
    return Subject("bowl" if concave else "dome", images, mask, light_directions=lights,
                   normals=normals)


TINY = dict(name="tiny", width=16, depth=3, first_kernel=1, reflectance_width=8, steps=20,
            lr_drop_at=18, images_per_step=8, update_every=10)
"""A preset small enough for a test: a 20-step fit of a small subject in seconds."""


def one_bounce(direct: np.ndarray, depth: np.ndarray, normals: np.ndarray, mask: np.ndarray,
               albedo: float) -> np.ndarray:
    """(n, m) the first bounce of a Lambertian surface's ``direct`` light (n, m) at its ``mask``'s
    m pixels: Nayar's kernel on the surface (``depth`` (H, W) in pixels, ``normals`` (H, W, 3)),
    reflectance ``albedo``."""
    return albedo * (interreflection_kernel(depth, normals, mask) @ direct.T).T


def tiny_fit(subject: Subject, **preset):
    """``method=unps`` on ``subject`` under its own lights with :data:`TINY` and ``preset``'s
    fields, no interreflections, seed 0."""
    from unps.inverse.fit import neural_inverse_rendering
    from unps.inverse.settings import InterreflectionModel, Preset

    torch.manual_seed(0)
    return neural_inverse_rendering(subject, subject.light_directions, Preset.from_config(**TINY, **preset),
                                    InterreflectionModel(enabled=False))


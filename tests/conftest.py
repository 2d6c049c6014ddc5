import os
from pathlib import Path

import pytest

from unps.data.analytic import render_lambertian

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

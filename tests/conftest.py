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

"""Where a fit's normal error is: by the true normal's angle from the view, and in its worst pixels.

    python experiments/calibrated/error_by_angle.py RUN [RUN ...]

Each RUN is the output folder of a ``python -m unps.fit`` on a DiLiGenT object (``normals.npy``
and ``.hydra/config.yaml``, whose ``subject.object`` names it). Printed per run: the mean error,
then for each band of the true normal's angle from the view its share of the object, its mean
error and what it adds to the object's mean, and the same for the pixels more than 30° off.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from unps.data.diligent import read_diligent_object
from unps.metrics import angular_error

DILIGENT = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "DiLiGenT"
BANDS = ((0, 30), (30, 50), (50, 65), (65, 75), (75, 90))   # degrees from the view
WORST = 30.0


def bands(error: np.ndarray, truth: np.ndarray) -> list[tuple[str, float, float, float]]:
    """(label, share of the pixels, mean error, contribution to the mean) for each band of
    :data:`BANDS` and for the pixels more than :data:`WORST` degrees off; ``error`` (m,) in
    degrees, ``truth`` (m, 3) unit normals."""
    from_view = np.degrees(np.arccos(np.clip(truth[:, 2], -1, 1)))
    groups = [(f"{lo}–{hi}° from the view", (from_view >= lo) & (from_view < hi)) for lo, hi in BANDS]
    groups.append((f"more than {WORST:g}° off", error > WORST))
    return [(label, float(chosen.mean()), float(error[chosen].mean()) if chosen.any() else 0.0,
             float(error[chosen].sum() / error.size)) for label, chosen in groups]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--data", type=Path, default=DILIGENT)
    args = parser.parse_args()
    for run in args.runs:
        name = OmegaConf.load(run / ".hydra" / "config.yaml").subject.object
        subject = read_diligent_object(args.data, name)
        normals, truth = np.load(run / "normals.npy")[subject.mask], subject.normals[subject.mask]
        error = angular_error(normals, truth)
        print(f"\n{run} ({name}): mean {error.mean():.2f}°")
        for label, share, mean, adds in bands(error, truth):
            print(f"  {label:<24} {100 * share:5.1f} % of the pixels, {mean:6.2f}°, adds {adds:.2f}°")


if __name__ == "__main__":
    main()

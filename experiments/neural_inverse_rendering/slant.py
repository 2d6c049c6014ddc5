"""Re-measure finished fits: normal MAE and slant bias from each run's normals.npy and its ground truth.

    python experiments/neural_inverse_rendering/slant.py runs/nir-noise0.1/*-unps-fast*
    python experiments/neural_inverse_rendering/slant.py runs/nir/Tablet1-* --group-seeds

A run folder is one `python -m unps.fit` output: its `normals.npy` and Hydra's
`.hydra/config.yaml`, from which the subject, and so its ground-truth normals and mask, is built
again (renders come from the cache). Printed per run: the normal MAE, `slant_bias`
(:func:`unps.metrics.slant_bias`, the signed error along the slant direction), and the mean
difference of the slants themselves, the measure `slant_bias` replaced, which reads any error
on parts facing the camera as steepening. With ``--group-seeds``, `<row>` and `<row>-seed<k>`
folders are also averaged per row, and the MAE of their ensemble (the seeds' normals averaged and
normalised) is printed: how much of the error is seed-to-seed variance rather than bias.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import numpy as np
from hydra.utils import instantiate
from omegaconf import OmegaConf

from unps.metrics import angular_error, slant_bias

VIEW = np.array([0.0, 0.0, 1.0])


def truth(run: Path, cache: dict) -> tuple[np.ndarray, np.ndarray]:
    """(H, W, 3) ground-truth normals and (H, W) mask of the subject a run folder was fitted on.

    Raises:
        FileNotFoundError: the folder has no `.hydra/config.yaml`.
        ValueError: the subject has no ground-truth normals.
    """
    config_file = run / ".hydra" / "config.yaml"
    if not config_file.is_file():
        raise FileNotFoundError(f"{config_file}: not found; is {run} a `python -m unps.fit` output?")
    cfg = OmegaConf.load(config_file)
    key = OmegaConf.to_yaml(cfg.subject, resolve=True)
    if key not in cache:
        subject = instantiate(cfg.subject, _partial_=True)()
        if subject.normals is None:
            raise ValueError(f"{run}: subject {subject.name!r} has no ground-truth normals")
        cache[key] = (subject.normals, subject.mask)
    return cache[key]


def measure(normals: np.ndarray, gt: np.ndarray, mask: np.ndarray) -> dict[str, float]:
    """MAE, slant bias and mean slant difference (degrees) of (H, W, 3) normals against the
    (H, W, 3) truth over the (H, W) mask."""
    return {"mae": float(angular_error(normals, gt)[mask].mean()),
            "slant_bias": slant_bias(normals, gt, mask),
            "slant_difference": float((angular_error(normals[mask], VIEW)
                                       - angular_error(gt[mask], VIEW)).mean())}


def load_normals(run: Path, shape: tuple[int, ...]) -> np.ndarray:
    """A run folder's normals.npy, checked against the subject's (H, W, 3) shape.

    Raises:
        ValueError: another shape.
    """
    normals = np.load(run / "normals.npy")
    if normals.shape != shape:
        raise ValueError(f"{run / 'normals.npy'}: shape {normals.shape}, expected the subject's {shape}")
    return normals


def ensemble(normals: list[np.ndarray]) -> np.ndarray:
    """The per-pixel mean of (H, W, 3) unit normals, normalised."""
    mean = np.sum(normals, axis=0)
    return mean / np.maximum(np.linalg.norm(mean, axis=-1, keepdims=True), 1e-12)


def row_name(run: Path) -> str:
    """`<row>-seed<k>` → `<row>`."""
    return re.sub(r"-seed\d+$", "", run.name)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path,
                        help="run folders (those without normals.npy are skipped)")
    parser.add_argument("--group-seeds", action="store_true", help="also print each row's mean over seeds")
    args = parser.parse_args(argv)
    cache: dict = {}
    rows: dict[str, list[tuple[dict, np.ndarray]]] = {}
    truths: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    print(f"{'run':44s} {'MAE °':>7s} {'slant bias °':>13s} {'slant difference °':>19s}")
    for run in sorted(args.runs):
        if not (run / "normals.npy").is_file():
            continue
        gt, mask = truth(run, cache)
        normals = load_normals(run, gt.shape)
        m = measure(normals, gt, mask)
        rows.setdefault(row_name(run), []).append((m, normals))
        truths[row_name(run)] = gt, mask
        print(f"{run.name:44s} {m['mae']:7.2f} {m['slant_bias']:+13.2f} {m['slant_difference']:+19.2f}",
              flush=True)
    if args.group_seeds:
        print(f"\n{'row (mean over seeds)':44s} {'MAE °':>7s} {'slant bias °':>13s} "
              f"{'slant difference °':>19s} seeds {'ensemble MAE °':>14s}")
        for name, seeds in rows.items():
            mean = {k: float(np.mean([m[k] for m, _ in seeds])) for k in seeds[0][0]}
            gt, mask = truths[name]
            together = angular_error(ensemble([n for _, n in seeds]), gt)[mask].mean()
            print(f"{name:44s} {mean['mae']:7.2f} {mean['slant_bias']:+13.2f} "
                  f"{mean['slant_difference']:+19.2f} {len(seeds):5d} {together:14.2f}")


if __name__ == "__main__":
    sys.exit(main())

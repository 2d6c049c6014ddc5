"""Where the calibrated normals go wrong on the light benchmark: pixels black in every image.

    python experiments/light_benchmark/black_pixels.py --runs <cache>/normals/default
    python experiments/light_benchmark/black_pixels.py --runs paper=<dir> relative=<dir> --methods rpca unps

Reads the rows that ``normals.py`` fitted (``<run>/<object>-<method>/normals.npy``, 96 lights,
``light=gt``) and splits each object's normal error between the pixels the images say something
about and those that are black in every one of the 96 images: no value above ``--levels``
quantisation steps of the object's storage (8-bit: 2/255; 16-bit: 2/65535). A black pixel holds
no shading at all, so any normal explains it; what a method puts there is its guess.

It also prints what a guess from the surroundings would give: the black pixels' normals replaced
by those of a depth map that follows the method's normals on the lit pixels and continues them
with the least curvature (squared second differences) across the black ones
(:func:`continue_surface`). This is an experiment on saved outputs, not a stage of unps.

Printed per object: the share of black pixels, then per run and method the mean angular error
over the whole object, over its lit pixels, and with the black pixels continued.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.ndimage import binary_dilation
from scipy.sparse.linalg import spsolve

from unps.data.diligent import read_diligent
from unps.metrics import angular_error

sys.path.insert(0, str(Path(__file__).resolve().parent))
import scenes  # noqa: E402

DEFAULT_DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
DEFAULT_CACHE = Path("~/.cache/unps/light_benchmark").expanduser()
FULL_SCALE = {"floor8": 255, "round8": 255, "png16": 65535}
LIGHT_SET = "96"


def black_everywhere(observed: np.ndarray, mask: np.ndarray, full_scale: int, levels: int = 2
                     ) -> np.ndarray:
    """(H, W) bool: object pixels whose every value, over all (n, H, W, 3) ``observed`` images
    (in [0, 1] of the stored range), is at most ``levels`` quantisation steps (1/``full_scale``)."""
    return mask & (observed.max(axis=(0, 3)) < (levels + 1) / full_scale)


def continue_surface(normals: np.ndarray, mask: np.ndarray, black: np.ndarray,
                     smoothness: float = 1.0) -> np.ndarray:
    """(H, W, 3) ``normals`` with the ``black`` pixels' replaced by those of the least-curved depth
    that follows the normals between lit neighbours.

    The depth z over the mask minimises Σ (n̄_z Δz + n̄_x)² along +col and (n̄_z Δz − n̄_y)² along
    +row (``unps.geometry.integrate_normals``' equations, for pairs of lit pixels only) plus
    ``smoothness``² Σ (second difference of z)² centred on black pixels and their neighbours; the
    black pixels' normals are (−∂z/∂x, −∂z/∂y, 1) normalised, from central differences where
    both neighbours are on the object, one-sided ones elsewhere.
    """
    h, w = mask.shape
    index = -np.ones((h, w), np.int64)
    index[mask] = np.arange(mask.sum())
    n = normals.astype(np.float64)
    lit = mask & ~black
    rows, cols, values, rhs = [], [], [], []
    count = 0

    def equations(columns: list[np.ndarray], weights: list[np.ndarray], target: np.ndarray) -> None:
        nonlocal count
        k = target.size
        eq = np.arange(count, count + k)
        for c, v in zip(columns, weights):
            rows.append(eq)
            cols.append(c)
            values.append(np.broadcast_to(v, (k,)))
        rhs.append(target)
        count += k

    for (dr, dc), sign in (((0, 1), -1.0), ((1, 0), 1.0)):
        a, b = index[: h - dr, : w - dc], index[dr:, dc:]
        ok = (a >= 0) & (b >= 0) & lit[: h - dr, : w - dc] & lit[dr:, dc:]
        mean = (n[: h - dr, : w - dc] + n[dr:, dc:])[ok] / 2
        equations([b[ok], a[ok]], [mean[:, 2], -mean[:, 2]], sign * (mean[:, 0] if dc else mean[:, 1]))
    near = binary_dilation(black, np.ones((3, 3), bool))
    for dr, dc in ((0, 1), (1, 0)):
        a, centre = index[: h - 2 * dr, : w - 2 * dc], index[dr: h - dr, dc: w - dc]
        b = index[2 * dr:, 2 * dc:]
        ok = (a >= 0) & (centre >= 0) & (b >= 0) & near[dr: h - dr, dc: w - dc]
        equations([a[ok], centre[ok], b[ok]], [smoothness, -2 * smoothness, smoothness],
                  np.zeros(int(ok.sum())))
    m = int(mask.sum())
    system = sp.csr_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))),
                           shape=(count, m))
    z = spsolve((system.T @ system + 1e-8 * sp.eye(m)).tocsc(), system.T @ np.concatenate(rhs))
    depth = np.zeros((h, w))
    depth[mask] = z
    slopes = []
    for axis in (1, 0):
        ahead, behind = np.roll(depth, -1, axis), np.roll(depth, 1, axis)
        on_ahead, on_behind = np.roll(mask, -1, axis), np.roll(mask, 1, axis)
        slopes.append(np.where(on_ahead & on_behind, (ahead - behind) / 2,
                               np.where(on_ahead, ahead - depth, np.where(on_behind, depth - behind, 0))))
    continued = np.stack([-slopes[0], slopes[1], np.ones_like(depth)], -1)   # ∂z/∂y = −∂z/∂row
    continued /= np.linalg.norm(continued, axis=-1, keepdims=True)
    out = normals.copy()
    out[black] = continued[black]
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", nargs="+", required=True,
                        help="normals.py run folders, each [label=]folder")
    parser.add_argument("--methods", nargs="+", default=["unps"], choices=("woodham", "rpca", "unps"))
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    parser.add_argument("--levels", type=int, default=2, help="quantisation steps still counted as black")
    args = parser.parse_args(argv)
    runs = dict(r.split("=", 1) if "=" in r else (Path(r).name, r) for r in args.runs)
    columns = [(label, Path(folder), method) for label, folder in runs.items() for method in args.methods]
    for _, folder, method in columns:
        missing = [o.name for o in scenes.OBJECTS
                   if not (folder / f"{o.name}-{method}" / "normals.npy").is_file()]
        if missing:
            sys.exit(f"{folder}: no {method} normals for {', '.join(missing)} (run normals.py first)")

    print(f"light benchmark, {LIGHT_SET} lights, light=gt: normal MAE ° over the object / its lit pixels / "
          f"with the black pixels continued (black: no value above {args.levels} steps in any image)")
    print(f"{'object':<12}{'storage':>8}{'black':>7}  "
          + "".join(f"{label + ' ' + m:>24}" for label, _, m in columns))
    totals = np.zeros((len(columns), 3))
    for obj in scenes.OBJECTS:
        folder = scenes.make_captures(obj, args.data, args.cache)[LIGHT_SET]
        subject = read_diligent(folder, name=obj.name, quantization=scenes.quantization(obj.storage))
        mask = subject.mask
        black = black_everywhere(subject.observed_images(), mask, FULL_SCALE[obj.storage], args.levels)
        line = f"{obj.name:<12}{obj.storage:>8}{black.sum() / mask.sum():>7.0%}  "
        for i, (_, run, method) in enumerate(columns):
            normals = np.load(run / f"{obj.name}-{method}" / "normals.npy")
            error = angular_error(normals[mask], subject.normals[mask])
            lit = error[~black[mask]].mean() if (~black[mask]).any() else float("nan")
            filled = angular_error(continue_surface(normals, mask, black)[mask], subject.normals[mask]).mean()
            totals[i] += error.mean(), lit, filled
            line += f"{error.mean():>8.2f}{lit:>8.2f}{filled:>8.2f}"
        print(line, flush=True)
    means = totals / len(scenes.OBJECTS)
    print(f"{'mean':<27}  " + "".join(f"{a:>8.2f}{b:>8.2f}{c:>8.2f}" for a, b, c in means))


if __name__ == "__main__":
    main()

"""Where the calibrated normals' error lies on the light benchmark, by the kind of pixel.

    python experiments/light_benchmark/error_sources.py --runs <cache>/normals/<tag>
    python experiments/light_benchmark/error_sources.py --runs <dir> --sets 96 12 --ring 2

Reads the rows that ``normals.py`` fitted (``<run>/<object>-unps/normals.npy``, ``light=gt``;
``--sets`` names the light counts, each run folder holding that count's fits: give one folder per
set, in the same order) and sorts each object pixel into the first of these kinds that holds:

- ``outline``: within ``--ring`` pixels of the mask's edge (the occluding contour, or a rim);
- ``black``: black or nearly so in every image (:func:`unps.data.checks.black_everywhere`,
  :func:`unps.data.checks.faintly_lit`): no shading to read;
- ``dark``: its brightness (the median over the images that light it of value / n·l, with the true
  normal and lights) under ``--dark`` of the object's median: a dark material;
- ``shadowed``: cast into shadow, by the true surface, in more than ``--shadowed`` of the images
  that face it (the true normals integrated to a depth and marched toward each light with
  :func:`unps.geometry.cast_shadows`, as the fit marches its own);
- ``plain``: the rest, the pixels the fit's model should explain best.

Printed per object the share of pixels and mean error of each kind; then, over the objects (each
weighing as much, as the benchmark's mean does), each kind's mean share, its mean error, and how
many degrees of the objects' mean error it holds (share × error, averaged) and how many of those
are above what it would hold at its object's plain pixels' error, with what the mean would be were
every kind's error that of the object's plain pixels.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

from unps.data.checks import black_everywhere, faintly_lit
from unps.data.diligent import read_diligent
from unps.geometry import cast_shadows, integrate_normals, outline_distance
from unps.metrics import angular_error

sys.path.insert(0, str(Path(__file__).resolve().parent))
import scenes  # noqa: E402

DEFAULT_DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
DEFAULT_CACHE = Path("~/.cache/unps/light_benchmark").expanduser()
KINDS = ("outline", "black", "dark", "shadowed", "plain")
MARCH_STEPS = 128
FACING = 0.05            # n·l above which an image counts as lighting a pixel


def pixel_kinds(observed: np.ndarray, mask: np.ndarray, normals: np.ndarray, lights: np.ndarray,
                ring: float, dark: float, shadowed: float) -> np.ndarray:
    """Each object pixel's kind, the first of :data:`KINDS` that holds (see the module's docstring).

    Args:
        observed: (n, H, W, 3) images as captured; mask: (H, W) bool.
        normals: (H, W, 3) true unit normals; lights: (n, 3) unit surface-to-light directions.
        ring: outline width in pixels; dark: share of the object's median brightness;
        shadowed: share of the facing images.

    Returns:
        (H, W) int8 index into :data:`KINDS`, −1 off the mask.
    """
    kind = np.full(mask.shape, -1, np.int8)
    shading = np.einsum("hwc,nc->nhw", normals, lights)                       # (n, H, W)
    facing = shading > FACING
    brightness = np.where(facing, observed.mean(-1) / np.maximum(shading, FACING), np.nan)
    brightness = np.nanmedian(np.where(facing.any(0), brightness, 0.0), axis=0)
    depth = integrate_normals(normals, mask)
    hidden = cast_shadows(torch.from_numpy(np.nan_to_num(depth)), torch.from_numpy(mask),
                          torch.from_numpy(lights).float(), 1.0, MARCH_STEPS).numpy()
    shadow_share = (hidden & facing).sum(0) / np.maximum(facing.sum(0), 1)
    tests = {
        "outline": outline_distance(mask) <= ring,
        "black": black_everywhere(observed, mask) | faintly_lit(observed, mask),
        "dark": brightness < dark * np.median(brightness[mask]),
        "shadowed": shadow_share > shadowed,
        "plain": np.ones_like(mask),
    }
    for index, name in reversed(list(enumerate(KINDS))):       # the first kind that holds wins
        kind[mask & tests[name]] = index
    return kind


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", nargs="+", type=Path, required=True,
                        help="normals.py run folders, one per --sets entry")
    parser.add_argument("--sets", nargs="+", default=["96"], choices=tuple(scenes.LIGHT_SETS))
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    parser.add_argument("--ring", type=float, default=2.0, help="outline width, pixels")
    parser.add_argument("--dark", type=float, default=0.2,
                        help="dark: brightness under this share of the object's median")
    parser.add_argument("--shadowed", type=float, default=0.1,
                        help="shadowed: cast into shadow in more than this share of the facing images")
    args = parser.parse_args(argv)
    if len(args.runs) != len(args.sets):
        sys.exit(f"--runs has {len(args.runs)} folders and --sets {len(args.sets)} light counts: "
                 "give one folder per set")
    for run in args.runs:
        missing = [o.name for o in scenes.OBJECTS if not (run / f"{o.name}-unps" / "normals.npy").is_file()]
        if missing:
            sys.exit(f"{run}: no unps normals for {', '.join(missing)} (run normals.py first)")

    for run, light_set in zip(args.runs, args.sets):
        print(f"\nlight benchmark, {light_set} lights, light=gt, {run}: "
              "share of the object's pixels / mean error °")
        print(f"{'object':<12}{'storage':>8}{'error':>8}  " + "".join(f"{k:>16}" for k in KINDS))
        shares, errors, plain_error = [], [], []
        for obj in scenes.OBJECTS:
            folder = scenes.make_captures(obj, args.data, args.cache)[light_set]
            subject = read_diligent(folder, name=obj.name, quantization=scenes.quantization(obj.storage))
            mask = subject.mask
            kind = pixel_kinds(subject.observed_images(), mask, subject.normals, subject.light_directions,
                               args.ring, args.dark, args.shadowed)[mask]
            fitted = np.load(run / f"{obj.name}-unps" / "normals.npy")
            error = angular_error(fitted[mask], subject.normals[mask])
            share = np.array([(kind == k).mean() for k in range(len(KINDS))])
            mean = np.array([error[kind == k].mean() if (kind == k).any() else np.nan
                             for k in range(len(KINDS))])
            shares.append(share)
            errors.append(mean)
            plain_error.append(mean[-1] if share[-1] else error.mean())
            print(f"{obj.name:<12}{obj.storage:>8}{error.mean():>7.2f}°  "
                  + "".join(f"{s:>7.0%} {e:>7.2f}°" if s else f"{'—':>16}" for s, e in zip(share, mean)),
                  flush=True)
        shares, errors = np.array(shares), np.array(errors)
        held = np.nan_to_num(shares * errors)
        total = held.sum(1).mean()
        as_plain = (shares * np.array(plain_error)[:, None]).sum(1).mean()
        print(f"{'mean':<20}{total:>7.2f}°  " + "".join(
            f"{s:>7.0%} {np.nanmean(e):>7.2f}°" for s, e in zip(shares.mean(0), errors.T)))
        excess = (held - shares * np.array(plain_error)[:, None]).mean(0)
        print(f"{'degrees of the mean':<28}" + "".join(f"{h:>15.2f}°" for h in held.mean(0)))
        print(f"{'… above the plain error':<28}" + "".join(f"{x:>+15.2f}°" for x in excess))
        print(f"every pixel at its object's plain pixels' error: {as_plain:.2f}° (against {total:.2f}°)")


if __name__ == "__main__":
    main()

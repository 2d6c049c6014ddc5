"""Which part of the estimated lights costs the normals: their directions or their intensities?

    python experiments/light_benchmark/light_parts.py --uncal RUNS --gt RUNS
    python experiments/light_benchmark/light_parts.py --uncal RUNS --gt RUNS --names ring --set threads=1
    python experiments/light_benchmark/light_parts.py --uncal RUNS --method woodham --lights-only

``RUNS`` are run folders of ``normals.py``: ``--uncal`` one made with estimated lights (``--light
selfcal --methods unps``, the default of ``python -m unps.fit``), ``--gt`` one made with the true
lights, on the same light set (``--lights``). For every object of the uncalibrated folder, the fit
is run again with the true lights' files replaced by those the uncalibrated fit ended with
(``lights.txt``): its directions with the true intensities, the true directions with its
intensities, and both (``light=gt``, so that the fit takes them as they are), each one
``python -m unps.fit`` in ``<out>/<part>/<object>-unps/`` (a rerun skips finished rows). Printed
per object: the lights' mean direction error, their mean relative intensity error and the share of
its log that is linear in the light's direction (a smooth brightening toward one side of the
dome, which the shading of a Lambertian surface cannot tell from a tilt of its normals), then the
normal error with the true lights, with each part estimated, with both, and the uncalibrated fit's
own (which also learnt the lights with the surface). ``--lights-only`` prints the light columns
alone, runs nothing and needs no ``--gt``: with ``--method woodham`` on a folder of
``normals.py --light estimated --methods woodham``, the network's own lights (and the reversal
test's, which keeps them on these objects).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import normals  # noqa: E402
import runs  # noqa: E402
import scenes  # noqa: E402

from unps.data.layout import DIRECTIONS, INTENSITIES  # noqa: E402
from unps.io.files import atomic_dir  # noqa: E402

PARTS = ("directions", "intensities", "both")
INSIDE_OUT_DEG = 20.0   # lights further off than this are read inside out (the reversal test's case)


def relative(intensities: np.ndarray) -> np.ndarray:
    """(n, 3) RGB intensities scaled to a geometric mean of 1 per channel."""
    return intensities / np.exp(np.log(intensities).mean(0))


def intensity_error(estimated: np.ndarray, true: np.ndarray) -> float:
    """Mean |e / e_true − 1| over lights and channels, each set scaled to geometric mean 1.

    >>> intensity_error(np.array([[1.0, 1, 1], [2, 2, 2]]), np.array([[2.0, 2, 2], [4, 4, 4]]))
    0.0
    """
    return float(np.mean(np.abs(relative(estimated) / relative(true) - 1)))


def linear_share(directions: np.ndarray, estimated: np.ndarray, true: np.ndarray) -> float:
    """The share of the variance of log(e / e_true) (mean over RGB) that an affine function of the
    true light direction explains: 1 where the error is a smooth brightening toward one side of
    the dome, 0 where it is light by light. ``directions`` (n, 3) unit; intensities (n, 3).

    >>> d = np.array([[0, 0, 1.0], [0.6, 0, 0.8], [0, 0.6, 0.8], [-0.6, 0, 0.8], [0, -0.6, 0.8]])
    >>> e = np.ones((5, 3))
    >>> round(linear_share(d, e * np.exp(0.3 * d[:, :1]), e), 6)
    1.0
    """
    error = np.log(relative(estimated) / relative(true)).mean(1)
    design = np.c_[np.ones(len(directions)), directions]
    fitted = design @ np.linalg.lstsq(design, error, rcond=None)[0]
    spread = np.var(error)
    return float(1 - np.var(error - fitted) / spread) if spread > 0 else 0.0


def summary(names: list[str], table: np.ndarray) -> list[str]:
    """The means of ``table`` (one row per object: direction error °, intensity error, linear
    share, then the normal MAE with the true lights, with the estimated directions, intensities,
    both, and the uncalibrated fit's), over all objects and over those whose lights are within
    :data:`INSIDE_OUT_DEG` (a reading inside out costs the normals 50–100°, which swamps the
    rest), and what each part adds to the true lights' error there.

    >>> rows = np.array([[5.0, 0.1, 0.9, 10, 12, 13, 15, 15], [40.0, 0.0, 0.5, 5, 80, 5, 80, 80]])
    >>> print("\\n".join(summary(["a", "b"], rows)))
    mean          22.50°   0.050    0.70   7.50°      46.00°       9.00°      47.50°  47.50°
    mean, 1 read the right way round (not b)
                   5.00°   0.100    0.90  10.00°      12.00°      13.00°      15.00°  15.00°
    there, added to the true lights' error: directions +2.00°, intensities +3.00°, both +5.00°
    the intensities add more than the directions on 1 of 1
    """
    def line(label: str, means: np.ndarray) -> str:
        return (f"{label:<12}{means[0]:>7.2f}°{means[1]:>8.3f}{means[2]:>8.2f}{means[3]:>7.2f}°"
                + "".join(f"{e:>11.2f}°" for e in means[4:7]) + f"{means[7]:>7.2f}°")
    right = table[:, 0] <= INSIDE_OUT_DEG
    kept = table[right]
    added = kept[:, 4:7] - kept[:, 3:4]
    left_out = [name for name, keep in zip(names, right) if not keep]
    return [line("mean", table.mean(0)),
            f"mean, {len(kept)} read the right way round (not {', '.join(left_out) or 'any'})",
            line("", kept.mean(0)),
            f"there, added to the true lights' error: directions {added[:, 0].mean():+.2f}°, "
            f"intensities {added[:, 1].mean():+.2f}°, both {added[:, 2].mean():+.2f}°",
            f"the intensities add more than the directions on {int((added[:, 1] > added[:, 0]).sum())} "
            f"of {len(kept)}"]


def mixed_capture(capture: Path, directions: np.ndarray, intensities: np.ndarray, folder: Path) -> Path:
    """``folder``: the capture's files (linked) with its light files replaced by these lights."""
    if (folder / DIRECTIONS).is_file():
        return folder
    with atomic_dir(folder, overwrite=True) as tmp:
        for item in capture.iterdir():
            if item.name not in (DIRECTIONS, INTENSITIES):
                (tmp / item.name).symlink_to(item.resolve())
        np.savetxt(tmp / DIRECTIONS, directions, fmt="%.9g")
        np.savetxt(tmp / INTENSITIES, intensities, fmt="%.9g")
    return folder


def lights_of(obj: scenes.BenchmarkObject, args) -> tuple[Path, np.ndarray, ...]:
    """The object's capture folder, its true directions and intensities, and the directions and
    intensities of its row in ``--uncal`` (``lights.txt``); directions (n, 3), intensities (n, 3)."""
    capture = scenes.make_captures(obj, args.data, args.cache)[args.lights]
    ended = np.loadtxt(args.uncal / f"{obj.name}-{args.method}" / "lights.txt", ndmin=2)
    return (capture, np.loadtxt(capture / DIRECTIONS, ndmin=2), np.loadtxt(capture / INTENSITIES, ndmin=2),
            ended[:, :3], ended[:, 3:])


def light_columns(true_directions, true_intensities, directions, intensities) -> list[float]:
    """Mean direction error (°), intensity error (:func:`intensity_error`) and its linear share."""
    cosines = np.clip(np.sum(directions * true_directions, 1), -1, 1)
    return [float(np.degrees(np.arccos(cosines)).mean()), intensity_error(intensities, true_intensities),
            linear_share(true_directions, intensities, true_intensities)]


def print_lights(args, found: list[scenes.BenchmarkObject]) -> None:
    """The light columns alone, per object, with their mean and median."""
    print(f"light benchmark objects, {args.lights} lights: "
          f"the lights of {args.uncal} (<object>-{args.method})")
    print(f"{'object':<12}{'dir err':>8}{'int err':>8}{'linear':>8}")
    table = []
    for obj in found:
        row = light_columns(*lights_of(obj, args)[1:])
        table.append(row)
        print(f"{obj.name:<12}{row[0]:>7.2f}°{row[1]:>8.3f}{row[2]:>8.2f}")
    for label, value in (("mean", np.mean(table, axis=0)), ("median", np.median(table, axis=0))):
        print(f"{label:<12}{value[0]:>7.2f}°{value[1]:>8.3f}{value[2]:>8.2f}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--uncal", type=Path, required=True,
                        help="a normals.py run folder made with estimated lights (method unps)")
    parser.add_argument("--gt", type=Path, default=None,
                        help="a normals.py run folder made with the true lights, same light set")
    parser.add_argument("--method", default="unps", help="the method of --uncal's rows (<object>-<method>/)")
    parser.add_argument("--lights-only", action="store_true",
                        help="only the lights' errors: no fit is run and --gt is not read")
    parser.add_argument("--lights", choices=list(scenes.LIGHT_SETS), default="96")
    parser.add_argument("--data", type=Path, default=normals.DEFAULT_DATA)
    parser.add_argument("--cache", type=Path, default=normals.DEFAULT_CACHE)
    parser.add_argument("--out", type=Path, default=None,
                        help="run folders (default: <cache>/light_parts/<lights>)")
    parser.add_argument("--names", nargs="+", default=None, help="objects (default: all of --uncal)")
    parser.add_argument("--set", dest="settings", nargs="*", default=[],
                        help="overrides for every fit, e.g. threads=1")
    args = parser.parse_args(argv)
    if args.gt is None and not args.lights_only:
        parser.error("--gt is needed unless --lights-only")
    found = [obj for obj in scenes.OBJECTS
             if (args.uncal / f"{obj.name}-{args.method}" / "lights.txt").is_file()
             and (args.lights_only or (args.gt / f"{obj.name}-unps" / "metrics.json").is_file())
             and (not args.names or obj.name in args.names)]
    if not found:
        sys.exit(f"no object has {args.uncal}/<object>-{args.method}/lights.txt"
                 + ("" if args.lights_only else f" and {args.gt}/<object>-unps/metrics.json")
                 + (f" among {args.names}" if args.names else ""))
    if args.lights_only:
        print_lights(args, found)
        return
    out = args.out or args.cache / "light_parts" / args.lights
    try:
        runs.claim(out, {"uncal": str(args.uncal.resolve()), "settings": args.settings})
    except ValueError as e:
        parser.error(str(e))

    print(normals.machine_line())
    print(f"\nlight benchmark objects, {args.lights} lights: the lights the uncalibrated fit ended with "
          f"({args.uncal}), taken apart (normal MAE °; light=gt with the files replaced)")
    print(f"{'object':<12}{'dir err':>8}{'int err':>8}{'linear':>8}{'true':>8}"
          + "".join(f"{p:>12}" for p in PARTS) + f"{'uncal':>8}")
    table = []
    for obj in found:
        capture, true_directions, true_intensities, directions, intensities = lights_of(obj, args)
        lights = {"directions": (directions, true_intensities),
                  "intensities": (true_directions, intensities),
                  "both": (directions, intensities)}
        errors = []
        for part in PARTS:
            folder = mixed_capture(capture, *lights[part], out / "captures" / f"{obj.name}-{part}")
            metrics = normals.run_row(folder, obj, "unps", "gt", args.settings, out / part)
            errors.append(metrics["normal_mae"])
        uncal = json.loads((args.uncal / f"{obj.name}-{args.method}" / "metrics.json").read_text())
        true = json.loads((args.gt / f"{obj.name}-unps" / "metrics.json").read_text())
        row = [*light_columns(true_directions, true_intensities, directions, intensities),
               true["normal_mae"], *errors, uncal["normal_mae"]]
        table.append(row)
        print(f"{obj.name:<12}{row[0]:>7.2f}°{row[1]:>8.3f}{row[2]:>8.2f}{row[3]:>7.2f}°"
              + "".join(f"{e:>11.2f}°" for e in errors) + f"{row[-1]:>7.2f}°", flush=True)
    for line in summary([obj.name for obj in found], np.array(table)):
        print(line)


if __name__ == "__main__":
    main()

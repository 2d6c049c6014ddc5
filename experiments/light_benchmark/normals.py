"""Calibrated normals on the light benchmark's objects: the fit where unps was never tuned.

    python experiments/light_benchmark/normals.py                       # 24 objects, 96 lights
    python experiments/light_benchmark/normals.py --set preset.prior_weight=0 --tag prior0
    python experiments/light_benchmark/normals.py --names blob03 goblet-a --methods unps
    python experiments/light_benchmark/normals.py --lights 12 --methods unps --tag sparse
    python experiments/light_benchmark/normals.py --light selfcal --methods unps --tag selfcal

The 24 objects of ``scenes.py`` (meshes and procedural shapes with cavities, thin parts and
self-shadowing; two or three held-out MERL materials each; cast shadows and interreflections;
8-bit ``floor`` / ``round`` or 16-bit storage with sensor noise), under their 96-light dome (or
their sparse set of 20 or 12 lights: ``--lights``), with their true lights (``light=gt``; or
uncalibrated, the lights estimated as a user's run estimates them: ``--light selfcal``, the
default of ``python -m unps.fit``, ``--light estimated``, the network and the reversal test, or
``--light refine``, those lights learnt with the surface in the fit, ``method=unps`` only):
Woodham's least squares, the robust initialisation and the fit
(``method=unps``, the default preset), each one ``python -m unps.fit`` run in its own process in
``<out>/<object>-<method>/`` (a rerun skips finished rows and resumes a killed fit). The captures
are rendered on first use into ``--cache``, as the light benchmark does. ``--set`` passes
overrides to every unps row (keep one ``--tag`` per setting). Printed: the mean angular error per
object and method, the fit's time, and the means; with estimated lights also each object's light
error and, stage by stage (the network, the reversal test, the self-calibration, the fit's own
step), the lights' mean direction error, its ratio to the network's and the objects the stage
left more than 1° / 2° worse (:func:`stage_lines`).

None of these objects, materials or shape seeds feeds training or was used to choose a default,
so they stand for captures unps has not seen: a setting that helps on ball, cat and pot1 should
help here too before it becomes a default.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np
import torch

from unps.errors import InputError

sys.path.insert(0, str(Path(__file__).resolve().parent))
import runs  # noqa: E402
import scenes  # noqa: E402

DEFAULT_DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
DEFAULT_CACHE = Path("~/.cache/unps/light_benchmark").expanduser()
METHODS = ("woodham", "rpca", "unps")
LIGHTS = ("gt", "estimated", "selfcal", "refine")


def run_row(folder: Path, obj: scenes.BenchmarkObject, method: str, light: str,
            settings: list[str], out: Path) -> dict:
    """One ``python -m unps.fit`` run; its metrics. Skipped when its metrics.json exists and the run
    was made with the settings this one would be (:func:`runs.stale_run`); a run finished or
    stopped part way under other settings is made again from nothing (:func:`runs.discard`), or,
    where only the preset's read-out settings differ, resumed from its checkpoint and read out
    again (:func:`runs.steps_kept`); refused while another process runs it (:func:`runs.held`)."""
    run_dir = out / f"{obj.name}-{method}"
    metrics = run_dir / "metrics.json"
    overrides = ["subject=folder", f"subject.root={folder}", f"subject.name={obj.name}",
                 f"subject.quantization={scenes.quantization(obj.storage)}", f"light={light}",
                 f"method={method}", *(settings if method == "unps" else [])]
    expected = runs.fit_settings(overrides)
    why = runs.stale_run(run_dir, expected) if runs.begun(run_dir) else None
    keep_steps = why is not None and runs.steps_kept(run_dir, expected)
    if why:
        print(f"  {obj.name} {method}: {'read out again' if keep_steps else 'run again'}, {why}", flush=True)
    if why or not metrics.is_file():
        command = [sys.executable, "-m", "unps.fit", *overrides, f"hydra.run.dir={run_dir}"]
        try:
            with runs.held(run_dir):
                print(f"  running {obj.name} {method}", flush=True)
                if why:
                    runs.clear(run_dir, keep_steps)
                done = subprocess.run(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                                      env={**os.environ, "HYDRA_FULL_ERROR": "1"})
        except RuntimeError as busy:
            sys.exit(str(busy))
        if done.returncode != 0:
            sys.exit(f"{' '.join(command)} failed:\n{done.stderr[-2000:]}")
    return json.loads(metrics.read_text())


def made_with(light: str, settings: list[str]) -> list[str]:
    """What a run folder records its rows as made with: the overrides; where the lights are
    estimated, the light first and the digest of the light-network weights last
    (:func:`runs.weights_digest` of ``light.checkpoint=``, else of the shipped weights), so that a
    rerun after new weights are shipped is refused rather than mixed. The folders of the true
    lights read as they always have.

    >>> made_with("gt", ["preset.width=96"])
    ['preset.width=96']
    >>> made = made_with("selfcal", []); made[0], made[-1].startswith("light-network weights ")
    ('light=selfcal', True)
    """
    if light == "gt":
        return list(settings)
    given = [s.split("=", 1)[1] for s in settings if s.startswith("light.checkpoint=")]
    return [f"light={light}", *settings,
            f"light-network weights {runs.weights_digest(given[-1] if given else None)}"]


def run_folder(cache: Path, tag: str, lights: str) -> Path:
    """Where a tag's runs go: ``<cache>/normals/<tag>`` for the dome, ``<tag>-<lights>`` for a
    sparse set, so that the same tag on another light set never reads the dome's rows."""
    return cache / "normals" / (tag if lights == "96" else f"{tag}-{lights}")


RAISED, RAISED_TWICE = 1.0, 2.0     # degrees, as benchmark.py flags a stage


def stage_lines(names: list[str], stages: list[list[dict]]) -> list[str]:
    """One line per light stage of the runs (``metrics.json`` ``light_stages``; ``stages[k]`` is
    object ``names[k]``'s, in the order the run took them, the fit's own step last where it learnt
    the lights): the mean direction error after it, its ratio to the network's, how many objects
    it left more than 1° and 2° above the stage before, and the worst such raise.

    >>> lines = stage_lines(["a", "b"], [[{"stage": "network", "light_dir_mae": 4.0},
    ...                                   {"stage": "fit", "light_dir_mae": 2.0}],
    ...                                  [{"stage": "network", "light_dir_mae": 6.0},
    ...                                   {"stage": "fit", "light_dir_mae": 7.5}]])
    >>> print("\\n".join(lines))
    stage       lights  ÷ network  >1° raises  >2° raises  worst raise
    network      5.00°       1.00           0           0
    fit          4.75°       0.95           1           0  +1.50° (b)
    """
    order = [stage["stage"] for stage in stages[0]]
    if any([stage["stage"] for stage in run] != order for run in stages):
        raise ValueError("the runs took different light stages: " + ", ".join(
            f"{name}: {[stage['stage'] for stage in run]}" for name, run in zip(names, stages)))
    errors = np.array([[stage["light_dir_mae"] for stage in run] for run in stages])   # (objects, stages)
    lines = [f"{'stage':<10}{'lights':>8}{'÷ network':>11}{'>1° raises':>12}{'>2° raises':>12}  worst raise"]
    for k, stage in enumerate(order):
        raises = errors[:, k] - errors[:, k - 1] if k else np.zeros(len(names))
        worst = int(np.argmax(raises))
        line = (f"{stage:<10}{errors[:, k].mean():>7.2f}°{errors[:, k].mean() / errors[:, 0].mean():>11.2f}"
                f"{int((raises > RAISED).sum()):>12}{int((raises > RAISED_TWICE).sum()):>12}")
        if raises[worst] > 0:
            line += f"  {raises[worst]:+.2f}° ({names[worst]})"
        lines.append(line)
    return lines


def storage_means(storages: list[str], errors: dict[str, list[float]]) -> list[str]:
    """One line per way of storing the captures (8-bit ``floor`` / ``round``, 16-bit): each
    method's mean error over the objects stored so, ``errors[method][k]`` being object k's, which
    is stored as ``storages[k]``. The 8-bit ones can be black in every image over much of a dark
    material, which the 16-bit ones never are.

    >>> storage_means(["png16", "floor8", "png16"], {"rpca": [1.0, 5.0, 2.0]})
    ['mean, png16 (2)             1.50°', 'mean, floor8 (1)            5.00°']
    """
    lines = []
    for kind in dict.fromkeys(storages):
        picked = [k for k, s in enumerate(storages) if s == kind]
        label = f"mean, {kind} ({len(picked)})"
        lines.append(f"{label:<24}" + "".join(f"{np.mean([e[k] for k in picked]):>8.2f}°"
                                              for e in errors.values()))
    return lines


def machine_line() -> str:
    """The line a table of runs starts with: the machine, its cores, the vector instructions
    torch's CPU kernels use (AVX2, AVX512…: they set a fit's speed) and torch."""
    device = "CUDA" if torch.cuda.is_available() else f"CPU ({torch.backends.cpu.get_cpu_capability()})"
    return f"machine: {platform.machine()}, {os.cpu_count()} cores, {device}; torch {torch.__version__}"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    parser.add_argument("--out", type=Path, default=None,
                        help="run folders (default: <cache>/normals/<tag>, <tag>-<lights> for a sparse set)")
    parser.add_argument("--tag", default="default", help="names the run folder")
    parser.add_argument("--lights", choices=list(scenes.LIGHT_SETS), default="96",
                        help="the light set: the dome (96) or a sparse rig (20, 12)")
    parser.add_argument("--light", choices=LIGHTS, default="gt",
                        help="the true lights, or estimated as unps.fit estimates them")
    parser.add_argument("--names", nargs="+", default=None, help="objects (default: all 24)")
    parser.add_argument("--methods", nargs="+", choices=METHODS, default=list(METHODS))
    parser.add_argument("--set", dest="settings", nargs="*", default=[],
                        help="overrides for every unps row, e.g. preset.prior_weight=0")
    args = parser.parse_args(argv)
    if not (args.data / "meshes").is_dir():
        sys.exit(f"{args.data}: the shared data (meshes, MERL fits) not found")
    known = {o.name for o in scenes.OBJECTS}
    unknown = sorted(set(args.names or ()) - known)
    if unknown:
        sys.exit(f"--names: {', '.join(unknown)} not among the objects ({', '.join(sorted(known))})")
    if args.light == "refine" and set(args.methods) != {"unps"}:
        parser.error("--light refine learns the lights in the fit: it needs --methods unps")
    out = args.out or run_folder(args.cache, args.tag, args.lights)
    try:
        runs.claim(out, made_with(args.light, args.settings))
    except (ValueError, InputError) as e:
        parser.error(str(e))

    print(machine_line())
    print(f"\nlight benchmark objects, {args.lights} lights, light={args.light}"
          f"{' ' + ' '.join(args.settings) if args.settings else ''} (normal MAE °)")
    header = f"{'object':<16}{'storage':>8}" + "".join(f"{m:>9}" for m in args.methods)
    estimated = args.light != "gt"
    print(header + (f"{'fit s':>8}" if "unps" in args.methods else "")
          + (f"{'lights':>9}" if estimated else ""))
    errors: dict[str, list[float]] = {m: [] for m in args.methods}
    light_errors: list[float] = []
    light_stages: list[list[dict]] = []
    names: list[str] = []
    storages: list[str] = []
    for obj in scenes.OBJECTS:
        if args.names and obj.name not in args.names:
            continue
        folder = scenes.make_captures(obj, args.data, args.cache)[args.lights]
        rows = {m: run_row(folder, obj, m, args.light, args.settings, out) for m in args.methods}
        storages.append(obj.storage)
        line = f"{obj.name:<16}{obj.storage:>8}"
        for method, metrics in rows.items():
            errors[method].append(metrics["normal_mae"])
            line += f"{metrics['normal_mae']:>8.2f}°"
        if "unps" in rows:
            line += f"{rows['unps']['runtime_s']:>8.0f}"
        names.append(obj.name)
        if estimated:  # every method's run estimates the same lights; the first one's error
            light_errors.append(next(iter(rows.values()))["light_dir_mae"])
            light_stages.append(rows.get("unps", next(iter(rows.values())))["light_stages"])
            line += f"{light_errors[-1]:>8.2f}°"
        print(line, flush=True)
    print(f"{'mean':<24}" + "".join(f"{np.mean(e):>8.2f}°" for e in errors.values())
          + ((f"{'':>8}" if "unps" in args.methods else "") + f"{np.mean(light_errors):>8.2f}°"
             if estimated else ""))
    for line in storage_means(storages, errors):
        print(line)
    if estimated:
        print(f"\nthe lights after each stage{' (unps: the fit learns them last)' if 'unps' in rows else ''}")
        for line in stage_lines(names, light_stages):
            print(line)
    if "unps" in errors and len(args.methods) > 1:
        for method in (m for m in args.methods if m != "unps"):
            better = sum(u < b for u, b in zip(errors["unps"], errors[method]))
            print(f"unps below {method} on {better} of {len(errors['unps'])} objects")


if __name__ == "__main__":
    main()

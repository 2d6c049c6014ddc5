"""Neural inverse rendering (method=unps) against the baselines, on DiLiGenT and synthetic subjects.

    python experiments/neural_inverse_rendering/benchmark.py [--out runs/nir] [--preset fast]
    python experiments/neural_inverse_rendering/benchmark.py --only diligent --preset paper
    python experiments/neural_inverse_rendering/benchmark.py --only diligent --objects ball --lights gt
    python experiments/neural_inverse_rendering/benchmark.py --seeds 0 1 --set preset.input_noise_var=0.3 \
        --out runs/nir-noise0.3

Every row is one `python -m unps.fit` run in its own process, in `<out>/<row>/` (a rerun skips
rows whose metrics.json exists, and a killed row resumes from its checkpoint, after checking that
Hydra recorded the same overrides); peak memory is the process's maximum resident set. ``--set``
passes overrides to every unps row (keep one ``--out`` per setting), and ``--seeds`` fits every
unps row once per seed, printing the mean and each seed's figure. Tables printed:

- DiLiGenT (ball full resolution, cat and pot1 crops read as floor by subject=<name>; 96 images):
  unps with the shipped light network's estimate, self-calibrated (light=selfcal), refined
  with the surface (light=refine), and
  with the ground-truth lights, next to the robust initialisation with the same (starting)
  lights and the paper's published uncalibrated figures; "light °" is the direction error of
  the lights unps used;
- synthetic Vase, BrokenPot, Tablet1 with ground-truth lights: Woodham, the Nayar baseline, and
  unps with interreflection=nayar and interreflection=off;
- seconds per step of preset=paper on this machine (``--paper-steps`` steps on pot1).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
from pathlib import Path

import torch
from omegaconf import OmegaConf

from unps.paper import PAPER_MAE

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "light_benchmark"))
import runs  # noqa: E402

DILIGENT = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "DiLiGenT"
OBJECTS = ("ball", "cat", "pot1")
PAPER = PAPER_MAE["estimated"]                          # the paper's uncalibrated MAE (°)
LIGHTS = ["estimated", "selfcal", "refine", "gt"]
SYNTHETIC = ["Vase", "BrokenPot", "Tablet1"]           # the paper's three; the other five on request
ALL_SYNTHETIC = [*SYNTHETIC, "Face", "Golf-ball", "Rose", "Sphere", "Tablet2"]


def run(out: Path, *overrides: str) -> dict:
    """One `unps.fit` in a fresh process; its metrics.json plus ``peak_rss_gb``.

    A finished row is read, not refitted, and a killed one resumed, only if Hydra recorded it with
    these overrides; a finished or killed row made with other settings than these overrides give now (a
    default changed since, :func:`runs.stale_run`) is made again from nothing (:func:`runs.discard`),
    or, where only the preset's read-out settings differ, resumed from its checkpoint and read out
    again (:func:`runs.steps_kept`), and says so.
    """
    metrics = out / "metrics.json"
    recorded = out / ".hydra" / "overrides.yaml"
    if recorded.is_file():
        done_with, wanted = set(OmegaConf.load(recorded)), set(overrides)
        if done_with != wanted:
            raise ValueError(f"{out} was run with other overrides: it lacks {sorted(wanted - done_with)} "
                             f"and has {sorted(done_with - wanted)}; give this setting its own --out")
    expected = runs.fit_settings(list(overrides))
    why = runs.stale_run(out, expected) if runs.begun(out) else None
    if why:
        keep_steps = runs.steps_kept(out, expected)
        print(f"  {out.name}: {'read out again' if keep_steps else 'run again'}, {why}", flush=True)
        runs.clear(out, keep_steps)
    if not metrics.is_file():
        code = ("import atexit, json, resource, sys, runpy\n"
                f"atexit.register(lambda: open({str(out / 'peak_rss_kb')!r}, 'w').write("
                "str(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)))\n"
                "sys.argv = ['unps.fit'] + sys.argv[1:]\n"
                "runpy.run_module('unps.fit', run_name='__main__')\n")
        print(f"  running {out.name}: {' '.join(overrides)}", flush=True)
        done = subprocess.run([sys.executable, "-c", code, *overrides, f"hydra.run.dir={out}"],
                              capture_output=True, text=True)
        if done.returncode != 0:
            raise RuntimeError(f"{out.name} failed:\n{done.stderr[-3000:]}")
    result = json.loads(metrics.read_text())
    rss = out / "peak_rss_kb"
    result["peak_rss_gb"] = int(rss.read_text()) / 2**20 if rss.is_file() else float("nan")
    return result


def unps_rows(out: Path, row: str, overrides: list[str], seeds: list[int]) -> list[dict]:
    """One unps fit per seed: ``<row>`` for seed 0, ``<row>-seed<k>`` otherwise."""
    return [run(out / (row if seed == 0 else f"{row}-seed{seed}"), *overrides, f"seed={seed}")
            for seed in seeds]


def mae(results: list[dict]) -> str:
    """Mean normal MAE over seeds, followed by each seed's when there are several."""
    values = [r["normal_mae"] for r in results]
    text = f"{sum(values) / len(values):.2f}"
    return text if len(values) == 1 else f"{text} ({' / '.join(f'{v:.2f}' for v in values)})"


def diligent_subject(name: str, data: Path) -> list[str]:
    """The object by name in the DiLiGenT folder ``data``, so that the crops are read the way they
    were made (quantization=auto)."""
    return [f"subject={name}", f"paths.diligent_dir={data}"]


def diligent(out: Path, data: Path, preset: str, objects: list[str], lights: list[str],
             extra: list[str], seeds: list[int]) -> None:
    print(f"\nDiLiGenT, 96 images, preset={preset} {' '.join(extra)} (normal MAE °; unps time and peak "
          f"memory of the first seed)")
    print(f"{'object':<6} {'light':<9} {'light °':>7} {'RPCA °':>7} {'paper °':>7} {'grid':>9} {'s':>6} "
          f"{'s/step':>6} {'GB':>5}  unps °")
    for name in objects:
        subject = diligent_subject(name, data)
        for light in lights:
            start = "estimated" if light == "refine" else light     # the lights refinement starts from
            rpca = run(out / f"{name}-{start}-rpca", *subject, f"light={start}", "method=rpca")
            fits = unps_rows(out, f"{name}-{light}-unps-{preset}",
                             [*subject, f"light={light}", "method=unps", f"preset={preset}", *extra], seeds)
            unps = fits[0]
            h, w = unps["fit_resolution"]
            print(f"{name:<6} {light:<9} {unps.get('light_dir_mae', 0):7.2f} {rpca['normal_mae']:7.2f} "
                  f"{PAPER[name] if light != 'gt' else '':>7} {f'{w}×{h}':>9} {unps['runtime_s']:6.0f} "
                  f"{unps['fit_s_per_step']:6.3f} {unps['peak_rss_gb']:5.2f}  {mae(fits)}", flush=True)


def synthetic(out: Path, preset: str, extra: list[str], seeds: list[int], subjects: list[str],
              models: list[str]) -> None:
    print(f"\nSynthetic subjects, ground-truth lights, preset={preset} {' '.join(extra)} (normal MAE °)")
    print(f"{'subject':<10} {'Woodham':>8} {'Nayar':>8} {'s':>6}  {' | '.join(f'unps {m}' for m in models)}")
    for name in subjects:
        common = [f"subject={name}", "light=gt"]
        woodham = run(out / f"{name}-woodham", *common, "method=woodham")
        nayar = run(out / f"{name}-nayar", *common, "method=nayar")
        unps = [*common, "method=unps", f"preset={preset}", *extra]
        fits = [unps_rows(out, f"{name}-unps-{preset}-{m}", [*unps, f"interreflection={m}"], seeds)
                for m in models]
        print(f"{name:<10} {woodham['normal_mae']:8.2f} {nayar['normal_mae']:8.2f} "
              f"{fits[-1][0]['runtime_s']:6.0f}  {' | '.join(mae(f) for f in fits)}", flush=True)


def paper_speed(out: Path, data: Path, steps: int) -> None:
    subject = diligent_subject("pot1", data)
    result = run(out / f"pot1-paper-{steps}steps", *subject, "light=gt", "method=unps", "preset=paper",
                 f"preset.steps={steps}")
    h, w = result["fit_resolution"]
    print(f"\npreset=paper on pot1 ({w}×{h}, {result['parameters'] / 1e6:.2f} M parameters): "
          f"{result['fit_s_per_step']:.2f} s/step over {steps} steps, peak {result['peak_rss_gb']:.2f} GB "
          f"→ {result['fit_s_per_step'] * 1000 / 60:.0f} min for 1000 steps")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=Path("runs/neural_inverse_rendering"))
    parser.add_argument("--preset", default="fast")
    parser.add_argument("--diligent", type=Path, default=DILIGENT,
                        help="the folder holding pmsData/ or pmsData_crop/ (default: ../shared/data/DiLiGenT "
                             "beside the repository)")
    parser.add_argument("--only", choices=["diligent", "synthetic", "speed"])
    parser.add_argument("--paper-steps", type=int, default=5)
    parser.add_argument("--objects", nargs="+", choices=OBJECTS, default=list(OBJECTS),
                        help="DiLiGenT objects (all three by default)")
    parser.add_argument("--lights", nargs="+", choices=LIGHTS, default=LIGHTS,
                        help="DiLiGenT light modes (all three by default)")
    parser.add_argument("--subjects", nargs="+", choices=ALL_SYNTHETIC, default=SYNTHETIC,
                        help="synthetic subjects (the paper's three by default)")
    parser.add_argument("--interreflection", nargs="+", choices=["off", "nayar"], default=["off", "nayar"],
                        help="interreflection models of the synthetic rows (both by default)")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0], help="seeds of every unps row")
    parser.add_argument("--set", nargs="+", default=[], metavar="KEY=VALUE",
                        help="Hydra overrides for every unps row, e.g. preset.input_noise_var=0.3")
    args = parser.parse_args()
    device = (torch.cuda.get_device_name() if torch.cuda.is_available()
              else f"CPU ({torch.backends.cpu.get_cpu_capability()})")
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, {device}; "
          f"torch {torch.__version__}")
    if args.only in (None, "diligent"):
        if not args.diligent.is_dir():
            sys.exit(f"{args.diligent}: DiLiGenT not found (give --diligent, or put ../shared/data "
                     f"beside the repository)")
        diligent(args.out, args.diligent, args.preset, args.objects, args.lights, args.set, args.seeds)
    if args.only in (None, "synthetic"):
        synthetic(args.out, args.preset, args.set, args.seeds, args.subjects, args.interreflection)
    if args.only in (None, "speed"):
        paper_speed(args.out, args.diligent, args.paper_steps)


if __name__ == "__main__":
    main()

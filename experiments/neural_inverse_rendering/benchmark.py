"""Neural inverse rendering (method=unps) against the baselines, on DiLiGenT and synthetic subjects.

    python experiments/neural_inverse_rendering/benchmark.py [--out runs/nir] [--preset fast]
    python experiments/neural_inverse_rendering/benchmark.py --only diligent --preset paper
    python experiments/neural_inverse_rendering/benchmark.py --only diligent --objects ball --lights gt

Every row is one `python -m unps.fit` run in its own process, in `<out>/<row>/` (a rerun skips
rows whose metrics.json exists, and a killed row resumes from its checkpoint); peak memory is the
process's maximum resident set. Tables printed:

- DiLiGenT (ball full resolution, cat and pot1 crops read as floor by subject=<name>; 96 images):
  unps with the shipped light network's estimate, with those lights refined (light=refine), and
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

DILIGENT = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "DiLiGenT"
OBJECTS = ("ball", "cat", "pot1")
PAPER = {"ball": 3.78, "cat": 7.91, "pot1": 8.75}       # the paper's uncalibrated MAE (°)
LIGHTS = ["estimated", "refine", "gt"]
SYNTHETIC = ["Vase", "BrokenPot", "Tablet1"]


def run(out: Path, *overrides: str) -> dict:
    """One `unps.fit` in a fresh process; its metrics.json plus ``peak_rss_gb``."""
    metrics = out / "metrics.json"
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


def diligent_subject(name: str) -> list[str]:
    """The object by name, so that the crops are read the way they were made (quantization=auto)."""
    return [f"subject={name}", f"paths.diligent_dir={DILIGENT}"]


def diligent(out: Path, preset: str, objects: list[str], lights: list[str]) -> None:
    print(f"\nDiLiGenT, 96 images, preset={preset} (normal MAE °; unps time and peak memory)")
    print(f"{'object':<6} {'light':<9} {'light °':>7} {'RPCA °':>7} {'unps °':>7} {'paper °':>7} "
          f"{'grid':>9} {'s':>6} {'s/step':>6} {'GB':>5}")
    for name in objects:
        subject = diligent_subject(name)
        for light in lights:
            start = "estimated" if light == "refine" else light     # the lights refinement starts from
            rpca = run(out / f"{name}-{start}-rpca", *subject, f"light={start}", "method=rpca")
            unps = run(out / f"{name}-{light}-unps-{preset}", *subject, f"light={light}", "method=unps",
                       f"preset={preset}")
            h, w = unps["fit_resolution"]
            print(f"{name:<6} {light:<9} {unps.get('light_dir_mae', 0):7.2f} {rpca['normal_mae']:7.2f} "
                  f"{unps['normal_mae']:7.2f} {PAPER[name] if light != 'gt' else '':>7} "
                  f"{f'{w}×{h}':>9} {unps['runtime_s']:6.0f} {unps['fit_s_per_step']:6.3f} "
                  f"{unps['peak_rss_gb']:5.2f}", flush=True)


def synthetic(out: Path, preset: str) -> None:
    print(f"\nSynthetic subjects, ground-truth lights, preset={preset} (normal MAE °)")
    print(f"{'subject':<10} {'Woodham':>8} {'Nayar':>8} {'unps off':>8} {'unps nayar':>10} {'s':>6}")
    for name in SYNTHETIC:
        common = [f"subject={name}", "light=gt"]
        woodham = run(out / f"{name}-woodham", *common, "method=woodham")
        nayar = run(out / f"{name}-nayar", *common, "method=nayar")
        off = run(out / f"{name}-unps-{preset}-off", *common, "method=unps", f"preset={preset}",
                  "interreflection=off")
        on = run(out / f"{name}-unps-{preset}-nayar", *common, "method=unps", f"preset={preset}",
                 "interreflection=nayar")
        print(f"{name:<10} {woodham['normal_mae']:8.2f} {nayar['normal_mae']:8.2f} "
              f"{off['normal_mae']:8.2f} {on['normal_mae']:10.2f} {on['runtime_s']:6.0f}", flush=True)


def paper_speed(out: Path, steps: int) -> None:
    subject = diligent_subject("pot1")
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
    parser.add_argument("--only", choices=["diligent", "synthetic", "speed"])
    parser.add_argument("--paper-steps", type=int, default=5)
    parser.add_argument("--objects", nargs="+", choices=OBJECTS, default=list(OBJECTS),
                        help="DiLiGenT objects (all three by default)")
    parser.add_argument("--lights", nargs="+", choices=LIGHTS, default=LIGHTS,
                        help="DiLiGenT light modes (all three by default)")
    args = parser.parse_args()
    device = torch.cuda.get_device_name() if torch.cuda.is_available() else "CPU"
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, {device}; "
          f"torch {torch.__version__}")
    if args.only in (None, "diligent"):
        if not DILIGENT.is_dir():
            sys.exit(f"{DILIGENT}: DiLiGenT not found (../shared/data beside the repository)")
        diligent(args.out, args.preset, args.objects, args.lights)
    if args.only in (None, "synthetic"):
        synthetic(args.out, args.preset)
    if args.only in (None, "speed"):
        paper_speed(args.out, args.paper_steps)


if __name__ == "__main__":
    main()

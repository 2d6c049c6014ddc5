"""How unps uses one GPU: the paper preset's fit, the default command, training throughput, memory.

    python experiments/gpu/run.py                          # on a CUDA machine, about 5 minutes
    python experiments/gpu/run.py --device cpu --steps 5 --train-steps 2 --subjects lambertian \
        --default-subject lambertian --render-samples 4   # the same rows on a CPU, as a smoke test

Rows, each a fresh process (``python -m unps.fit`` / ``python -m unps.train``) in ``<out>/<row>``:

- ``paper-<subject>``: ``preset=paper light=gt`` (full resolution; ``--steps`` steps): fit seconds,
  its stages (steps, interreflection update, cast shadows, read-out), the normal MAE, peak GPU memory;
- ``default-<subject>``: the default uncalibrated command (``light=selfcal preset=fast``): wall
  seconds of the whole command, and its stages (light network, self-calibration, fit);
- ``train``: ``python -m unps.train recipe=paper`` for ``--train-steps`` steps, the training data
  rendered on the device: samples per second over the run (start-up and a small validation
  included) and once running (after its first steps, validations left out), and peak GPU
  memory; and the training data's two halves alone: its random draws (CPU, one process; the
  ``recipe.workers`` processes share them out) and their rendering on the device, one sample at
  a time.

Subjects are ``subject=`` names (DiLiGenT objects read from ``--diligent``, the folder holding
``pmsData/`` or ``pmsData_crop/``). A rerun skips rows whose
metrics.json exists.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import torch

DILIGENT = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "DiLiGenT"
FIT_STAGES = ("steps", "interreflection update", "cast shadows", "read-out", "robust initialisation")
DEFAULT_STAGES = ("light network", "self-calibration", "method")


def machine(device: str) -> str:
    """The GPU (or CPU) this script measures, with torch."""
    if device.startswith("cuda") and torch.cuda.is_available():
        name = torch.cuda.get_device_name(torch.device(device if ":" in device else "cuda:0"))
    else:
        name = platform.processor() or platform.machine()
    return f"{name}; {os.cpu_count()} CPU cores; torch {torch.__version__}"


def run(out: Path, module: str, *overrides: str) -> tuple[dict, float]:
    """``python -m <module> overrides…`` in a fresh process; its metrics.json and wall seconds (0 when
    the row was already there)."""
    metrics = out / "metrics.json"
    if metrics.is_file():
        return json.loads(metrics.read_text()), 0.0
    command = [sys.executable, "-m", module, *overrides, f"hydra.run.dir={out}"]
    print("  running", " ".join(command[2:]), flush=True)
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed:\n{done.stderr[-3000:]}")
    return json.loads(metrics.read_text()), seconds


def memory(metrics: dict) -> str:
    peak = metrics.get("gpu_peak_gb")
    return "–" if peak is None else f"{peak:.1f}"


def subject_overrides(name: str, diligent: Path) -> list[str]:
    return [f"subject={name}", f"paths.diligent_dir={diligent}"]


def data_rates(device: str, samples: int) -> tuple[float, float]:
    """Samples per second of the two halves of ``recipe=paper``'s training data on this machine:
    drawing (the CPU part, in one process; the workers share it out) and rendering the draws on
    ``device`` one sample at a time (the first, which starts CUDA, not timed)."""
    from hydra import compose, initialize_config_module

    from unps.device import resolve_device
    from unps.lightnet.data import LightData
    from unps.lightnet.synthesis import render

    with initialize_config_module("unps.conf", version_base="1.3"):
        cfg = compose("train", overrides=["recipe=paper"])
    where = resolve_device(device)
    data = LightData(cfg.recipe, cfg.data, cfg.seed, device=where)
    data.setup("fit")
    start = time.perf_counter()
    scenes = [data.train_set.draw(index) for index in range(samples + 1)]
    drawing = (samples + 1) / (time.perf_counter() - start)
    render(scenes.pop(), where)
    if where.type == "cuda":
        torch.cuda.synchronize(where)
    start = time.perf_counter()
    for scene in scenes:
        render(scene, where)
    if where.type == "cuda":
        torch.cuda.synchronize(where)
    return drawing, samples / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", default="cuda")
    parser.add_argument("--out", type=Path, default=Path("runs/gpu"))
    parser.add_argument("--subjects", nargs="+", default=["cat", "pot1"])
    parser.add_argument("--default-subject", default="cat", help="the subject of the default command")
    parser.add_argument("--steps", type=int, default=1000, help="steps of the paper-preset fits")
    parser.add_argument("--train-steps", type=int, default=100)
    parser.add_argument("--render-samples", type=int, default=64)
    parser.add_argument("--diligent", type=Path, default=DILIGENT)
    args = parser.parse_args()
    device = [f"device={args.device}"]
    print(f"machine: {machine(args.device)}\n", flush=True)

    print("| row | seconds | normal MAE ° | peak GPU GB | where the time goes (s) |")
    print("|---|---|---|---|---|")
    schedule = [f"preset.steps={args.steps}", f"preset.lr_drop_at={max(1, args.steps * 9 // 10)}"]
    for name in args.subjects:
        metrics, _ = run(args.out / f"paper-{name}", "unps.fit", *subject_overrides(name, args.diligent),
                         "preset=paper", "light=gt", *schedule, *device)
        stages = metrics["stage_seconds"]
        spent = ", ".join(f"{k} {stages[k]:.1f}" for k in FIT_STAGES if k in stages)
        print(f"| paper preset, {name}, {args.steps} steps (fit) | {metrics['runtime_s']:.1f} | "
              f"{metrics.get('normal_mae', float('nan')):.2f} | {memory(metrics)} | {spent} |", flush=True)

    name = args.default_subject
    metrics, wall = run(args.out / f"default-{name}", "unps.fit", *subject_overrides(name, args.diligent),
                        *device)
    stages = metrics["stage_seconds"]
    spent = ", ".join(f"{k} {stages[k]:.1f}" for k in DEFAULT_STAGES if k in stages)
    print(f"| default command, {name} (whole command) | {wall:.1f} | "
          f"{metrics.get('normal_mae', float('nan')):.2f} | {memory(metrics)} | {spent} |", flush=True)

    steps = args.train_steps
    metrics, _ = run(args.out / "train", "unps.train", "recipe=paper", f"recipe.max_steps={steps}",
                     f"recipe.val_every={steps}", "recipe.val_samples=64", *device)
    overall = metrics["steps"] * 32 / metrics["train_seconds"]
    running = metrics.get("train_samples_per_s")
    running = "–" if running is None else f"{running:.1f}"
    print(f"| training, recipe=paper, {steps} steps of 32 | {metrics['train_seconds']:.1f} | – | "
          f"{memory(metrics)} | {overall:.1f} samples/s over the run (start-up and a validation of 64 "
          f"included), {running} once running |", flush=True)
    drawing, rendering = data_rates(args.device, args.render_samples)
    print(f"| training data alone: draws in one CPU process, rendering on {args.device} | – | – | – | "
          f"{drawing:.1f} and {rendering:.1f} samples/s |", flush=True)


if __name__ == "__main__":
    main()

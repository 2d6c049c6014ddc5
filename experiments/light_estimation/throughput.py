"""Training throughput of the light network on this CPU: each candidate speed-up measured alone.

    python experiments/light_estimation/throughput.py                 # the recipe=cpu sizes
    python experiments/light_estimation/throughput.py --steps 20 --batch 8 16 32
    python experiments/light_estimation/throughput.py --pipeline 27cc432   # whole runs, before and now

Prints, for fixed pre-generated batches of the CPU recipe (64 px, 16 images, width 32), the
training step (forward, backward, Adam) in samples per second, with the floating-point operations
one sample's forward and backward pass takes and the rate they run at against a large float32
matrix product on the same threads, for: the extractor's late strides (``recipe=cpu``'s) on
contiguous tensors (as trained before 2026-11-24) and channels-last (as it is), and LCNet's
strides (``light=mimo``'s, the paper's); then, with the late strides, bf16 autocast,
``torch.compile`` (inductor; its compile time apart) and larger batches; and the data
generation in samples per second on one core, for the old data (blobs, cap of lights,
perturbation) and the new (every shape family and light layout, the simulated camera).

With ``--pipeline <rev>``, whole ``python -m unps.train`` runs instead (``--run-steps`` steps of
the CPU recipe, no validation), from the code at ``<rev>`` with its data and from this checkout
with the new data, at the recipe's data worker and thread settings and at the alternatives; it
prints samples per second of the whole run (data, step, logging and checkpoints).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from unittest import mock

import torch
import torch.nn.functional as F
from torch.utils.flop_counter import FlopCounterMode

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "speed"))
from compare import worktree  # noqa: E402
from stages import machine  # noqa: E402

from unps.lightnet.bins import encode_lights
from unps.lightnet import network
from unps.lightnet.network import LATE_STRIDES, LCNET_STRIDES, LightNet
from unps.lightnet.rig import LAYOUTS, Camera
from unps.lightnet.shapes import SHAPES
from unps.lightnet.synthesis import LightDataset

KEYS = ("azimuth", "elevation", "intensity")


def batches(dataset: LightDataset, size: int, count: int) -> list[dict]:
    return [torch.utils.data.default_collate([dataset[i * size + j] for j in range(size)])
            for i in range(count)]


def step_rate(net: torch.nn.Module, data: list[dict], autocast: bool = False) -> float:
    """Training samples per second over ``data`` (after one warm-up step)."""
    optimizer = torch.optim.Adam(net.parameters(), 5e-4)

    def one(batch):
        context = torch.autocast("cpu", torch.bfloat16) if autocast else contextlib.nullcontext()
        with context:
            logits = net(batch["images"], batch["mask"])
        targets = encode_lights(batch["directions"], batch["intensities"])
        loss = sum(F.cross_entropy(logits[k].float().flatten(0, 1), t.flatten())
                   for k, t in zip(KEYS, targets))
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()

    one(data[0])
    start = time.perf_counter()
    for batch in data[1:]:
        one(batch)
    return sum(len(b["images"]) for b in data[1:]) / (time.perf_counter() - start)


def flops_per_sample(net: torch.nn.Module, batch: dict) -> float:
    """Floating-point operations of one training sample's forward and backward pass."""
    with FlopCounterMode(display=False) as counter:
        logits = net(batch["images"], batch["mask"])
        sum(value.sum() for value in logits.values()).backward()
    net.zero_grad()
    return counter.get_total_flops() / len(batch["images"])


def matmul_rate(size: int = 2048, repeats: int = 10) -> float:
    """FLOP/s of a large float32 matrix product on this process's threads: what these cores
    reach at best, the yardstick for the network's step."""
    a, b = torch.rand(size, size), torch.rand(size, size)
    a @ b
    start = time.perf_counter()
    for _ in range(repeats):
        a @ b
    return 2 * size ** 3 * repeats / (time.perf_counter() - start)


def data_rate(dataset: LightDataset, count: int) -> float:
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    start = time.perf_counter()
    for i in range(count):
        dataset[i]
    torch.set_num_threads(threads)
    return count / (time.perf_counter() - start)


REPO = Path(__file__).resolve().parents[2]
SETTINGS = {"recipe (no data worker, 2 threads)": [],
            "1 data worker, 2 threads": ["recipe.workers=1"],
            "1 data worker, 1 thread": ["recipe.workers=1", "recipe.threads=1"],
            "LCNet's strides": ["light.strides=[2,2,1,2,1,2,1]"]}


def run_rate(source: Path, steps: int, overrides: list[str]) -> float:
    """Samples per second of one ``python -m unps.train`` run of ``steps`` steps from ``source``."""
    with tempfile.TemporaryDirectory() as out:
        command = [sys.executable, "-m", "unps.train", f"hydra.run.dir={out}", f"recipe.max_steps={steps}",
                   f"recipe.val_every={steps}", "recipe.val_samples=8", "recipe.max_time=null", *overrides]
        done = subprocess.run(command, cwd=source, env={**os.environ, "PYTHONPATH": str(source)},
                              capture_output=True, text=True)
        if done.returncode:
            raise SystemExit(f"{' '.join(command)} (from {source}) failed:\n{done.stderr[-2000:]}")
        metrics = json.loads((Path(out) / "metrics.json").read_text())
    return metrics["steps"] * 8 / metrics["train_seconds"]


def pipeline(before: str, steps: int) -> None:
    old = worktree(before, Path(tempfile.gettempdir()) / "unps-throughput")
    print(f"whole training runs, {steps} steps of 8 samples (64 px, 16 images, width 32):")
    print(f"  {before} (blobs, contiguous), recipe   {run_rate(old, steps, []):6.1f} samples/s")
    for label, overrides in SETTINGS.items():
        rate = run_rate(REPO, steps, overrides)
        print(f"  now (new data, channels-last), {label:<34} {rate:6.1f} samples/s", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=12)
    parser.add_argument("--batch", type=int, nargs="+", default=[8, 16, 32])
    parser.add_argument("--width", type=int, default=32)
    parser.add_argument("--resolution", type=int, default=64)
    parser.add_argument("--images", type=int, default=16)
    parser.add_argument("--pipeline", metavar="REV", help="time whole runs against this revision")
    parser.add_argument("--run-steps", type=int, default=200)
    args = parser.parse_args()
    print(f"machine: {machine()}")
    if args.pipeline:
        pipeline(args.pipeline, args.run_steps)
        return
    common = dict(resolution=args.resolution, images=args.images, seed=11)
    old = LightDataset(10_000, **common)
    new = LightDataset(10_000, shapes=dict.fromkeys(SHAPES, 1.0), layouts=dict.fromkeys(LAYOUTS, 1.0),
                       camera=Camera(), **common)
    print(f"data, one core: old {data_rate(old, 24):.1f} samples/s, new {data_rate(new, 24):.1f} samples/s")
    data = batches(old, args.batch[0], args.steps)

    def fresh(strides=LATE_STRIDES):
        torch.manual_seed(0)
        return LightNet(args.width, 64, strides)

    peak = matmul_rate()

    def measured(label: str, net: torch.nn.Module) -> None:
        rate, flops = step_rate(net, data), flops_per_sample(net, data[0])
        print(f"  {label:<31} {rate:7.1f} samples/s; {flops / 1e9:.2f} GFLOP per sample at "
              f"{rate * flops / 1e9:.0f} GFLOP/s, {rate * flops / peak:.0%} of a 2048² float32 matrix "
              f"product's {peak / 1e9:.0f} GFLOP/s")

    print(f"step, batch {args.batch[0]} ({args.resolution} px, {args.images} images, width {args.width}):")
    with mock.patch.object(network, "channels_last", lambda x: x):
        measured("late strides, contiguous", fresh())
    measured("late strides, channels-last", fresh())
    measured("LCNet's strides, channels-last", fresh(LCNET_STRIDES))
    print(f"  bf16 autocast                   {step_rate(fresh(), data, autocast=True):7.1f} samples/s")
    compiled = torch.compile(fresh())
    start = time.perf_counter()
    step_rate(compiled, data[:2])
    compile_s = time.perf_counter() - start
    rate = step_rate(compiled, data)
    print(f"  torch.compile                   {rate:7.1f} samples/s (compiling took {compile_s:.0f} s)")
    for size in args.batch[1:]:
        rate = step_rate(fresh(), batches(old, size, max(3, args.steps * args.batch[0] // size)))
        print(f"  batch {size:<25} {rate:7.1f} samples/s")


if __name__ == "__main__":
    main()

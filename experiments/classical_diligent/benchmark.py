"""Classical solvers on real DiLiGenT: Woodham and the robust initialisation, with the given lights.

    python experiments/classical_diligent/benchmark.py [--data ../shared/data/DiLiGenT] [--repeats 3]

Prints one row per object (normal mean angular error over the mask, solver time) and the
targets of the foundation issue. Times are the median of --repeats runs of the solver alone
(reading excluded), on this machine with torch's default thread count.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from pathlib import Path

import torch

from unps.data.diligent import read_diligent
from unps.metrics import normal_metrics
from unps.solvers.rpca import robust_init
from unps.solvers.woodham import woodham

OBJECTS = {"ball": ("pmsData/ballPNG", "16-bit, full resolution"),
           "cat": ("pmsData_crop/catPNG", "8-bit crop"),
           "pot1": ("pmsData_crop/pot1PNG", "8-bit crop")}
DEFAULT_DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "DiLiGenT"


def timed(solve, subject, repeats):
    times, estimate = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        estimate = solve(subject, subject.light_directions)
        times.append(time.perf_counter() - start)
    mae = normal_metrics(estimate.normals, subject.normals, subject.mask)["normal_mae"]
    return mae, statistics.median(times)


def cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    if not args.data.is_dir():
        raise SystemExit(f"{args.data}: DiLiGenT folder not found (pass --data)")

    print(f"machine: {cpu_name()}, {os.cpu_count()} cores, torch {torch.__version__} "
          f"({torch.get_num_threads()} threads); lights: ground truth; all 96 images")
    print(f"{'object':<6} {'images':<24} {'H×W':>9} {'pixels':>7} "
          f"{'Woodham °':>9} {'s':>6} {'RPCA °':>8} {'s':>6}")
    rows = {}
    for name, (relative, kind) in OBJECTS.items():
        subject = read_diligent(args.data / relative)
        w_mae, w_time = timed(woodham, subject, args.repeats)
        r_mae, r_time = timed(robust_init, subject, args.repeats)
        rows[name] = (w_mae, r_mae, r_time)
        h, w = subject.resolution
        print(f"{name:<6} {kind:<24} {f'{h}×{w}':>9} {subject.mask.sum():>7} "
              f"{w_mae:>9.2f} {w_time:>6.2f} {r_mae:>8.2f} {r_time:>6.2f}")

    checks = [
        ("Woodham on ball ≤ 4.35°", rows["ball"][0] <= 4.35),
        ("robust init on ball ≤ 3.3°", rows["ball"][1] <= 3.3),
        ("robust init below Woodham on cat and pot1",
         all(rows[k][1] < rows[k][0] for k in ("cat", "pot1"))),
        ("robust init ≤ 1 s per crop", all(rows[k][2] <= 1.0 for k in ("cat", "pot1"))),
    ]
    for text, ok in checks:
        print(f"{'met ' if ok else 'MISSED'}  {text}")


if __name__ == "__main__":
    main()

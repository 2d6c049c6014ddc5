"""Classical solvers on real DiLiGenT: Woodham and the robust initialisation, with the given lights.

    python experiments/classical_diligent/benchmark.py [--data ../shared/data/DiLiGenT] [--repeats 3]

Prints one row per object (normal mean angular error over the mask, solver time) and the
targets of the foundation issue. Times are the median of --repeats runs of the solver alone
(reading excluded), on this machine with torch's default thread count.

Then, to show what 8-bit truncation does and what ``quantization=floor`` recovers where the
16-bit truth is known, ball's 16-bit images are truncated to 8 bits the way PS-FCN made the cat
and pot1 crops (⌊16-bit / 256⌋), once as they are and once after scaling the brightest pixel to
43 levels (as dark as pot1), written to a temporary folder and read back both ways.
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import statistics
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
import torch

from unps.data.diligent import read_diligent
from unps.metrics import normal_metrics, slant_bias
from unps.solvers.rpca import robust_init
from unps.solvers.woodham import woodham

# (object, folder, how the images are described, quantization); the crops are read both ways,
# floor (unps's default for them, the way they were made) and round (the figures in the data README)
ROWS = [("ball", "pmsData/ballPNG", "16-bit, full resolution", "round"),
        ("cat", "pmsData_crop/catPNG", "8-bit crop, floor", "floor"),
        ("cat", "pmsData_crop/catPNG", "8-bit crop, round", "round"),
        ("pot1", "pmsData_crop/pot1PNG", "8-bit crop, floor", "floor"),
        ("pot1", "pmsData_crop/pot1PNG", "8-bit crop, round", "round")]
DEFAULT_DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "DiLiGenT"


def timed(solve, subject, repeats):
    """(normal MAE °, slant bias °, median seconds) of ``solve`` with the subject's own lights."""
    times, estimate = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        estimate = solve(subject, subject.light_directions)
        times.append(time.perf_counter() - start)
    mae = normal_metrics(estimate.normals, subject.normals, subject.mask)["normal_mae"]
    return mae, slant_bias(estimate.normals, subject.normals, subject.mask), statistics.median(times)


def truncated_copy(folder: Path, out: Path, peak: int) -> Path:
    """A copy of a 16-bit DiLiGenT folder with every image scaled so that the brightest pixel of
    the set is just below ``peak + 1`` 8-bit levels, then truncated to 8 bits (⌊v / 256⌋)."""
    out.mkdir(parents=True)
    names = (folder / "filenames.txt").read_text().split()
    levels = {name: cv2.imread(str(folder / name), cv2.IMREAD_UNCHANGED) for name in names}
    if any(v is None or v.dtype != np.uint16 for v in levels.values()):
        raise SystemExit(f"{folder}: expected 16-bit PNGs to truncate")
    scale = (peak + 1) * 256 * (1 - 1e-6) / max(int(v.max()) for v in levels.values())
    for name, v in levels.items():
        cv2.imwrite(str(out / name), (np.floor(v * scale) // 256).astype(np.uint8))
    for extra in folder.iterdir():
        if extra.name not in levels:
            shutil.copy(extra, out / extra.name)
    return out


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
          f"{'Woodham °':>9} {'s':>6} {'RPCA °':>8} {'s':>6} {'RPCA slant bias °':>17}")
    rows = {}
    for name, relative, kind, quantization in ROWS:
        subject = read_diligent(args.data / relative, quantization=quantization)
        w_mae, _, w_time = timed(woodham, subject, args.repeats)
        r_mae, r_slant, r_time = timed(robust_init, subject, args.repeats)
        rows[name, quantization] = (w_mae, r_mae, r_time)
        h, w = subject.resolution
        print(f"{name:<6} {kind:<24} {f'{h}×{w}':>9} {subject.mask.sum():>7} "
              f"{w_mae:>9.2f} {w_time:>6.2f} {r_mae:>8.2f} {r_time:>6.2f} {r_slant:>+17.2f}")

    crops = [(k, q) for k in ("cat", "pot1") for q in ("floor", "round")]
    checks = [
        ("Woodham on ball ≤ 4.35°", rows["ball", "round"][0] <= 4.35),
        ("robust init on ball ≤ 3.3°", rows["ball", "round"][1] <= 3.3),
        ("robust init below Woodham on cat and pot1", all(rows[k][1] < rows[k][0] for k in crops)),
        ("robust init ≤ 1 s per crop", all(rows[k][2] <= 1.0 for k in crops)),
        ("floor below round for both solvers on both crops",
         all(rows[k, "floor"][i] < rows[k, "round"][i] for k in ("cat", "pot1") for i in (0, 1))),
    ]
    for text, ok in checks:
        print(f"{'met ' if ok else 'MISSED'}  {text}")

    print("\nball truncated to 8 bits (from the 16-bit original above), read both ways")
    print(f"{'brightest level':<16} {'quantization':<12} {'Woodham °':>9} {'RPCA °':>8} "
          f"{'RPCA slant bias °':>17}")
    with tempfile.TemporaryDirectory() as tmp:
        for peak in (255, 43):
            folder = truncated_copy(args.data / ROWS[0][1], Path(tmp) / f"peak{peak}", peak)
            for quantization in ("round", "floor"):
                subject = read_diligent(folder, quantization=quantization)
                w_mae = timed(woodham, subject, 1)[0]
                r_mae, r_slant, _ = timed(robust_init, subject, 1)
                print(f"{peak:<16} {quantization:<12} {w_mae:>9.2f} {r_mae:>8.2f} {r_slant:>+17.2f}",
                      flush=True)


if __name__ == "__main__":
    main()

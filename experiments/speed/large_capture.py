"""The default command on photographs the size a camera takes: wall time, peak memory, where the time goes.

    python experiments/speed/large_capture.py                    # 12 images, ×4: 2448×2048 (5 MP)
    python experiments/speed/large_capture.py --scale 2 --images 20
    python experiments/speed/large_capture.py --set light=gt method=rpca

DiLiGenT's ball (its full 612×512 frame, 16-bit) stands for a user's capture: ``--images`` of its
96, spread evenly over its lights (the one nearest the view, then each time the farthest), are
enlarged ``--scale`` times (bilinear) and written as 16-bit PNGs, scaled so that the brightest value
is the top level (nothing clipped), with ``light_directions.txt`` beside them and no mask (found
from the images, as for a user's folder). Then ``python -m unps.fit subject=folder
subject.root=<capture>`` runs as a user runs it (plus ``--set``), in its own process; printed:
its wall time, its peak resident memory, the light error and the seconds of each stage
(``stage_seconds`` in ``metrics.json``). The capture is written once under ``--out`` and reused.
"""

from __future__ import annotations

import argparse
import json
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "light_benchmark"))
from scenes import evenly_spread  # noqa: E402
from stages import DILIGENT, machine  # noqa: E402

from unps.data.diligent import read_diligent_object  # noqa: E402

SHOWN = ("reading", "light network", "reversal test", "self-calibration", "robust initialisation",
         "steps", "read-out", "depth")
"""The stages printed, in the order they run (``stage_seconds`` also holds the parts of a step)."""


def write_capture(diligent: Path, images: int, scale: int, folder: Path) -> tuple[int, int]:
    """Write the enlarged capture into ``folder`` (made here); returns its (width, height)."""
    ball = read_diligent_object(diligent, "ball")
    chosen = evenly_spread(ball.light_directions, images)
    stack = ball.observed_images()[chosen]
    top = float(stack.max())
    height, width = stack.shape[1] * scale, stack.shape[2] * scale
    partial = folder.with_name(folder.name + ".partial")
    partial.mkdir(parents=True, exist_ok=True)
    for k, image in enumerate(stack):
        large = cv2.resize(image, (width, height), interpolation=cv2.INTER_LINEAR)
        sixteen = np.round(np.clip(large / top, 0, 1) * 65535).astype(np.uint16)
        cv2.imwrite(str(partial / f"{k:03d}.png"), np.ascontiguousarray(sixteen[..., ::-1]))   # BGR
    np.savetxt(partial / "light_directions.txt", ball.light_directions[chosen], fmt="%.6f")
    partial.rename(folder)
    return width, height


def run_folder(out: Path, capture: str, overrides: list[str]) -> Path:
    """The fit's folder under ``out``, named by the capture and the overrides, with neither '=' nor
    '/' in it: it is passed to the fit as ``hydra.run.dir=…``, whose value may hold no '='."""
    label = "-".join(override.replace("=", "_").replace("/", "_") for override in overrides)
    return out / ("run-" + capture + ("-" + label if label else ""))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--diligent", type=Path, default=DILIGENT)
    parser.add_argument("--images", type=int, default=12)
    parser.add_argument("--scale", type=int, default=4)
    parser.add_argument("--out", type=Path, default=Path.home() / ".cache" / "unps" / "large_capture")
    parser.add_argument("--set", dest="overrides", nargs="*", default=[],
                        help="overrides of python -m unps.fit")
    args = parser.parse_args(argv)
    if not 3 <= args.images <= 96:
        parser.error(f"--images {args.images}: between 3 and DiLiGenT's 96")
    if args.scale < 1:
        parser.error(f"--scale {args.scale}: a whole number, 1 or more")
    if not (args.diligent / "pmsData" / "ballPNG").is_dir():
        parser.error(f"--diligent {args.diligent}: no pmsData/ballPNG there (DiLiGenT's ball at full frame)")
    capture = args.out / f"ball-{args.images}-x{args.scale}"
    if not capture.is_dir():
        width, height = write_capture(args.diligent, args.images, args.scale, capture)
        print(f"wrote {capture} ({args.images} images, {width}×{height})", flush=True)
    run = run_folder(args.out, capture.name, args.overrides)
    shutil.rmtree(run, ignore_errors=True)      # a run left there would resume, not be measured
    command = [sys.executable, "-m", "unps.fit", "subject=folder", f"subject.root={capture}",
               *args.overrides, f"hydra.run.dir={run}"]
    start = time.perf_counter()
    done = subprocess.run(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    wall = time.perf_counter() - start
    if done.returncode:
        sys.exit(f"{' '.join(command)} failed:\n{done.stderr[-2000:]}")
    peak_gb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 2 ** 20   # KiB on Linux
    metrics = json.loads((run / "metrics.json").read_text())
    height, width = metrics["resolution"]
    print(f"machine: {machine()}")
    print(f"python -m unps.fit subject=folder subject.root={capture} {' '.join(args.overrides)}")
    print(f"{args.images} images of {width}×{height} ({width * height / 1e6:.1f} MP): wall {wall:.1f} s, "
          f"peak memory {peak_gb:.1f} GB, light error {metrics.get('light_dir_mae', float('nan')):.2f}°")
    seconds = metrics["stage_seconds"]
    for stage in SHOWN:
        if stage in seconds:
            print(f"  {stage:<24}{seconds[stage]:7.1f} s")


if __name__ == "__main__":
    main()

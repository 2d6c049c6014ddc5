"""Do two versions of unps write the same normals? A check for changes meant to keep outputs.

    python experiments/speed/same_outputs.py --before 27cc432
    python experiments/speed/same_outputs.py --before 27cc432 --cases woodham-cat rpca-cat

Each case runs ``python -m unps.fit`` from the old source (a detached worktree, as
``compare.py`` makes it) and from this checkout, each in its own process with the same seed and
thread count, and compares the two ``normals.npy`` bit for bit; where they differ it prints the
largest angle between them. The cases: Woodham and the robust initialisation on DiLiGenT cat and
on the analytic sphere, and a short ``method=unps`` fit (60 steps) on each, all with the true
lights; and Woodham on cat with the default lights (the network, the reversal test and the
self-calibration).
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from compare import worktree  # noqa: E402
from stages import DILIGENT, machine  # noqa: E402

from unps.metrics import angular_error  # noqa: E402

SPHERE = ["subject=lambertian", "subject.size=48", "subject.n_lights=24"]
CAT = ["subject=cat", f"paths.diligent_dir={DILIGENT}"]
SHORT_UNPS = ["method=unps", "preset.steps=60", "preset.lr_drop_at=54"]
CASES = {
    "woodham-sphere": [*SPHERE, "method=woodham"],
    "rpca-sphere": [*SPHERE, "method=rpca"],
    "unps-sphere": [*SPHERE, *SHORT_UNPS],
    "woodham-cat": [*CAT, "method=woodham"],
    "rpca-cat": [*CAT, "method=rpca"],
    "unps-cat": [*CAT, *SHORT_UNPS],
    "selfcal-cat": [*CAT, "method=woodham", "light=selfcal"],
}


def normals(source: Path, overrides: list[str], run_dir: Path) -> np.ndarray:
    """``normals.npy`` of one fit run from ``source`` (light=gt unless the case names its lights, seed
    0, 2 threads)."""
    shutil.rmtree(run_dir, ignore_errors=True)
    lights = [] if any(o.startswith("light=") for o in overrides) else ["light=gt"]
    command = [sys.executable, "-m", "unps.fit", *overrides, *lights, "seed=0", "threads=2",
               f"hydra.run.dir={run_dir}"]
    done = subprocess.run(command, cwd=source, env={**os.environ, "PYTHONPATH": str(source)},
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(command)} (from {source}) failed:\n{done.stderr[-2000:]}")
    return np.load(run_dir / "normals.npy")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--before", required=True, help="a git revision of this repository")
    parser.add_argument("--cases", nargs="+", choices=list(CASES), default=list(CASES))
    parser.add_argument("--out", type=Path, default=Path("runs/same-outputs"))
    args = parser.parse_args()
    args.out = args.out.resolve()              # the runs start in the old source's folder
    old = worktree(args.before, args.out)
    new = Path(__file__).resolve().parents[2]
    print(f"machine: {machine()}; before: {args.before}")
    for name in args.cases:
        a = normals(old, CASES[name], args.out / name / "before")
        b = normals(new, CASES[name], args.out / name / "after")
        if a.shape == b.shape and np.array_equal(a, b):
            verdict = "bit-identical"
        else:
            on = np.isfinite(a).all(-1) & (np.abs(a).sum(-1) > 0)
            verdict = f"differ: largest angle {angular_error(a[on], b[on]).max():.2e}°"
        print(f"{name:<15} {verdict}", flush=True)


if __name__ == "__main__":
    main()

"""Two fits at once on this machine: does each take its share of the cores?

    python experiments/speed/parallel.py                    # ball, fast preset, 200 steps
    python experiments/speed/parallel.py --subject cat --steps 300

Runs one fit alone (``python -m unps.fit``, threads chosen automatically), then the same fit
twice at once as a Hydra sweep with the joblib launcher (``hydra/launcher=local
hydra.launcher.n_jobs=2 seed=0,1``), and prints each fit's seconds per step and its ratio to
the fit alone. With every core shared fairly the ratio is about the number of parallel fits
(2 on 2 cores); before fits took their share, it was about 10.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from stages import DILIGENT, machine  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--subject", default="ball")
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--out", type=Path, default=Path("runs/speed-parallel"))
    args = parser.parse_args()
    shutil.rmtree(args.out, ignore_errors=True)
    common = [f"subject={args.subject}", "method=unps", "preset=fast", "light=gt",
              f"paths.diligent_dir={DILIGENT}", f"preset.steps={args.steps}",
              f"preset.lr_drop_at={int(args.steps * 0.9)}"]
    fit = [sys.executable, "-m", "unps.fit"]
    subprocess.run([*fit, *common, f"hydra.run.dir={args.out / 'alone'}"], check=True, capture_output=True)
    subprocess.run([*fit, "-m", *common, "hydra/launcher=local", "hydra.launcher.n_jobs=2", "seed=0,1",
                    f"hydra.sweep.dir={args.out / 'pair'}"], check=True, capture_output=True)
    alone = json.loads((args.out / "alone" / "metrics.json").read_text())["fit_s_per_step"]
    pair = [json.loads(p.read_text())["fit_s_per_step"]
            for p in sorted((args.out / "pair").glob("*/metrics.json"))]
    print(f"machine: {machine()}")
    print(f"{args.subject}, fast preset, {args.steps} steps: alone {alone:.3f} s/step; two at once "
          + ", ".join(f"{p:.3f} s/step ({p / alone:.2f}×)" for p in pair))


if __name__ == "__main__":
    main()

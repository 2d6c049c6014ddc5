"""Where the seconds of one fit go, stage by stage (:mod:`unps.timing`).

    python experiments/speed/stages.py                                 # ball, cat, pot1; fast, light=gt
    python experiments/speed/stages.py --subjects ball --set preset.steps=200
    python experiments/speed/stages.py --set preset=paper preset.steps=20 --subjects pot1
    python experiments/speed/stages.py --diligent ~/data/DiLiGenT      # DiLiGenT elsewhere than ../shared

Each subject is fitted in this process by :func:`unps.fit.fit` (``method=unps preset=fast
light=gt`` unless ``--set`` says otherwise), into ``<out>/<subject>/`` (deleted first, so no
fit resumes), and the seconds of every stage are printed as one table: whole stages in seconds,
the parts of a step in milliseconds per step. "loop and loss" is what the steps took beyond
their timed parts (Lightning's loop, the loss, logging, the random draws). The table is also
written to ``<out>/profile.md`` and the numbers to ``<out>/profile.json``.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import platform
import shutil
import time
from pathlib import Path

import torch

from unps.timing import recording

DILIGENT = Path(__file__).resolve().parents[3] / "shared" / "data" / "DiLiGenT"
WHOLE = ("reading", "lights", "robust initialisation", "system assembly", "steps", "read-out",
         "depth", "writing")
PER_STEP = ("normal network", "interreflection solve", "reflectance network", "backward",
            "optimiser", "interreflection update", "progress pictures")


def machine() -> str:
    """One line naming the CPU, the vector instructions torch's kernels use on it, its cores and torch."""
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return (f"{model} ({torch.backends.cpu.get_cpu_capability()}), {os.cpu_count()} cores, "
            f"torch {torch.__version__} ({torch.get_num_threads()} threads)")


def profile(subject: str, overrides: list[str], out: Path, diligent: Path = DILIGENT) -> dict:
    """Fit one subject (a DiLiGenT object is read from ``diligent``) and return its stage
    seconds, steps, wall time and normal MAE."""
    from hydra import compose, initialize_config_module

    from unps.pipeline import fit

    run_dir = out / subject
    shutil.rmtree(run_dir, ignore_errors=True)
    with initialize_config_module("unps.conf", version_base=None):
        cfg = compose("fit", overrides=[f"subject={subject}", "method=unps", "preset=fast", "light=gt",
                                        f"paths.diligent_dir={diligent}",
                                        f"paths.output_dir={run_dir}", *overrides])
    start = time.perf_counter()
    with recording() as seconds:
        metrics = fit(cfg)
    return {"subject": subject, "seconds": dict(seconds), "wall_s": time.perf_counter() - start,
            "steps": metrics.get("fit_steps", 0) - metrics.get("resumed_from_step", 0),
            "normal_mae": metrics.get("normal_mae"), "grid": metrics.get("fit_resolution")}


def table(results: list[dict]) -> str:
    """Markdown: one column per subject; whole stages in s, the parts of a step in ms/step."""
    names = [r["subject"] for r in results]
    lines = ["| stage | " + " | ".join(names) + " |", "|---" * (len(names) + 1) + "|"]

    def row(label, values):
        lines.append(f"| {label} | " + " | ".join(values) + " |")

    for stage in WHOLE:
        row(f"{stage} (s)", [f"{r['seconds'].get(stage, 0.0):.1f}" for r in results])
    for stage in PER_STEP:
        row(f"… {stage} (ms/step)",
            [f"{1000 * r['seconds'].get(stage, 0.0) / max(r['steps'], 1):.1f}" for r in results])
    def loop_and_loss(r: dict) -> float:
        rest = r["seconds"].get("steps", 0.0) - sum(r["seconds"].get(s, 0.0) for s in PER_STEP)
        return 1000 * rest / max(r["steps"], 1)

    row("… loop and loss (ms/step)", [f"{loop_and_loss(r):.1f}" for r in results])
    row("**total (s)**", [f"**{r['wall_s']:.1f}**" for r in results])
    row("normal MAE (°)", [f"{r['normal_mae']:.2f}" if r["normal_mae"] is not None else "–" for r in results])
    row("working grid", ["×".join(map(str, r["grid"][::-1])) if r["grid"] else "–" for r in results])
    return "\n".join(lines)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--subjects", nargs="+", default=["ball", "cat", "pot1"])
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                        help="overrides for every fit (e.g. preset.steps=200)")
    parser.add_argument("--out", type=Path, default=Path("runs/speed-profile"))
    parser.add_argument("--diligent", type=Path, default=DILIGENT,
                        help="the folder holding pmsData/ or pmsData_crop/, for DiLiGenT's subjects "
                             "(default: ../shared/data/DiLiGenT beside the repository)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    args.out.mkdir(parents=True, exist_ok=True)
    results = []
    for subject in args.subjects:
        print(f"profiling {subject} ({' '.join(args.set) or 'fast preset, light=gt'}) …", flush=True)
        results.append(profile(subject, args.set, args.out, args.diligent))
    heading = f"machine: {machine()}\nsettings: method=unps preset=fast light=gt {' '.join(args.set)}\n"
    text = heading + "\n" + table(results) + "\n"
    print(text)
    (args.out / "profile.md").write_text(text)
    (args.out / "profile.json").write_text(json.dumps({"machine": machine(), "overrides": args.set,
                                                       "results": results}, indent=1))


if __name__ == "__main__":
    main()

"""Two versions of unps side by side on one machine: wall time and normal error per subject.

    python experiments/speed/compare.py --before 6efa55c                 # ball, cat, pot1, fast, gt
    python experiments/speed/compare.py --before 6efa55c --subjects ball --set preset.steps=200
    python experiments/speed/compare.py --before 6efa55c --subjects ball --preset paper --set preset.steps=20
    python experiments/speed/compare.py --before b8fbc44 --set preset.steps=60 --stages read-out

``--before`` is any git revision of this repository; it is checked out once into a detached
worktree under ``<out>/before-<rev>``. For every subject, the fit runs as a user runs it,
``python -m unps.fit subject=<s> method=unps preset=<preset> light=gt`` (plus ``--set``), first
with the old source and then with this checkout, each in its own process, so the two share
the machine's state as closely as one run allows. "wall" is the whole command (start-up,
reading, fit, writing), "fit" the method and depth (``runtime_s`` in metrics.json); ``--stages``
adds the seconds of named stages (``stage_seconds`` in metrics.json, :mod:`unps.timing`). The
table goes to stdout and to ``<out>/compare.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from stages import DILIGENT, machine  # noqa: E402

REPO = Path(__file__).resolve().parents[2]


def worktree(revision: str, out: Path) -> Path:
    """A detached checkout of ``revision`` (made once, reused)."""
    commit = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", revision],
                            check=True, capture_output=True, text=True).stdout.strip()
    path = (out / f"before-{commit}").resolve()
    if not (path / "unps").is_dir():
        shutil.rmtree(path, ignore_errors=True)
        subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", str(path), commit],
                       check=True, capture_output=True)
    return path


def run(source: Path, subject: str, preset: str, overrides: list[str], run_dir: Path) -> dict:
    """One fit from ``source`` in a fresh process; its wall time and metrics."""
    shutil.rmtree(run_dir, ignore_errors=True)
    command = [sys.executable, "-m", "unps.fit", f"subject={subject}", "method=unps", f"preset={preset}",
               "light=gt", f"paths.diligent_dir={DILIGENT}", f"hydra.run.dir={run_dir}", *overrides]
    env = {**os.environ, "PYTHONPATH": str(source)}
    start = time.perf_counter()
    done = subprocess.run(command, cwd=source, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(command)} (from {source}) failed:\n{done.stderr[-2000:]}")
    metrics = json.loads((run_dir / "metrics.json").read_text())
    return {"wall_s": wall, "fit_s": metrics["runtime_s"], "s_per_step": metrics["fit_s_per_step"],
            "normal_mae": metrics["normal_mae"], "stage_seconds": metrics["stage_seconds"]}


def table(pairs: dict[str, tuple[dict, dict]], stages: list[str]) -> str:
    """Markdown rows, one per subject, of its runs before and now (as :func:`run` returns them):
    wall, fit, seconds per step, each of ``stages`` and the normal error."""
    columns = ["wall", "fit", "s/step", *stages, "MAE"]
    rows = ["| subject | " + " | ".join(f"{c} before → now{'' if c in ('s/step', 'MAE') else ' (s)'}"
                                        for c in columns) + " | Δ MAE (°) |",
            "|---" * (len(columns) + 2) + "|"]
    for subject, (a, b) in pairs.items():
        cells = [f"{a['wall_s']:.1f} → {b['wall_s']:.1f}", f"{a['fit_s']:.1f} → {b['fit_s']:.1f}",
                 f"{a['s_per_step']:.3f} → {b['s_per_step']:.3f}"]
        cells += [f"{a['stage_seconds'][name]:.2f} → {b['stage_seconds'][name]:.2f}" for name in stages]
        cells.append(f"{a['normal_mae']:.3f} → {b['normal_mae']:.3f}°")
        rows.append(f"| {subject} | " + " | ".join(cells) + f" | {b['normal_mae'] - a['normal_mae']:+.3f} |")
    return "\n".join(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--before", required=True, help="git revision to compare with")
    parser.add_argument("--subjects", nargs="+", default=["ball", "cat", "pot1"])
    parser.add_argument("--preset", default="fast")
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE")
    parser.add_argument("--stages", nargs="*", default=[], metavar="STAGE",
                        help="stages whose seconds to show too (e.g. read-out 'robust initialisation')")
    parser.add_argument("--out", type=Path, default=Path("runs/speed-compare"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    old = worktree(args.before, args.out)
    pairs = {}
    for subject in args.subjects:
        print(f"{subject}: before ({old.name}) …", flush=True)
        a = run(old, subject, args.preset, args.set, args.out / f"{subject}-before")
        unknown = [name for name in args.stages if name not in a["stage_seconds"]]
        if unknown:
            raise SystemExit(f"--stages: no stage {', '.join(map(repr, unknown))} in the run's metrics.json; "
                             f"its stages: {', '.join(sorted(a['stage_seconds']))}")
        print(f"{subject}: now …", flush=True)
        pairs[subject] = a, run(REPO, subject, args.preset, args.set, args.out / f"{subject}-now")
    text = (f"machine: {machine()}\nbefore: {args.before} ({old.name}); now: this checkout; "
            f"method=unps preset={args.preset} light=gt {' '.join(args.set)}\n\n"
            + table(pairs, args.stages) + "\n")
    print(text)
    (args.out / "compare.md").write_text(text)


if __name__ == "__main__":
    main()

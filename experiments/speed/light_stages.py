"""Two versions of unps side by side on the default lights: each light stage's seconds and the
lights it ends with.

    python experiments/speed/light_stages.py --before d7b80ae                 # ball, cat, pot1, 3 rounds
    python experiments/speed/light_stages.py --before d7b80ae --subjects cat --rounds 5

``--before`` is any git revision of this repository, checked out once into a detached worktree
under ``<out>/before-<rev>`` (as ``compare.py`` does). Every round runs, for each subject,
``python -m unps.fit subject=<s> method=woodham`` (the default ``light=selfcal``: the light network,
the reversal test, the self-calibration; Woodham's least squares after them takes a fraction of a
second) first from the old source, then from this checkout, each in its own process: the two
alternate, so a machine whose speed drifts slows both alike. The stages' seconds are those every
run writes (``stage_seconds`` in ``metrics.json``); the table gives their median over the rounds and
the lights' mean direction error of the last round. It goes to stdout and to
``<out>/light_stages.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from compare import REPO, worktree  # noqa: E402
from stages import DILIGENT, machine  # noqa: E402

STAGES = ("light network", "reversal test", "self-calibration", "lights")


def run(source: Path, subject: str, threads: int, run_dir: Path) -> dict:
    """One default-lights fit from ``source`` in a fresh process: its stage seconds and light error."""
    shutil.rmtree(run_dir, ignore_errors=True)
    command = [sys.executable, "-m", "unps.fit", f"subject={subject}", "method=woodham",
               f"threads={threads}", f"paths.diligent_dir={DILIGENT}", f"hydra.run.dir={run_dir}"]
    done = subprocess.run(command, cwd=source, env={**os.environ, "PYTHONPATH": str(source)},
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(command)} (from {source}) failed:\n{done.stderr[-2000:]}")
    metrics = json.loads((run_dir / "metrics.json").read_text())
    return {**{name: metrics["stage_seconds"][name] for name in STAGES},
            "light_dir_mae": metrics["light_dir_mae"]}


def table(runs: dict[tuple[str, str], list[dict]], subjects: list[str]) -> str:
    """Markdown rows, one per subject: each stage's median seconds before → now over the rounds of
    ``runs[subject, "before" | "now"]`` (what :func:`run` returns, round by round), and the light
    error of the last round."""
    header = " | ".join(f"{name} (s), before → now" for name in STAGES)
    rows = [f"| subject | {header} | light error (°), before → now |", "|---" * (len(STAGES) + 2) + "|"]
    for subject in subjects:
        before, now = runs[subject, "before"], runs[subject, "now"]
        cells = [f"{statistics.median(r[name] for r in before):.1f} → "
                 f"{statistics.median(r[name] for r in now):.1f}" for name in STAGES]
        rows.append(f"| {subject} | {' | '.join(cells)} | "
                    f"{before[-1]['light_dir_mae']:.4f} → {now[-1]['light_dir_mae']:.4f} |")
    return "\n".join(rows) + "\n"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--before", required=True, help="git revision to compare with")
    parser.add_argument("--subjects", nargs="+", default=["ball", "cat", "pot1"])
    parser.add_argument("--rounds", type=int, default=3, help="runs of each version per subject")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("runs/speed-light-stages"))
    args = parser.parse_args(argv)
    if args.rounds < 1:
        parser.error(f"--rounds must be at least 1, got {args.rounds}")
    args.out.mkdir(parents=True, exist_ok=True)
    old = worktree(args.before, args.out)
    runs: dict[tuple[str, str], list[dict]] = {}
    for round_ in range(args.rounds):
        for subject in args.subjects:
            for version, source in (("before", old), ("now", REPO)):
                print(f"round {round_ + 1}/{args.rounds}, {subject}, {version} …", flush=True)
                runs.setdefault((subject, version), []).append(
                    run(source, subject, args.threads, args.out / f"{subject}-{version}"))
    rows = table(runs, args.subjects)
    text = (f"machine: {machine()}\nbefore: {args.before} ({old.name}); now: this checkout; "
            f"method=woodham, the default lights, {args.threads} threads; medians of {args.rounds} "
            f"rounds\n\n" + rows)
    print(text)
    (args.out / "light_stages.md").write_text(text)


if __name__ == "__main__":
    main()

"""How many steps the self-calibration needs: its lights' error as it goes, on every light benchmark case.

    python experiments/light_benchmark/selfcal_steps.py               # every case, 1500 steps (~50 min)
    python experiments/light_benchmark/selfcal_steps.py --only benchmark --sets 12
    python experiments/light_benchmark/selfcal_steps.py --report --marks 500 1000 1500
    python experiments/light_benchmark/selfcal_steps.py --steps 1000 --report --settle 0.02 0.05 0.1

Each case (``benchmark.py``'s) is estimated by the network and the reversal test, then
self-calibrated with the default settings for ``--steps`` steps, the direction error of its lights
read every 100 steps (:func:`unps.lights.selfcal.self_calibrate`'s ``observe``); one json per case
in ``<cache>/results/selfcal_steps-<steps>/`` (a rerun resumes). The fit is deterministic and its
steps do not depend on how many there will be (a constant learning rate, the shadows marched every
100 steps), so the error read at step S is what ``light.selfcal.steps=S`` gives.

Printed per group and light set, at each of ``--marks``: the mean direction error, its ratio to the
network's, the cases the self-calibration up to that step left more than 1° and 2° above where it
started (after the reversal test) with the worst, and the cases more than 0.3° above and below
the last step's error. With ``--settle``, the same for ``light.selfcal.settle_deg`` at each value
given (each case stopped at the first read where its lights moved no more than that on average
since the one before, as the fit itself stops), with the mean steps taken.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from unps.lights.selfcal import self_calibrate
from unps.metrics import angular_error

sys.path.insert(0, str(Path(__file__).parent))
import benchmark  # noqa: E402
import runs  # noqa: E402
import scenes  # noqa: E402

MARKS = (300, 500, 700, 1000, 1500)
NOTABLE = 0.3   # degrees from the last step's error


def trace_case(subject, network, settings) -> dict:
    """The lights' direction error from the network, after the reversal test, and every 100
    steps of the self-calibration (``trace``: ``[[step, error], …]``), with the (n, 3) directions
    at each of those steps (``directions``, in the trace's order)."""
    start = network(subject)
    truth = subject.light_directions.astype(np.float64)
    trace, seen = [], []

    def observe(step, directions):
        trace.append([step, float(angular_error(directions, truth).mean())])
        seen.append(np.round(directions, 7).tolist())

    self_calibrate(subject, start, settings, observe=observe)
    return {"network": start.verdicts[0].errors["light_dir_mae"],
            "start": float(angular_error(start.directions.astype(np.float64), truth).mean()),
            "trace": trace, "directions": seen}


def error_at(case: dict, step: int) -> float:
    """The case's error read at ``step`` (a multiple of 100, or its last step)."""
    return dict((int(s), e) for s, e in case["trace"])[step]


def settled_step(case: dict, settle_deg: float) -> int:
    """The step at which ``light.selfcal.settle_deg=settle_deg`` stops the case's fit: the first
    read, short of the last step, where the lights have moved no more than ``settle_deg`` on
    average since the read before (the trace's directions); its last step where none is."""
    steps = [int(step) for step, _ in case["trace"]]
    directions = [np.asarray(d) for d in case["directions"]]
    for k in range(1, len(steps) - 1):
        if angular_error(directions[k], directions[k - 1]).mean() <= settle_deg:
            return steps[k]
    return steps[-1]


def settled_summary(names: list[str], cases: list[dict], settle: list[float]) -> str:
    """One line per ``settle`` value for the cases of one light set, as :func:`summary`'s, with
    each case read where that value stops it (:func:`settled_step`) and the mean steps taken."""
    last = np.array([c["trace"][-1][1] for c in cases])
    network = np.mean([c["network"] for c in cases])
    lines = []
    for value in settle:
        stops = [settled_step(c, value) for c in cases]
        at = np.array([error_at(c, stop) for c, stop in zip(cases, stops)])
        raised = at - np.array([c["start"] for c in cases])
        worst, off = int(np.argmax(raised)), at - last
        lines.append(f"  settle {value:>5g}°: {at.mean():6.2f}°  ratio {at.mean() / network:.3f}  "
                     f"steps {np.mean(stops):6.0f}  raised >1°: {int((raised > 1).sum()):>2}  "
                     f">2°: {int((raised > 2).sum()):>2}  worst {raised[worst]:+.2f}° ({names[worst]})  "
                     f"vs the last step: {int((off > NOTABLE).sum())} above, "
                     f"{int((off < -NOTABLE).sum())} below, worst {off.max():+.2f}°")
    return "\n".join(lines)


def summary(names: list[str], cases: list[dict], marks) -> str:
    """One line per mark for the cases of one light set (``names`` and their :func:`trace_case`
    results)."""
    last = np.array([c["trace"][-1][1] for c in cases])
    network = np.mean([c["network"] for c in cases])
    lines = []
    for mark in marks:
        at = np.array([error_at(c, mark) for c in cases])
        raised = at - np.array([c["start"] for c in cases])
        worst = int(np.argmax(raised))
        off = at - last
        lines.append(f"  step {mark:>5}: {at.mean():6.2f}°  ratio {at.mean() / network:.3f}  "
                     f"raised >1°: {int((raised > 1).sum()):>2}  >2°: {int((raised > 2).sum()):>2}  "
                     f"worst {raised[worst]:+.2f}° ({names[worst]})  vs the last step: "
                     f"{int((off > NOTABLE).sum())} above, {int((off < -NOTABLE).sum())} below")
    return "\n".join(lines)


def main(argv=None) -> None:
    parser = benchmark.study_parser(__doc__.split("\n")[0], "where each case's trace is kept "
                                    "(default: <cache>/results/selfcal_steps-<steps>)")
    parser.add_argument("--steps", type=int, default=1500, help="self-calibration steps (default 1500)")
    parser.add_argument("--marks", type=int, nargs="+", default=list(MARKS),
                        help="steps to report (multiples of 100, or --steps)")
    parser.add_argument("--settle", type=float, nargs="*", default=[],
                        help="light.selfcal.settle_deg values to read off the traces")
    args = parser.parse_args(argv)
    bad = [m for m in args.marks if m > args.steps or (m % 100 and m != args.steps)]
    if bad:
        parser.error(f"--marks {bad}: each must be a multiple of 100 up to --steps ({args.steps}), "
                     "or --steps")
    out = args.out or args.cache / "results" / f"selfcal_steps-{args.steps}"
    try:
        runs.claim(out, {"steps": args.steps, "scenes": scenes.SCENE_VERSION, "directions": True,
                         "weights": runs.weights_digest(None)})
    except ValueError as e:
        parser.error(str(e))
    print(f"network → reversal test → self-calibration, default settings but {args.steps} steps; the "
          f"lights' mean direction error at steps {', '.join(map(str, args.marks))}; results in {out}")
    network, _ = benchmark.light_source(["reversal"], [])
    every_step = ["light=selfcal", f"light.selfcal.steps={args.steps}", "light.selfcal.settle_deg=0"]
    settings = benchmark.instantiate_node(["fit"], every_step, "light.selfcal")()

    def progress(case, result, _) -> str:
        group, name, label = case
        marks = "  ".join(f"{m}: {error_at(result, m):6.2f}°" for m in args.marks)
        return (f"{group:<10}{name:<12}{label:>4}  network {result['network']:6.2f}°  start "
                f"{result['start']:6.2f}°  {marks}")

    rows = runs.summaries(benchmark.study_cases(args), out,
                          lambda subject: trace_case(subject, network, settings),
                          lambda result: result, progress, args.report)
    print("\n".join(progress(case, result, None) for case, result in rows.items()))
    for group, label, cases in runs.by_light_set(rows):
        names = [name for g, name, lab in rows if (g, lab) == (group, label)]
        network_mean = np.mean([c["network"] for c in cases])
        print(f"\n{group} {label} ({len(cases)} cases; network {network_mean:.2f}°)")
        print(summary(names, cases, args.marks))
        if args.settle:
            print(settled_summary(names, cases, args.settle))


if __name__ == "__main__":
    main()

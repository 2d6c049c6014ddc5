"""How many steps the self-calibration needs: its lights' error as it goes, on every light benchmark case.

    python experiments/light_benchmark/selfcal_steps.py                 # every case, 1000 steps (~1 h)
    python experiments/light_benchmark/selfcal_steps.py --only benchmark --sets 12
    python experiments/light_benchmark/selfcal_steps.py --report --marks 300 500 1000
    python experiments/light_benchmark/selfcal_steps.py --report --settle 0.02 0.05 0.1 0.2
    python experiments/light_benchmark/selfcal_steps.py --report --settle 0.1 --limit 1.5
    python experiments/light_benchmark/selfcal_steps.py --report --settle 0.1 --limits 1.5 2 none
    python experiments/light_benchmark/selfcal_steps.py --set selfcal.lr_lights=0.006 --tag lr0.006

Each case (``benchmark.py``'s) is estimated by the network and the reversal test, then fitted as
the default self-calibration fits (:func:`unps.lights.selfcal.frame_held_then_pulled`), each fit
for ``--steps`` steps without stopping early, the lights' direction error and
:func:`unps.lights.selfcal.flattening` read every 100 steps (``observe``): first the fit with the
shared frame held; then, where it flattened the lights by more than
``light.selfcal.max_flattening_deg`` at any read, the pulled fit that would take over (neither
where the reversal test warned that the reading may be inside out or the network is unsure of it,
as by default). One json per
case in ``<cache>/results/selfcal_steps-<steps>/`` (a rerun resumes). A fit is deterministic and
its steps do not depend on how many there will be (a constant learning rate, the shadows marched
every 100 steps), so a read at step S is what ``light.selfcal.steps=S`` gives, and a stop rule can
be read off the traces.

Printed per group and light set, for a fixed number of steps (``--marks``) and for
``light.selfcal.settle_deg`` at each value of ``--settle`` (each fit stopped at the first read
where its lights moved no more than that on average since the one before, as the fit itself
stops): the final lights' mean direction error (the held fit where it is kept, else the pulled
one, else the start, as the default decides), its ratio to the network's, the steps taken by both
fits together, the cases raised by more than 1° and 2° over the start (after the reversal test)
with the worst, and the cases more than 0.3° above and below the full-length fits' result;
all of it read under ``light.selfcal.max_flattening_deg`` at ``--limit`` (default: the limit the
traces were made with). For each value of ``--limits`` the same line as
``light.selfcal.max_flattening_deg`` at that value would give it (each fit stopped as the first
``--settle`` value says, else at its last read), then the cases it changes by more than 0.3°.
The traces hold the pulled fit only where the held one flattened past the limit they were made
with, so a limit below that one cannot be read off them.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from hydra.errors import ConfigCompositionException

from unps.lights.selfcal import (fit_once, flattening, frame_held, unsure_reading, warned_inside_out,
                                 working_images)
from unps.metrics import angular_error

sys.path.insert(0, str(Path(__file__).parent))
import benchmark  # noqa: E402
import runs  # noqa: E402
import scenes  # noqa: E402

MARKS = (300, 500, 700, 1000)
NOTABLE = 0.3   # degrees from the full-length fits' error
TRACED = "traced"   # --limit's default: the limit each trace was made with


def trace_fit(images, start, settings, truth: np.ndarray) -> dict:
    """One fit (:func:`unps.lights.selfcal.fit_once` with ``settings``, never declined), read
    every 100 steps: ``trace`` ``[[step, error, flattening], …]`` and the (n, 3) ``directions`` at
    each of those steps."""
    trace, seen = [], []
    first_guess = start.directions.astype(np.float64)

    def observe(step, directions):
        trace.append([step, float(angular_error(directions, truth).mean()),
                      flattening(directions, first_guess)])
        seen.append(np.round(directions, 7).tolist())

    fit_once(images, start, replace(settings, max_flattening_deg=None), observe)
    return {"trace": trace, "directions": seen}


def trace_case(subject, network, settings) -> dict:
    """The network's and the start's (after the reversal test) direction errors, the held fit's
    trace (:func:`trace_fit`), and the pulled fit's where the held one flattened the lights by more
    than ``settings.max_flattening_deg`` at some read (else None); no fit where the reversal test
    warned, or the network is unsure of the reading (``inside_out``,
    :func:`unps.lights.selfcal.warned_inside_out`, :func:`unps.lights.selfcal.unsure_reading`): the
    default fits those both ways (:func:`unps.lights.selfcal.both_readings`), which this study does
    not trace."""
    start = network(subject)
    truth = subject.light_directions.astype(np.float64)
    limit = settings.max_flattening_deg
    case = {"network": start.verdicts[0].errors["light_dir_mae"],
            "start": float(angular_error(start.directions.astype(np.float64), truth).mean()),
            "max_flattening_deg": limit, "inside_out": False, "held": None, "pulled": None}
    if ((settings.turn_inside_out or settings.decline_inside_out) and warned_inside_out(start)
            or settings.turn_inside_out and unsure_reading(start)):
        return {**case, "inside_out": True}
    images = working_images(subject, start, settings)
    held = trace_fit(images, start, frame_held(settings), truth)
    flattened = limit is not None and max(f for _, _, f in held["trace"]) > limit
    return {**case, "held": held, "pulled": trace_fit(images, start, settings, truth) if flattened else None}


def settled_step(fit: dict, settle_deg: float) -> int:
    """The step at which ``light.selfcal.settle_deg=settle_deg`` stops the fit: the first read,
    short of the last step, where the lights have moved no more than ``settle_deg`` on average
    since the read before (the trace's directions); its last step where none is (or for 0)."""
    steps = [int(step) for step, *_ in fit["trace"]]
    if settle_deg:
        directions = [np.asarray(d) for d in fit["directions"]]
        for k in range(1, len(steps) - 1):
            if angular_error(directions[k], directions[k - 1]).mean() <= settle_deg:
                return steps[k]
    return steps[-1]


def final_read(case: dict, stop) -> tuple[dict | None, int, int]:
    """Where the final lights are read, each fit stopped at ``stop(fit)``: the fit (None: the
    start's lights), the index of its read, and the steps of both fits together. The held fit's
    lights unless they are flattened by more than the limit there, else the pulled fit's under the
    same rule, else the start's (and the start's, without a fit, where the reversal test warned
    that the start may be inside out)."""
    steps = 0
    if case["inside_out"]:
        return None, 0, steps
    for fit in (case["held"], case["pulled"]):
        if fit is None:       # the held fit flattened nowhere, so it was kept
            break
        at = stop(fit)
        steps += at
        index = next(k for k, row in enumerate(fit["trace"]) if int(row[0]) == at)
        limit = case["max_flattening_deg"]
        if limit is None or fit["trace"][index][2] <= limit:
            return fit, index, steps
    return None, 0, steps


def final(case: dict, stop) -> tuple[float, int]:
    """The final lights' direction error and the steps of both fits together (:func:`final_read`)."""
    fit, index, steps = final_read(case, stop)
    return (case["start"] if fit is None else fit["trace"][index][1]), steps


def final_directions(case: dict, stop) -> np.ndarray | None:
    """(n, 3) the final lights (:func:`final_read`); None where no fit was traced (the reversal
    test warned), so the start's directions are not in the traces."""
    fit, index, _ = final_read(case, stop)
    if fit is None:
        return None if case["held"] is None else np.asarray(case["held"]["directions"][0])
    return np.asarray(fit["directions"][index])


def limit_value(text: str) -> float | None | str:
    """A ``--limit`` or ``--limits`` value: degrees, or ``none`` (never decline); ``traced`` (the
    limit the traces were made with) passes as it is."""
    if text == TRACED:
        return TRACED
    if text.lower() in ("none", "null"):
        return None
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give degrees (e.g. 1.5) or none") from None


def with_limit(case: dict, limit: float | None) -> dict:
    """``case`` as its traces read under ``light.selfcal.max_flattening_deg=limit``.

    Raises:
        ValueError: the limit is below the one the traces were made with (or the traces were made
            with none), so the pulled fit it would need was not traced everywhere.
    """
    traced = case["max_flattening_deg"]
    if limit == TRACED:
        return case
    if limit is not None and (traced is None or limit < traced):
        raise ValueError(f"a limit of {limit:g}° cannot be read off traces made with "
                         f"max_flattening_deg={traced}: their pulled fits start above that")
    return {**case, "max_flattening_deg": limit}


def changed_cases(before: list[dict], after: list[dict], names: list[str], stop) -> str:
    """The cases whose final lights move by more than :data:`NOTABLE` from ``before`` to
    ``after`` (the same cases under another limit, :func:`with_limit`), as ``name before → after``."""
    moved = []
    for name, old, new in zip(names, before, after):
        was, now = final(old, stop)[0], final(new, stop)[0]
        if abs(now - was) > NOTABLE:
            moved.append(f"{name} {was:.2f}° → {now:.2f}°")
    return ", ".join(moved) or "none"


def last_read(fit: dict) -> int:
    """The step of a fit's last read: where it stops when nothing stops it sooner."""
    return int(fit["trace"][-1][0])


def summary_line(label: str, cases: list[dict], names: list[str], stop) -> str:
    """One line: the cases' final lights with each fit stopped at ``stop(fit)`` (:func:`final`)."""
    network = np.mean([c["network"] for c in cases])
    done = [final(c, stop) for c in cases]
    at = np.array([error for error, _ in done])
    full = np.array([final(c, last_read)[0] for c in cases])
    raised = at - np.array([c["start"] for c in cases])
    worst, off = int(np.argmax(raised)), at - full
    return (f"  {label:<14}{at.mean():6.2f}°  ratio {at.mean() / network:.3f}  steps "
            f"{np.mean([s for _, s in done]):5.0f}  raised >1°: {int((raised > 1).sum()):>2}  "
            f">2°: {int((raised > 2).sum()):>2}  worst {raised[worst]:+.2f}° ({names[worst]})  vs the "
            f"full length: {int((off > NOTABLE).sum())} above, {int((off < -NOTABLE).sum())} below")


def main(argv=None) -> None:
    parser = benchmark.study_parser(__doc__.split("\n")[0], "where each case's trace is kept "
                                    "(default: <cache>/results/selfcal_steps-<steps>)")
    parser.add_argument("--steps", type=int, default=1000, help="steps of each fit (default 1000)")
    parser.add_argument("--marks", type=int, nargs="+", default=list(MARKS),
                        help="fixed numbers of steps to report (multiples of 100, or --steps)")
    parser.add_argument("--settle", type=float, nargs="*", default=[],
                        help="light.selfcal.settle_deg values to read off the traces")
    parser.add_argument("--limits", type=limit_value, nargs="*", default=[],
                        help="light.selfcal.max_flattening_deg values (degrees, or none) to read off the "
                             "traces, each fit stopped as the first --settle value says")
    parser.add_argument("--limit", type=limit_value, default=TRACED,
                        help="light.selfcal.max_flattening_deg (degrees, or none) the --marks and --settle "
                             "lines are read under (default: the one the traces were made with)")
    parser.add_argument("--set", dest="settings", nargs="*", default=[],
                        help="light.<key>=<value> overrides of both fits, e.g. selfcal.lr_lights=0.006")
    parser.add_argument("--tag", default=None,
                        help="names the results folder with the overrides (default: selfcal_steps-<steps>)")
    args = parser.parse_args(argv)
    bad = [m for m in args.marks if m > args.steps or (m % 100 and m != args.steps)]
    if bad:
        parser.error(f"--marks {bad}: each must be a multiple of 100 up to --steps ({args.steps}), "
                     "or --steps")
    if TRACED in args.limits:
        parser.error("--limits: give degrees or none (traced is --limit's default only)")
    if args.settings and not (args.tag or args.out):
        parser.error("--set: give the run its own --tag (or --out)")
    folder = f"selfcal_steps-{args.steps}" + (f"-{args.tag}" if args.tag else "")
    out = args.out or args.cache / "results" / folder
    every_step = [*args.settings, f"selfcal.steps={args.steps}", "selfcal.settle_deg=0"]
    try:
        light = benchmark.light_settings(["reversal", "selfcal"], every_step)
        settings = benchmark.instantiate_node(["fit"], ["light=selfcal", *(f"light.{s}" for s in every_step)],
                                              "light.selfcal")()
    except (ValueError, ConfigCompositionException) as e:
        parser.error(str(e))
    try:
        with_limit({"max_flattening_deg": settings.max_flattening_deg}, args.limit)
    except ValueError as e:
        parser.error(f"--limit: {e}")
    try:
        runs.claim(out, {"steps": args.steps, "scenes": scenes.SCENE_VERSION, "fits": "held, then pulled",
                         "light": light, "weights": runs.weights_digest(None),
                         **benchmark.capture_options(args)})
    except ValueError as e:
        parser.error(str(e))
    print(f"network → reversal test → self-calibration (the frame held, then pulled where that "
          f"flattens), each fit {args.steps} steps{'; ' + ' '.join(args.settings) if args.settings else ''}; "
          f"results in {out}")
    network, _ = benchmark.light_source(["reversal"], [])

    def progress(case, result, _) -> str:
        group, name, label = case
        result = with_limit(result, args.limit)
        marks = "  ".join(f"{m}: {final(result, lambda fit, m=m: m)[0]:6.2f}°" for m in args.marks)
        note = "  inside out" if result["inside_out"] else "  pulled" if result["pulled"] is not None else ""
        return (f"{group:<10}{name:<12}{label:>4}  network {result['network']:6.2f}°  start "
                f"{result['start']:6.2f}°  {marks}{note}")

    rows = runs.summaries(benchmark.study_cases(args), out,
                          lambda subject: trace_case(subject, network, settings),
                          lambda result: result, progress, args.report)
    print("\n".join(progress(case, result, None) for case, result in rows.items()))
    for group, label, traced in runs.by_light_set(rows):
        cases = [with_limit(case, args.limit) for case in traced]
        names = [name for g, name, lab in rows if (g, lab) == (group, label)]
        network_mean = np.mean([c["network"] for c in cases])
        print(f"\n{group} {label} ({len(cases)} cases; network {network_mean:.2f}°)")
        for mark in args.marks:
            print(summary_line(f"step {mark}", cases, names, lambda fit, mark=mark: mark))
        for value in args.settle:
            print(summary_line(f"settle {value:g}°", cases, names,
                               lambda fit, value=value: settled_step(fit, value)))
        stop = (lambda fit: settled_step(fit, args.settle[0])) if args.settle else last_read
        for limit in args.limits:
            try:
                limited = [with_limit(case, limit) for case in traced]
            except ValueError as e:
                parser.error(f"--limits: {e}")
            label = "no limit" if limit is None else f"limit {limit:g}°"
            print(summary_line(label, limited, names, stop))
            print(f"    changed: {changed_cases(cases, limited, names, stop)}")


if __name__ == "__main__":
    main()

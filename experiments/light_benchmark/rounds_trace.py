"""How many rounds the self-calibration needs: its lights' error after each, on the light benchmark.

    python experiments/light_benchmark/rounds_trace.py --only diligent synthetic          # 6 rounds (~40 min)
    python experiments/light_benchmark/rounds_trace.py --only benchmark --rounds 8 --sets 12
    python experiments/light_benchmark/rounds_trace.py --only diligent synthetic --report

Each case (``benchmark.py``'s) is estimated by the network and the reversal test, then
self-calibrated as the default does (the frame-held fit, or the pulled one where that was
declined; both readings where the reversal test warns or the network is unsure), with
``light.selfcal.rounds=--rounds``: the rounds stop where the default's would (a round that moves
the lights no more than ``settle_deg``, one that would flatten them past the limit, one that
diverges), so the lights kept after round k are those ``light.selfcal.rounds=k`` returns, for
every k up to ``--rounds``. They are read off the fits' ``observe`` calls: each round's fit starts
from the lights the round before kept (its first read), and the last round's lights are those
returned. One json per case in ``<cache>/results/rounds_trace-<rounds>/`` (a rerun resumes).

Printed per case: the network's error, then the lights' error after each round (``·`` where the
rounds had stopped: the same lights as the round before); per group and light set, the mean after
each round, its ratio to the network's, and the cases whose lights after the last round are more
than 0.3° above or below those after the default's 3 rounds.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from hydra.errors import ConfigCompositionException

from unps.lights.selfcal import self_calibrate
from unps.metrics import angular_error

sys.path.insert(0, str(Path(__file__).parent))
import benchmark  # noqa: E402
import runs  # noqa: E402
import scenes  # noqa: E402

DEFAULT_ROUNDS = 3      # light.selfcal.rounds's default, the column the others are compared with
NOTABLE = 0.3           # degrees from the default's rounds


def fit_starts(reads: list[tuple[int, np.ndarray]]) -> list[np.ndarray]:
    """The (n, 3) directions each fit started from, from ``observe``'s ``(step, directions)``
    calls in order: a fit's first read is at step 0, and every fit makes one."""
    return [directions for step, directions in reads if step == 0]


def kept_after_rounds(starts: list[np.ndarray], returned: np.ndarray, made: int) -> list[np.ndarray]:
    """The (n, 3) lights kept after rounds 1 … ``made`` (the verdict's ``rounds``), from the
    fits' starting lights ``starts`` (:func:`fit_starts`) and the lights the stage ``returned``.
    Round k + 1's fit starts from round k's lights, and the round fits are the stage's last,
    with one more after them where a round was made but not kept (it would have flattened the
    lights too far, or diverged): that fit started from the lights returned.

    >>> starts = [np.full((1, 3), k) for k in (0.0, 1.0, 2.0, 9.0)]   # round 3 not kept
    >>> [float(a[0, 0]) for a in kept_after_rounds(starts, np.full((1, 3), 9.0), made=2)]
    [2.0, 9.0]
    >>> [float(a[0, 0]) for a in kept_after_rounds(starts[:3], np.full((1, 3), 9.0), made=2)]
    [2.0, 9.0]
    """
    refused = int(np.allclose(starts[-1], returned, atol=1e-5))
    first = len(starts) - refused - (made - 1)
    return [*starts[first:first + made - 1], returned]


def trace_case(subject, network, settings) -> dict:
    """The network's direction error and the lights' error after each round made (the stage's
    verdict, its evidence and the fits it made read as :func:`kept_after_rounds` says), or only
    the network's where the self-calibration left the lights as they were (declined, or skipped)."""
    start = network(subject)
    truth = subject.light_directions.astype(np.float64)
    reads: list[tuple[int, np.ndarray]] = []
    fitted, verdict = self_calibrate(subject, start, settings,
                                     lambda step, directions: reads.append((step, directions)))
    case = {"network": start.verdicts[0].errors["light_dir_mae"],
            "start": float(angular_error(start.directions.astype(np.float64), truth).mean()),
            "outcome": verdict.outcome, "reason": verdict.reason, "rounds": []}
    if verdict.outcome != "changed" or "rounds" not in verdict.evidence:
        return {**case, "rounds": [float(angular_error(fitted.directions.astype(np.float64), truth).mean())]}
    kept = kept_after_rounds(fit_starts(reads), fitted.directions.astype(np.float64),
                             int(verdict.evidence["rounds"]))
    return {**case, "rounds": [float(angular_error(k, truth).mean()) for k in kept]}


def after_round(case: dict, k: int) -> float:
    """The lights' error after round ``k`` (1-based): that of the last round made where fewer were."""
    return case["rounds"][min(k, len(case["rounds"])) - 1]


def case_line(group: str, name: str, label: str, case: dict, rounds: int) -> str:
    made = len(case["rounds"])
    cells = "".join(f"{after_round(case, k):7.2f}°" if k <= made else f"{'·':>8}"
                    for k in range(1, rounds + 1))
    return f"{group:<10}{name:<12}{label:>4}  network {case['network']:6.2f}° {cells}"


def set_lines(cases: list[dict], names: list[str], rounds: int) -> list[str]:
    """The mean after each round and its ratio to the network's, and the cases the rounds past
    the default's move by more than :data:`NOTABLE`."""
    network = np.mean([c["network"] for c in cases])
    means = [np.mean([after_round(c, k) for c in cases]) for k in range(1, rounds + 1)]
    lines = ["  after round " + "".join(f"{k:>8d}" for k in range(1, rounds + 1)),
             "  mean        " + "".join(f"{m:7.2f}°" for m in means),
             "  ratio       " + "".join(f"{m / network:8.2f}" for m in means)]
    if rounds > DEFAULT_ROUNDS:
        moved = [(name, after_round(c, DEFAULT_ROUNDS), after_round(c, rounds))
                 for name, c in zip(names, cases)]
        for word, sign in (("above", 1), ("below", -1)):
            listed = [f"{n} {a:.2f}° → {b:.2f}°" for n, a, b in moved if sign * (b - a) > NOTABLE]
            lines.append(f"  after round {rounds}, {word} round {DEFAULT_ROUNDS}'s by > {NOTABLE}°: "
                         f"{', '.join(listed) or 'none'}")
    return lines


def main(argv=None) -> None:
    parser = benchmark.study_parser(__doc__.split("\n")[0], "where each case's trace is kept "
                                    "(default: <cache>/results/rounds_trace-<rounds>)")
    parser.add_argument("--rounds", type=int, default=6, help="light.selfcal.rounds (default 6)")
    args = parser.parse_args(argv)
    if args.rounds < 1:
        parser.error(f"--rounds must be at least 1, got {args.rounds}")
    out = args.out or args.cache / "results" / f"rounds_trace-{args.rounds}"
    overrides = [f"selfcal.rounds={args.rounds}"]
    try:
        light = benchmark.light_settings(["reversal", "selfcal"], overrides)
        settings = benchmark.instantiate_node(["fit"], ["light=selfcal", *(f"light.{s}" for s in overrides)],
                                              "light.selfcal")()
        runs.claim(out, {"rounds": args.rounds, "scenes": scenes.SCENE_VERSION, "light": light,
                         "weights": runs.weights_digest(None), **benchmark.capture_options(args)})
    except (ValueError, ConfigCompositionException) as e:
        parser.error(str(e))
    print(f"network → reversal test → self-calibration, up to {args.rounds} rounds; the lights' mean "
          f"direction error after each; results in {out}")
    network, _ = benchmark.light_source(["reversal"], [])

    def progress(case, result, _) -> str:
        return case_line(*case, result, args.rounds)

    rows = runs.summaries(benchmark.study_cases(args), out,
                          lambda subject: trace_case(subject, network, settings),
                          lambda result: result, progress, args.report)
    print("\n".join(progress(case, result, None) for case, result in rows.items()))
    for group, label, traced in runs.by_light_set(rows):
        names = [name for g, name, lab in rows if (g, lab) == (group, label)]
        network_mean = np.mean([c["network"] for c in traced])
        print(f"\n{group} {label} ({len(traced)} cases; network {network_mean:.2f}°)")
        print("\n".join(set_lines(traced, names, args.rounds)))


if __name__ == "__main__":
    main()

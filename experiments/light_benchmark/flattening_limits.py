"""Other limits on flattening, read off two benchmark runs: one with the limit, one without.

    python experiments/light_benchmark/benchmark.py --set selfcal.rounds=1 --tag one
    python experiments/light_benchmark/benchmark.py --set selfcal.rounds=1 \
        selfcal.max_flattening_deg=null --tag free
    python experiments/light_benchmark/flattening_limits.py --limited one --free free --limits 2.5 3 none

``light.selfcal.max_flattening_deg`` only decides, case by case, whether the fit with the shared
frame held is kept: where it flattened the lights by no more than the limit, the lights are that
fit's (the run without a limit has them, and its verdict's ``flattened_deg``); past it, the fit
that takes over (or the lights it started from) is the same under every limit at or above the
limited run's (that run has them). So for each limit at or above the limited run's, a case's final
lights are read from one of the two runs. Not exact where the reversal test warned of a reading
inside out and both readings were fitted (``light.selfcal.turn_inside_out``): there the limit acts
on each reading's fit, and the choice between them on both; such cases are marked ``*``. Read off
runs of one fit each (``--set selfcal.rounds=1``): the limit also decides which later round is
kept (``light.selfcal.rounds``), which neither run records.

Printed per group and light set: the mean final direction error under each limit, the cases it
raises by more than 1° and 2° over the start (after the reversal test), and the cases whose held fit
flattened past the limited run's limit with the two runs' errors.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import benchmark  # noqa: E402

BOTH_READINGS = "fitted as read and half turned"


def case_row(result: dict) -> dict:
    """The direction errors of one case's result json that a limit picks between: the network's,
    the start's (after the stages before the self-calibration), the final one; the held fit's
    flattening (NaN where it made none), whether both readings were fitted, and the limit the
    case was run under (None: none)."""
    stages = {s["stage"]: s for s in result["stages"]}
    selfcal = stages.get("selfcal", {})
    start = [s for s in result["stages"] if s["stage"] != "selfcal"][-1]
    flattened = selfcal.get("evidence", {}).get("frame_held_flattened_deg",
                                                selfcal.get("evidence", {}).get("flattened_deg", np.nan))
    return {"network": stages["network"]["dir"], "start": start["dir"], "final": result["stages"][-1]["dir"],
            "flattened": float(flattened), "both": BOTH_READINGS in selfcal.get("reason", ""),
            "limit": result["light"]["selfcal"]["max_flattening_deg"],
            "rounds": result["light"]["selfcal"].get("rounds", 1)}


def read_run(folder: Path) -> dict[str, dict]:
    """``{case: case_row}`` for every case json in a benchmark run folder."""
    return {path.stem: case_row(json.loads(path.read_text()))
            for path in sorted(folder.glob("*-*.json")) if path.name != "settings.json"}


def group_of(case: str) -> str:
    """The benchmark group of a case's name (``group-object-set``)."""
    return next(g for g in benchmark.GROUPS if case.startswith(g + "-"))


def under_limit(limited: dict, free: dict, limit: float | None) -> float:
    """A case's final error under ``limit`` (None: none), from its rows in the run with the
    limit and the one without."""
    if limit is None or not free["flattened"] > limit:
        return free["final"]
    return limited["final"]


def limit_value(text: str) -> float | None:
    """A --limits value: degrees ≥ 0, or none."""
    if text.lower() in ("none", "null"):
        return None
    value = float(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text}: a limit is degrees >= 0, or none")
    return value


def report(limited_run: dict, free_run: dict, limits: list[float | None], below: float) -> list[str]:
    """The lines printed: per group and light set, each limit's mean and raises, then the cases
    whose held fit flattened past ``below`` (the limited run's limit) and whose two runs differ."""
    common = sorted(set(limited_run) & set(free_run))
    keys = sorted({(group_of(case), case.rsplit("-", 1)[1]) for case in common},
                  key=lambda k: (benchmark.GROUPS.index(k[0]), -int(k[1])))
    lines = []
    for group, label in keys:
        cases = [c for c in common if group_of(c) == group and c.endswith("-" + label)]
        network = np.mean([limited_run[c]["network"] for c in cases])
        lines.append(f"{group} {label} ({len(cases)} cases; network {network:.2f}°)")
        for limit in limits:
            final = np.array([under_limit(limited_run[c], free_run[c], limit) for c in cases])
            raised = final - np.array([limited_run[c]["start"] for c in cases])
            name = "no limit" if limit is None else f"limit {limit:g}°"
            lines.append(f"  {name:<12}{final.mean():6.2f}°  ratio {final.mean() / network:.3f}  raised "
                         f">1°: {int((raised > 1).sum()):>2}  >2°: {int((raised > 2).sum()):>2}")
        for c in cases:
            differ = abs(free_run[c]["final"] - limited_run[c]["final"]) > 0.005
            if free_run[c]["flattened"] > below and differ:
                mark = "*" if free_run[c]["both"] or limited_run[c]["both"] else " "
                lines.append(f"    {c:<28}{mark} flattened {free_run[c]['flattened']:5.2f}°  "
                             f"limited {limited_run[c]['final']:6.2f}° → free {free_run[c]['final']:6.2f}°  "
                             f"(start {limited_run[c]['start']:6.2f}°)")
    return lines


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--results", type=Path, default=benchmark.DEFAULT_CACHE / "results",
                        help="the benchmark's results folder")
    parser.add_argument("--limited", required=True, help="tag of the run with the limit")
    parser.add_argument("--free", required=True, help="tag of the run with selfcal.max_flattening_deg=null")
    parser.add_argument("--limits", type=limit_value, nargs="+", default=[2.0, 3.0, None])
    args = parser.parse_args(argv)
    runs = {}
    for tag in (args.limited, args.free):
        runs[tag] = read_run(args.results / tag)
        if not runs[tag]:
            parser.error(f"{args.results / tag}: no benchmark results there")
        rounds = {row["rounds"] for row in runs[tag].values()} - {1}
        if rounds:
            parser.error(f"{tag}: its cases were run with selfcal.rounds={sorted(rounds)}, not 1: each "
                         f"round after the first is kept or not by the limit too, which a run "
                         f"without it does not record")
    free_limits = {row["limit"] for row in runs[args.free].values()}
    if free_limits != {None}:
        parser.error(f"--free {args.free}: its cases were run with limits {sorted(free_limits, key=str)}, "
                     "not selfcal.max_flattening_deg=null")
    limited_limits = {row["limit"] for row in runs[args.limited].values()}
    if None in limited_limits or len(limited_limits) != 1:
        parser.error(f"--limited {args.limited}: its cases were run with limits "
                     f"{sorted(limited_limits, key=str)}, not one limit")
    floor = float(limited_limits.pop())
    low = [limit for limit in args.limits if limit is not None and limit < floor]
    if low:
        parser.error(f"--limits {low}: below the limited run's {floor:g}°, which cannot be read off it")
    print(f"limits on flattening read off {args.results / args.limited} (limit {floor:g}°) and "
          f"{args.results / args.free} (none)")
    print("\n".join(report(runs[args.limited], runs[args.free], args.limits, floor)))


if __name__ == "__main__":
    main()

"""The network's error against how far from the view its lights stand, under the drawn rigs and DiLiGenT's.

    python experiments/light_benchmark/reach.py            # both groups, every light set: ~2 min
    python experiments/light_benchmark/reach.py --report   # the tables from the cases run so far

Each object of the benchmark is lit twice: by a rig drawn as the light network's training draws
them (``benchmark`` group, :func:`scenes.draw_rig`: 96-light domes reaching 17–50° from the view)
and by DiLiGenT's own dome (``diligent-rig``, :func:`scenes.diligent_rig`: 43°, its 20 and 12
evenly spread sets reaching its edge). Per case the network's lights (``light=selfcal``'s first
stage, eight passes, no stage after it) are compared light by light with the truth: each light's
zenith (its angle from the view axis), its direction error and its zenith error (estimate − truth,
< 0 where it is read nearer the view). Two tables, both without the objects every network reads
inside out (:data:`by_material.INSIDE_OUT`, whose 40–70° would swamp the rest):

- **by the drawn rig's reach**: the objects binned by how far the drawn rig's farthest light
  stands, each bin's mean error under both rigs;
- **by each light's zenith**: every light of every object binned by its own zenith, the mean
  error and zenith error per bin under both rigs, and what DiLiGenT's rig would give if each of
  its lights were read as well as a drawn rig's light at the same zenith (``as drawn``): the part
  of the gap the lights' zeniths explain.

Results are kept case by case in ``--out`` (default ``<cache>/reach``); a rerun resumes. None of
it feeds training.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import benchmark  # noqa: E402
import scenes  # noqa: E402
from by_material import INSIDE_OUT  # noqa: E402

from unps.metrics import angular_error  # noqa: E402

REACH_BINS = ((0.0, 25.0), (25.0, 40.0), (40.0, 90.0))
"""Bins of the drawn rigs' reach, degrees from the view axis; DiLiGenT's dome falls in the last."""
ZENITH_BINS = ((0.0, 10.0), (10.0, 20.0), (20.0, 30.0), (30.0, 40.0), (40.0, 90.0))
"""Bins of a light's own zenith, degrees."""
GROUPS = ("benchmark", "diligent-rig")


VIEW = np.array([0.0, 0.0, 1.0])


def zenith_deg(directions: np.ndarray) -> np.ndarray:
    """(n,) angles in degrees between the (n, 3) light directions and the view axis +z.

    >>> zenith_deg(np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]])).round(2).tolist()
    [0.0, 36.87]
    """
    return angular_error(directions, VIEW)


def run_case(subject, network) -> dict:
    """Light by light: the true zenith, the network's direction error and zenith error (degrees)."""
    estimate, truth = network(subject).directions, subject.light_directions
    zenith = zenith_deg(truth)
    return {"zenith": zenith.tolist(), "error": angular_error(estimate, truth).tolist(),
            "zenith_error": (zenith_deg(estimate) - zenith).tolist()}


def paired_objects(rows: dict, label: str) -> list[str]:
    """The objects of light set ``label`` run under both rigs, less :data:`INSIDE_OUT`, sorted."""
    return sorted(name for group, name, set_ in rows if group == GROUPS[0] and set_ == label
                  and (GROUPS[1], name, label) in rows and name not in INSIDE_OUT)


def by_reach(rows: dict) -> str:
    """Per light set and bin of the drawn rig's reach: the objects' mean error under both rigs."""
    lines = [f"{'lights':>6} {'drawn reach':>12} {'objects':>8} {'drawn rig':>10} {'DiLiGenT rig':>13}"]
    for label in scenes.LIGHT_SETS:
        names = paired_objects(rows, label)
        if not names:
            continue
        mean = {(g, n): float(np.mean(rows[g, n, label]["error"])) for g in GROUPS for n in names}
        reach = {n: max(rows[GROUPS[0], n, label]["zenith"]) for n in names}
        for low, high in (*REACH_BINS, (0.0, 90.0)):
            chosen = [n for n in names if low <= reach[n] < high]
            if chosen:
                span = "all" if (low, high) == (0.0, 90.0) else f"{low:.0f}–{high:.0f}°"
                lines.append(f"{label:>6} {span:>12} {len(chosen):>8} "
                             + " ".join(f"{np.mean([mean[g, n] for n in chosen]):>{w}.2f}°"
                                        for g, w in zip(GROUPS, (9, 12))))
    return "\n".join(lines)


def by_zenith(rows: dict) -> str:
    """Per light set and bin of a light's own zenith: lights, mean error and mean zenith error
    under both rigs; then each rig's mean and DiLiGenT's rig read as the drawn one per bin."""
    lines = [f"{'lights':>6} {'zenith':>8}" + "".join(
        f"  {f'{g}: lights':>20} {'error':>7} {'zenith err':>10}" for g in GROUPS)]
    edges = [low for low, _ in ZENITH_BINS[1:]]
    for label in scenes.LIGHT_SETS:
        names = paired_objects(rows, label)
        if not names:
            continue
        pooled = {g: {k: np.concatenate([rows[g, n, label][k] for n in names])
                      for k in ("zenith", "error", "zenith_error")} for g in GROUPS}
        bins = {g: np.digitize(pooled[g]["zenith"], edges) for g in GROUPS}
        drawn_error = {}
        for k, (low, high) in enumerate(ZENITH_BINS):
            cells = []
            for g in GROUPS:
                inside = bins[g] == k
                error, tilt = pooled[g]["error"][inside], pooled[g]["zenith_error"][inside]
                if inside.any() and g == GROUPS[0]:
                    drawn_error[k] = error.mean()
                cells.append(f"  {int(inside.sum()):>20} " + (f"{error.mean():>6.2f}° {tilt.mean():>+9.2f}°"
                                                            if inside.any() else f"{'–':>7} {'–':>10}"))
            lines.append(f"{label:>6} {f'{low:.0f}–{high:.0f}°':>8}" + "".join(cells))
        dome_bins = bins[GROUPS[1]]
        read_as_drawn = (f"{np.mean([drawn_error[k] for k in dome_bins]):.2f}°"
                         if set(dome_bins.tolist()) <= set(drawn_error) else
                         "– (a zenith bin the drawn rig leaves empty)")
        lines.append(f"{label:>6} {'all':>8} drawn rig {pooled[GROUPS[0]]['error'].mean():.2f}°, "
                     f"DiLiGenT's {pooled[GROUPS[1]]['error'].mean():.2f}°, DiLiGenT's lights read as "
                     f"drawn ones at their zenith {read_as_drawn}")
    return "\n".join(lines)


def report(rows: dict) -> str:
    names = sorted({n for _, n, _ in rows} - set(INSIDE_OUT))
    return (f"network's lights, {len(names)} objects read the right way round "
            f"(without {', '.join(INSIDE_OUT)})\n\nby the drawn rig's reach\n{by_reach(rows)}\n\n"
            f"by each light's zenith\n{by_zenith(rows)}")


def progress(case: tuple, row: dict, result: dict) -> str:
    return f"{' '.join(case)}: error {np.mean(row['error']):.2f}°, reach {max(row['zenith']):.1f}°"


def main() -> None:
    parser = benchmark.study_parser(__doc__.split("\n")[0], "default: <cache>/reach", groups=GROUPS)
    args = parser.parse_args()
    out = args.out or args.cache / "reach"
    benchmark.network_study(parser, args, out, {"scenes": scenes.SCENE_VERSION, "study": "reach"},
                            run_case, report, progress)


if __name__ == "__main__":
    main()

"""The network's error against how far from the view its lights reach, under the drawn rigs and DiLiGenT's.

    python experiments/light_benchmark/reach.py --tag netT       # results of benchmark.py --tag …
    python experiments/light_benchmark/reach.py --tag netT --final

Each object of the benchmark is lit twice: by a rig drawn as the light network's training draws
them (``benchmark`` group, :func:`scenes.draw_rig`) and by DiLiGenT's own dome (``diligent-rig``,
:func:`scenes.diligent_rig`). A rig's reach is the largest angle between one of its lights and the
view axis (drawn 96-light domes: 17–50°; DiLiGenT's dome 43°, and its 20 and 12 evenly spread
sets reach its edge). For each light set, the cases are binned by the drawn rig's reach, and each
bin prints the mean direction error of the same objects under both rigs (the network's, the first
stage of each case; with ``--final``, the last stage's), less the objects that every network reads
inside out (:data:`by_material.INSIDE_OUT`, whose 40–70° would swamp the rest).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import scenes  # noqa: E402
from benchmark import DEFAULT_CACHE, DEFAULT_DATA  # noqa: E402
from by_material import INSIDE_OUT, stage_errors  # noqa: E402

BINS = ((0.0, 25.0), (25.0, 40.0), (40.0, 90.0))
"""Reach bins of the drawn rigs, in degrees from the view axis; DiLiGenT's dome falls in the last."""


def reach_deg(directions: np.ndarray) -> float:
    """The largest angle (degrees) between one of the (n, 3) unit light directions and the view
    axis +z.

    >>> round(reach_deg(np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]])), 2)
    36.87
    """
    return float(np.degrees(np.arccos(np.clip(directions[:, 2], -1, 1))).max())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    parser.add_argument("--tag", required=True,
                        help="a results folder of benchmark.py --tag holding both groups")
    parser.add_argument("--final", action="store_true", help="the last stage's error, not the network's")
    args = parser.parse_args()
    results = args.cache / "results" / args.tag
    if not results.is_dir():
        parser.error(f"no results folder for --tag {args.tag} in {args.cache / 'results'}")
    drawn, dome = (stage_errors(results, group, args.final) for group in ("benchmark", "diligent-rig"))
    dome_rig = scenes.diligent_rig(args.data)
    names = [obj.name for obj in scenes.OBJECTS if obj.name not in INSIDE_OUT]
    print(("final lights" if args.final else "network") + f" (tag {args.tag}): direction error of the "
          f"{len(names)} objects read the right way round, binned by the drawn rig's reach")
    print(f"{'lights':>6} {'drawn reach':>12} {'objects':>8} {'drawn rig':>10} {'DiLiGenT rig':>13}")
    for label in scenes.LIGHT_SETS:
        reaches = {obj.name: reach_deg(scenes.draw_rig(obj.seed).directions[label]) for obj in scenes.OBJECTS}
        cases = [name for name in names if (name, label) in drawn and (name, label) in dome]
        for low, high in BINS:
            chosen = [name for name in cases if low <= reaches[name] < high]
            if chosen:
                print(f"{label:>6} {f'{low:.0f}–{high:.0f}°':>12} {len(chosen):>8} "
                      f"{np.mean([drawn[n, label] for n in chosen]):>9.2f}° "
                      f"{np.mean([dome[n, label] for n in chosen]):>12.2f}°")
        print(f"{label:>6} {'all':>12} {len(cases):>8} {np.mean([drawn[n, label] for n in cases]):>9.2f}° "
              f"{np.mean([dome[n, label] for n in cases]):>12.2f}°   (DiLiGenT's set reaches "
              f"{reach_deg(dome_rig.directions[label]):.1f}°)")


if __name__ == "__main__":
    main()

"""The light network's error by material: objects of one material, matte or glossy, beside the painted ones.

    python experiments/light_benchmark/by_material.py --tags runI runP     # results of benchmark.py --tag …
    python experiments/light_benchmark/by_material.py --tags runP-default --final
    python experiments/light_benchmark/by_material.py --tags runP-slant --slant [--final]  # which way

Reads the network's direction error (the first stage of each case; with ``--final``, the last
stage's) from ``<cache>/results/<tag>`` for the ``single`` group (``benchmark.py --only single``:
each object in the first of its materials alone) and the ``benchmark`` group (the same objects
painted in two or three), and prints, per tag, the mean over the objects of each kind under
96 / 20 / 12 lights:

- **matte**: the single-material objects whose material's mirror peak is under
  :data:`GLOSSY_PEAK` times its off-peak value (:func:`gloss`), less those that every network
  reads inside out (:data:`INSIDE_OUT`, whose 40–70° would swamp the rest);
- **glossy**: the other single-material objects;
- **painted**: the benchmark group, the same objects less :data:`INSIDE_OUT`.

With ``--slant``, the lights' slant bias instead (``light_slant_bias``, recorded by
``benchmark.py`` since 2026-12-01, late: < 0 where the lights are read nearer the view axis than
they are).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
import scenes  # noqa: E402
from benchmark import DEFAULT_CACHE, DEFAULT_DATA  # noqa: E402

from unps.lightnet.brdf import read_neural_brdf  # noqa: E402

GLOSSY_PEAK = 10.0
"""A material is glossy when π·f at the mirror direction of a light 30° off the normal is this many
times π·f toward the view along the normal (a Lambertian material: 1; the benchmark's matte MERL
materials 1.1–7.8, the others 240 and above)."""
INSIDE_OUT = ("pot-shard", "rose")


def gloss(brdf) -> float:
    """π·f(l, mirror of l) / π·f(l, n) for l 30° off the normal: how far the mirror peak stands out.

    ``brdf(wi, wo)`` takes (m, 3) unit directions in the surface frame (z the normal) and gives
    (m, 3) RGB values; the ratio is of their means.
    """
    t = math.radians(30)
    light = torch.tensor([[math.sin(t), 0.0, math.cos(t)]])
    mirror = torch.tensor([[-math.sin(t), 0.0, math.cos(t)]])
    normal = torch.tensor([[0.0, 0.0, 1.0]])
    with torch.no_grad():
        return float(brdf(light, mirror).mean()) / max(float(brdf(light, normal).mean()), 1e-12)


def kinds(data: Path) -> dict[str, str]:
    """Each benchmark object's kind in the single group: 'matte', 'glossy' or 'inside out'."""
    out = {}
    for obj in scenes.SINGLE_MATERIAL:
        if obj.name in INSIDE_OUT:
            out[obj.name] = "inside out"
            continue
        brdf = read_neural_brdf(data / "merl_nbrdf" / f"{obj.materials[0]}.h5")
        out[obj.name] = "glossy" if gloss(brdf) >= GLOSSY_PEAK else "matte"
    return out


def stage_errors(results: Path, group: str, final: bool = False,
                 key: str = "dir") -> dict[tuple[str, str], float]:
    """{(object, light set): the direction error (``key="slant"``: the slant bias) after the
    network (or, ``final``, after the last stage)} of one group in a results folder; a case whose
    result has no such figure (made before it was recorded) is left out."""
    out = {}
    for path in results.glob(f"{group}-*.json"):
        name, label = path.stem[len(group) + 1:].rsplit("-", 1)
        stage = json.loads(path.read_text())["stages"][-1 if final else 0]
        if key in stage:
            out[name, label] = stage[key]
    return out


def means(errors: dict[tuple[str, str], float], names, sign: str = "") -> str:
    """'a / b / c°' over ``names`` under 96, 20 and 12 lights ('–' where a case is missing);
    ``sign="+"`` writes the sign of each."""
    cells = []
    for label in scenes.LIGHT_SETS:
        values = [errors.get((name, label)) for name in names]
        cells.append("–" if not values or None in values else f"{np.mean(values):{sign}.2f}")
    return "–" if set(cells) == {"–"} else " / ".join(cells) + "°"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    parser.add_argument("--tags", nargs="+", required=True, help="results folders of benchmark.py --tag")
    parser.add_argument("--final", action="store_true", help="the last stage's error, not the network's")
    parser.add_argument("--slant", action="store_true",
                        help="the slant bias (< 0: lights read nearer the view axis), not the error")
    args = parser.parse_args()
    missing = [tag for tag in args.tags if not (args.cache / "results" / tag).is_dir()]
    if missing:
        parser.error(f"no results folder for --tags {' '.join(missing)} in {args.cache / 'results'}")
    kind = kinds(args.data)
    matte = sorted(n for n, k in kind.items() if k == "matte")
    glossy = sorted(n for n, k in kind.items() if k == "glossy")
    print(f"matte ({len(matte)}): {' '.join(matte)}\nglossy ({len(glossy)}): {' '.join(glossy)}\n"
          f"left out (read inside out by every network): {' '.join(INSIDE_OUT)}\n")
    figure, key, sign = (("slant bias", "slant", "+") if args.slant else ("direction error", "dir", ""))
    print(("final lights" if args.final else "network") + f" ({figure} under 96 / 20 / 12 lights)")
    print(f"{'tag':<16} {'one material, matte':>24} {'one material, glossy':>24} {'painted':>24}")
    for tag in args.tags:
        results = args.cache / "results" / tag
        single, painted = (stage_errors(results, group, args.final, key) for group in ("single", "benchmark"))
        print(f"{tag:<16} {means(single, matte, sign):>24} {means(single, glossy, sign):>24} "
              f"{means(painted, matte + glossy, sign):>24}")


if __name__ == "__main__":
    main()

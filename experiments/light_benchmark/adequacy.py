"""Free the lights where the held fit's model already renders the images? A keep-or-discard test
for the free self-calibration that asks how much of the images the model leaves unexplained.

    python experiments/light_benchmark/benchmark.py --tag base \
        --set selfcal.frame_held_first=false                   # the held fit, the default until 2026-12-02
    python experiments/light_benchmark/benchmark.py --tag free --set selfcal.frame_held_first=false \
        selfcal.prior_weight=0 selfcal.max_flattening_deg=null        # the lights free
    python experiments/light_benchmark/adequacy.py --held base --free free

The self-calibration held near the network's lights (``prior_weight=0.003``) gains
little; with the lights free it finds DiLiGenT's cat (5.6° → 1.8°) and drifts by tens of degrees
elsewhere (``subsets.py``, ``starts.py``). The drifts were put down to what the model cannot render
(spatially varying gloss, interreflections, 8-bit floors): the fit spends light error to absorb
it. If so, the free fit should be safe where the held fit already explains the images. Per case
present in both results folders of ``benchmark.py`` (the reversal test's warned readings, which
neither fits, left out), this reads:

- *residual*: the held fit's image loss (its objective less the prior's pull; mean absolute error
  in units of the images' 99th percentile) over the mean image value on the object in the same
  units — the share of the images the held fit leaves unexplained;
- *bought*: 1 − the free fit's image loss over the held fit's — what freeing the lights buys;
- *moved*: how far the free fit moved the lights (degrees);

and their rank correlation with the free fit's gain over the held fit (held error − free error),
and what keeping the free fit where the residual is below each quartile would give per light
count. It reads the captures again for the mean image value (seconds a case). None of it feeds
training.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

sys.path.insert(0, str(Path(__file__).resolve().parent))
import benchmark  # noqa: E402
import scenes  # noqa: E402

FEATURES = ("residual", "bought", "moved")


def image_loss(stage: dict) -> float:
    """The self-calibration's image loss: its final objective less the prior's pull."""
    evidence = stage["evidence"]
    return float(evidence["loss"] - evidence.get("prior", 0.0))


def features(held: dict, free: dict, level: float) -> dict | None:
    """One case's figures from two ``benchmark.py`` results (their stages ending in selfcal; the
    start is the stage before it) and the mean image value on the object over the images' 99th
    percentile; None where the self-calibration did not fit (declined before fitting, as where the
    reversal test warned).

    >>> stage = lambda d, loss, moved: {"stage": "selfcal", "dir": d,
    ...                                 "evidence": {"loss": loss, "prior": 0.001, "moved_deg": moved}}
    >>> held = {"stages": [{"stage": "reversal", "dir": 5.0}, stage(4.0, 0.011, 1.0)]}
    >>> free = {"stages": [{"stage": "reversal", "dir": 5.0}, stage(2.0, 0.006, 3.0)]}
    >>> {k: round(v, 3) for k, v in features(held, free, 0.2).items()}
    {'start': 5.0, 'held': 4.0, 'free': 2.0, 'gain': 2.0, 'residual': 0.05, 'bought': 0.5, 'moved': 3.0}
    """
    h, f = ({s["stage"]: s for s in r["stages"]} for r in (held, free))
    if any("loss" not in (fit["selfcal"].get("evidence") or {}) for fit in (h, f)):
        return None
    before = held["stages"][[s["stage"] for s in held["stages"]].index("selfcal") - 1]
    return {"start": before["dir"], "held": h["selfcal"]["dir"], "free": f["selfcal"]["dir"],
            "gain": h["selfcal"]["dir"] - f["selfcal"]["dir"],
            "residual": image_loss(h["selfcal"]) / level,
            "bought": 1 - image_loss(f["selfcal"]) / image_loss(h["selfcal"]),
            "moved": float(f["selfcal"]["evidence"]["moved_deg"])}


def kept(rows: list[dict], threshold: float) -> tuple[float, float]:
    """Mean error and worst raise over the held fit when the free fit is kept where the residual
    is below ``threshold`` and the held fit elsewhere.

    >>> kept([{"residual": 0.1, "held": 3.0, "free": 1.0}, {"residual": 0.3, "held": 2.0, "free": 9.0}], 0.2)
    (1.5, 0.0)
    """
    chosen = [(r["free"] if r["residual"] < threshold else r["held"], r["held"]) for r in rows]
    return float(np.mean([c for c, _ in chosen])), float(max(c - h for c, h in chosen))


def level_of(subject) -> float:
    """Mean image value on the object over the images' 99th percentile there."""
    values = subject.observed_images()[:, subject.mask]
    return float(values.mean() / max(np.quantile(values, 0.99), 1e-12))


def report(rows: dict) -> str:
    """Per case (sorted by residual) its figures; then the rank correlations and, per light
    count, the threshold rule at the residual's quartiles."""
    lines = [f"{'group':<9} {'case':<12} {'set':>3} {'start':>7} {'held':>7} {'free':>7} {'gain':>7} "
             f"{'residual':>8} {'bought':>7} {'moved':>6}"]
    for (group, name, label), r in sorted(rows.items(), key=lambda kv: kv[1]["residual"]):
        lines.append(f"{group:<9} {name:<12} {label:>3} {r['start']:>6.2f}° {r['held']:>6.2f}° "
                     f"{r['free']:>6.2f}° {r['gain']:>+7.2f} {r['residual']:>8.3f} {r['bought']:>7.2f} "
                     f"{r['moved']:>6.1f}")
    values = list(rows.values())
    gains = np.array([r["gain"] for r in values])
    lines.append(f"\n{len(values)} cases; the free fit better than the held one on {int((gains > 0).sum())}, "
                 f"worse by more than 1° on {int((gains < -1).sum())}")
    lines.append("rank correlation with the free fit's gain: " + ", ".join(
        f"{key} {spearmanr([r[key] for r in values], gains)[0]:+.2f}" for key in FEATURES))
    quartiles = np.quantile([r["residual"] for r in values], [0.25, 0.5, 0.75])
    lines.append(f"\n{'set':>4} {'cases':>5} {'held':>7} {'free':>7}  "
                 + "  ".join(f"{'residual < %.3f' % q:>22}" for q in quartiles))
    groups = [(label, "", [r for (group, _, lab), r in rows.items() if lab == label and group != "synthetic"])
              for label in scenes.LIGHT_SETS]
    renders = [r for (group, _, _), r in rows.items() if group == "synthetic"]
    groups.append(("100", "   (unps's renders)", renders))
    for label, note, chosen in groups:
        if chosen:
            lines.append(rule_row(label, chosen, quartiles) + note)
    return "\n".join(lines)


def rule_row(label: str, chosen: list[dict], thresholds) -> str:
    """One light count's mean held and free error and the threshold rule at each threshold."""
    cells = ["%6.2f° (worst %+6.2f°)" % kept(chosen, t) for t in thresholds]
    return (f"{label:>4} {len(chosen):>5} {np.mean([r['held'] for r in chosen]):>6.2f}° "
            f"{np.mean([r['free'] for r in chosen]):>6.2f}°  " + "  ".join(f"{c:>22}" for c in cells))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=benchmark.DEFAULT_DATA)
    parser.add_argument("--cache", type=Path, default=benchmark.DEFAULT_CACHE)
    parser.add_argument("--held", required=True, help="tag of benchmark.py's run with the held fit")
    parser.add_argument("--free", required=True, help="tag of benchmark.py's run with the lights free")
    args = parser.parse_args()
    held_dir, free_dir = (args.cache / "results" / tag for tag in (args.held, args.free))
    rows = {}
    for group, name, label, read in benchmark.cases(benchmark.GROUPS, list(scenes.LIGHT_SETS),
                                                    args.data, args.cache):
        file = f"{group}-{name}-{label}.json"
        if not ((held_dir / file).is_file() and (free_dir / file).is_file()):
            continue
        held, free = (json.loads((d / file).read_text()) for d in (held_dir, free_dir))
        row = features(held, free, level_of(read()))
        if row is not None:
            rows[group, name, label] = row
    if not rows:
        parser.error(f"no case has run in both {held_dir} and {free_dir}")
    print(report(rows))


if __name__ == "__main__":
    main()

"""What a capture without a mask costs the lights: the default light stages with the true mask and
with the mask unps finds itself (``subject.mask=auto``), and how far the light network moves when
only the mask's outline changes.

    python experiments/light_benchmark/mask_outline.py --only benchmark diligent --sets 20 12
    python experiments/light_benchmark/mask_outline.py --report      # the tables from what has run
    python experiments/light_benchmark/mask_outline.py --network-only --checkpoint W.pt --out DIR

Per case, four masks: the true one; the automatic one (:func:`unps.data.automask.auto_mask` on
the captured images, as a folder without ``mask.png`` is read); the true one less its outline
(one pixel eroded) and with one pixel more (dilated). Under each, the light network's estimate
(``light=estimated``'s eight passes, no stage after them); under the true and the automatic
mask, the default stages too (``light=selfcal``: network, reversal test, self-calibration), as
``python -m unps.fit`` runs them. The benchmark's captures are rendered with the mask of the
pixels the object covers whole and nothing outside it (``scenes.py``), so their outline holds
no pixel partly object and partly background; DiLiGenT's photographs do, and their masks were
drawn to include them, as ``--outline partial`` renders and masks the benchmark's.
``--network-only`` leaves the default stages out; ``--checkpoint`` reads other weights (give each
its own ``--out``). None of it feeds a stage. Results are kept case by
case in ``--out`` (default ``<cache>/mask_outline``); a rerun resumes.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy import ndimage

from unps.data.automask import auto_mask

sys.path.insert(0, str(Path(__file__).resolve().parent))
import benchmark  # noqa: E402
import runs  # noqa: E402

NETWORK_MASKS = ("true", "auto", "eroded", "dilated")
STAGED_MASKS = ("true", "auto")


def masks(subject) -> dict[str, np.ndarray]:
    """The four (H, W) bool masks a case is read with (module docstring)."""
    true = subject.mask
    return {"true": true, "auto": auto_mask(subject.observed_images()).mask,
            "eroded": ndimage.binary_erosion(true, border_value=1), "dilated": ndimage.binary_dilation(true)}


def run_case(subject, network, default=None) -> dict:
    """The network's direction error under each mask, the default stages' under the true and the
    automatic one (each stage's, as :func:`benchmark.run_case` records them; none without
    ``default``), and how many
    pixels each mask misses and adds against the true one."""
    found = masks(subject)
    result = {"missed": {k: int((subject.mask & ~m).sum()) for k, m in found.items()},
              "added": {k: int((m & ~subject.mask).sum()) for k, m in found.items()},
              "pixels": int(subject.mask.sum()), "network": {}, "default": {}}
    for name in STAGED_MASKS if default is not None else ():
        result["default"][name] = benchmark.run_case(default, subject.replace(mask=found[name]))["stages"]
    for name in NETWORK_MASKS:   # the default's first stage is the network's estimate
        stages = result["default"].get(name) or \
            benchmark.run_case(network, subject.replace(mask=found[name]))["stages"]
        result["network"][name] = stages[0]["dir"]
    return result


def summarise(result: dict) -> dict:
    row = {f"net_{k}": v for k, v in result["network"].items()}
    row |= {f"final_{k}": stages[-1]["dir"] for k, stages in result["default"].items()} or \
        {f"final_{k}": float("nan") for k in STAGED_MASKS}
    row["auto_missed"], row["auto_added"] = result["missed"]["auto"], result["added"]["auto"]
    row["auto_share"] = (row["auto_missed"] + row["auto_added"]) / result["pixels"]
    return row


def progress(case, row: dict, result: dict) -> str:
    group, name, label = case
    final = ("" if np.isnan(row["final_true"]) else
             f"   final: true {row['final_true']:6.2f}°  auto {row['final_auto']:6.2f}°")
    return (f"{group:<12} {name:<12} {label:>3}  network: true {row['net_true']:6.2f}°"
            f"  auto {row['net_auto']:6.2f}°  eroded {row['net_eroded']:6.2f}°"
            f"  dilated {row['net_dilated']:6.2f}°{final}"
            f"   auto mask misses {row['auto_missed']}, adds {row['auto_added']} pixels")


def report(rows: dict) -> str:
    staged = any(not np.isnan(s["final_true"]) for s in rows.values())
    columns = [f"net_{k}" for k in NETWORK_MASKS] + ([f"final_{k}" for k in STAGED_MASKS] if staged else [])
    lines = ["mean direction error        cases   " + "  ".join(f"{c:>13}" for c in columns)
             + ("   auto worse by >1° (final)" if staged else "   auto worse by >1° (network)")
             + "   auto mask off by >3 % of the object"]
    stage = "final" if staged else "net"
    for group, label, summaries in runs.by_light_set(rows):
        means = [np.mean([s[c] for s in summaries]) for c in columns]
        worse = sum(s[f"{stage}_auto"] - s[f"{stage}_true"] > 1 for s in summaries)
        off = sum(s["auto_share"] > 0.03 for s in summaries)
        lines.append(f"{group:<12} {label:>3} lights  {len(summaries):>5}   "
                     + "  ".join(f"{m:12.2f}°" for m in means) + f"   {worse:>10} of {len(summaries):<14}"
                     + f"   {off} of {len(summaries)}")
    if not staged:
        return "\n".join(lines)
    lines.append("")
    lines.append("largest losses to the automatic mask (default stages):")
    losses = sorted(rows.items(), key=lambda kv: kv[1]["final_true"] - kv[1]["final_auto"])[:8]
    for (group, name, label), s in losses:
        lines.append(f"  {group:<12} {name:<12} {label:>3}: {s['final_true']:6.2f}° → "
                     f"{s['final_auto']:6.2f}° (network {s['net_true']:.2f}° → {s['net_auto']:.2f}°; the "
                     f"mask misses {s['auto_missed']} and adds {s['auto_added']} pixels)")
    return "\n".join(lines)


def main() -> None:
    parser = benchmark.study_parser(__doc__.split("\n")[0], "default: <cache>/mask_outline",
                                    groups=("benchmark", "diligent"))
    parser.add_argument("--network-only", action="store_true", help="leave the default stages out")
    parser.add_argument("--checkpoint", help="light-network weights (default: the shipped ones)")
    args = parser.parse_args()
    settings = [f"checkpoint={args.checkpoint}"] if args.checkpoint else []
    cases = benchmark.study_cases(args)
    out = args.out or args.cache / "mask_outline"
    try:
        made_with = {"study": "mask_outline", "light": benchmark.light_settings(None, settings),
                     "weights": benchmark.weights_used(settings)}
        runs.claim(out, made_with | ({"network_only": True} if args.network_only else {})
                   | benchmark.capture_options(args))
    except ValueError as e:
        parser.error(str(e))
    network, _ = benchmark.light_source([], settings)
    default = None if args.network_only else benchmark.light_source(None, settings)[0]
    print(report(runs.summaries(cases, out, lambda subject: run_case(subject, network, default),
                                summarise, progress, args.report)))


if __name__ == "__main__":
    main()

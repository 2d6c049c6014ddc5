"""Do a rig's lamps cost the light network, or its layout? The network read with the lamps evened out.

    python experiments/light_benchmark/lamps.py --only diligent-rig benchmark --sets 96   # ~5 min
    python experiments/light_benchmark/lamps.py --report                                 # the table so far

Per case: the direction error of the network's lights (``light=selfcal``'s first stage, eight
passes, no stage after it) on the images as captured; with every lamp made alike (each image
divided by its light's true RGB intensity: the brightness spread and colours gone); and with only
each lamp's colour taken out (each image divided by its light's RGB intensity and multiplied by
their mean: the brightness spread kept, every lamp white). Where the network's error under one rig
barely moves either way, what costs it there is the rig's layout. Results are kept case by case in
``--out`` (default ``<cache>/lamps``); a rerun resumes. None of it feeds training.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from unps.metrics import light_direction_mae

sys.path.insert(0, str(Path(__file__).resolve().parent))
import benchmark  # noqa: E402
import runs  # noqa: E402
import scenes  # noqa: E402

READINGS = ("captured", "lamps alike", "lamps white")


def evened(subject, keep_brightness: bool):
    """The subject with each image divided by its light's RGB intensity (times their mean with
    ``keep_brightness``), its intensities forgotten so the network cannot be handed them."""
    intensities = subject.light_intensities.astype(np.float64)                    # (n, 3)
    scale = intensities.mean(1, keepdims=True) / intensities if keep_brightness else 1 / intensities
    images = subject.observed_images() * scale[:, None, None, :]
    return subject.replace(images=images.astype(np.float32), light_intensities=None)


def run_case(subject, network) -> dict:
    """The network's direction error on ``subject`` read each way of :data:`READINGS`."""
    truth = subject.light_directions
    ways = (subject, evened(subject, keep_brightness=False), evened(subject, keep_brightness=True))
    return {name: light_direction_mae(network(way).directions, truth) for name, way in zip(READINGS, ways)}


def report(rows: dict) -> str:
    """Per group and light set: the mean direction error read each way."""
    lines = [f"{'group':<13} {'set':>4} {'cases':>5}" + "".join(f"{name:>14}" for name in READINGS)]
    for group, label, chosen in runs.by_light_set(rows):
        lines.append(f"{group:<13} {label:>4} {len(chosen):>5}" + "".join(
            f"{np.mean([r[name] for r in chosen]):>13.2f}°" for name in READINGS))
    return "\n".join(lines)


def progress(case: tuple, row: dict, result: dict) -> str:
    return f"{' '.join(case)}: " + ", ".join(f"{name} {row[name]:.2f}°" for name in READINGS)


def main() -> None:
    parser = benchmark.study_parser(__doc__.split("\n")[0], "default: <cache>/lamps",
                                    groups=("benchmark", "diligent-rig", "diligent"))
    args = parser.parse_args()
    out = args.out or args.cache / "lamps"
    benchmark.network_study(parser, args, out, {"scenes": scenes.SCENE_VERSION, "readings": list(READINGS)},
                            run_case, report, progress)


if __name__ == "__main__":
    main()

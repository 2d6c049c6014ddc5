"""Which reading explains the images better: the self-calibration's frame-held fit from the
network's lights and from their half turn about the view, and where each ends.

    python experiments/light_benchmark/both_readings.py --only benchmark synthetic diligent --sets 96
    python experiments/light_benchmark/both_readings.py --only benchmark single diligent-rig \
        --names rose pot-shard
    python experiments/light_benchmark/both_readings.py --only diligent diligent-rig benchmark \
        --names ball face rose pot-shard --room-light 0.01

The two readings render the same shading and highlights (a half turn of the lights and normals
about the view leaves every n·l and n·h as it is); they differ in the depth the normals integrate
to, and so in the cast shadows each depth throws, which the self-calibration's model renders. Per
case: the network's lights (``light.stages=[]``) and their half turn (``start``: each one's
direction error), each fitted with the lights' shared frame held and no pull
(:func:`unps.lights.selfcal.fit_once`, no limit on flattening; ``fitted``: where each ends), the
end loss of each and the half turn's relative to the reading as read (``rel``: below 0 where the
half turn explains the images better), the steps each fit took, and ``INSIDE-OUT`` where the half
turn starts nearer the true lights. ``light.selfcal.turn_inside_out`` makes these two fits where
the reversal test warned or the network is unsure, and keeps the reading
:func:`unps.lights.selfcal.half_turn_kept` picks by ``rel`` (:func:`unps.lights.selfcal.both_readings`).
"""

from __future__ import annotations

import logging
import sys
import time
from dataclasses import replace
from pathlib import Path

import torch

from unps.lightnet.estimate import network_lights
from unps.lights.reversal import half_turned
from unps.lights.selfcal import SelfCalibration, fit_once, frame_held, working_images
from unps.metrics import angular_error

sys.path.insert(0, str(Path(__file__).resolve().parent))
import benchmark  # noqa: E402


def main():
    torch.set_num_threads(1)
    args = benchmark.case_parser(__doc__.split("\n")[0]).parse_args()
    logging.basicConfig(level=logging.ERROR)
    held = frame_held(replace(SelfCalibration(), max_flattening_deg=None, device="cpu"))
    for group, name, label, read in benchmark.asked_cases(args):
        subject, began = read(), time.time()
        lights, _ = network_lights(subject, device="cpu")
        row = {}
        for key, start in (("cur", lights), ("rev", half_turned(lights))):
            fitted, verdict = fit_once(working_images(subject, start, held), start, held)
            row[key] = (angular_error(start.directions, subject.light_directions).mean(),
                        angular_error(fitted.directions, subject.light_directions).mean(),
                        verdict.evidence["loss"], verdict.evidence["steps"])
        c, r = row["cur"], row["rev"]
        print(f"{group:<12} {name:<12} {label:>3} start {c[0]:6.1f} {r[0]:6.1f} fitted {c[1]:6.1f} "
              f"{r[1]:6.1f} loss {c[2]:.5f} {r[2]:.5f} rel {(r[2] - c[2]) / c[2]:+.3f} steps {c[3]} "
              f"{r[3]} {'INSIDE-OUT' if r[0] < c[0] else ''} {time.time() - began:.0f}s", flush=True)


if __name__ == "__main__":
    main()

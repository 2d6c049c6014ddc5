"""Which cue tells a reading inside out? The cast shadows the reversal test reads, against two it
does not: the occluding contour and the light found in attached shadows.

    python experiments/light_benchmark/reversal_cues.py                 # every case, ~30 min on 2 cores
    python experiments/light_benchmark/reversal_cues.py --only diligent

Per case, the network's lights (``light.stages=[]``) and the robust initialisation's normals
with them give one reading of the surface; its half turn about the view axis is the other
(:mod:`unps.lights.reversal`). Shading, highlights and attached shadows are the same under
both; the cues are what differs:

- **shadows**: the reversal test's evidence (:func:`unps.lights.reversal.shadow_evidence`): how
  many times more often than expected the pixels that only the reversed (current) reading
  shadows are dark (``rlift``, ``clift``);
- **contour**: the mean outward component n·t of the reading's normals on the occluding contour
  (:func:`unps.lights.contour.outward_normals`), +1 facing outward as a convex outline does; the
  reversed reading has its negative;
- **interreflection**: in the pairs of pixel and image in attached shadow (n·l < −0.05, the same
  for both readings), where direct light cannot reach, the share of the observed light that a
  one-bounce prediction explains (Nayar's kernel, :func:`unps.solvers.nayar.interreflection_kernel`,
  on the reading's integrated depth, lit by the observed images, times the Lambertian albedo;
  one free scale), for the current (``cur``) and reversed (``rev``) reading, and the mean observed
  level there (``level``, in units of the images' 99th percentile). Since a flat level of light
  (ambient, a room's, light scattered under the surface) is "explained" by any positive
  prediction, two more columns read what only interreflection would show: ``flat`` (per
  reading, 1 − the scaled prediction's squared error over that of the best flat level: above 0
  where the prediction follows where the light is) and ``pixel`` (the share explained of what
  changes from image to image at a pixel, each pixel's mean over its attached images taken
  out: ambient light does not change with the light; over the ``pairs`` of the pixels
  attached in two images or more), ``change`` (the share of the observed light's Σ value² in
  those pairs that is such change at all, whichever reading predicts it: near 0 where the light
  in attached shadows is the same in every image, as a room's is), and ``scale``, the reversed reading's
  free scale (about the brightest material's albedo, at most 1, where the prediction is
  interreflection).

``inside out`` marks the readings whose half turn is nearer the true lights.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import numpy as np

from unps.lightnet.estimate import network_lights
from unps.lights import with_lights
from unps.lights.contour import outward_normals
from unps.lights.reversal import (HALF_TURN, attached_predictions, explained_share, shadow_evidence,
                                  summarise_attached)
from unps.metrics import angular_error
from unps.solvers.rpca import robust_init

sys.path.insert(0, str(Path(__file__).resolve().parent))
import benchmark  # noqa: E402

def contour_facing(normals: np.ndarray, mask: np.ndarray) -> float:
    """Mean outward component of (H, W, 3) unit ``normals`` on the occluding contour of ``mask``
    (nan without one)."""
    contour, outward = outward_normals(mask)
    if not contour.any():
        return float("nan")
    return float((normals[contour][:, :2] * outward[contour][:, :2]).sum(1).mean())


def over_flat(seen: np.ndarray, predicted: np.ndarray) -> float:
    """1 − the squared error of the one-scale fit ``scale · predicted`` to ``seen`` (both (k,))
    over that of the best flat level (their mean); nan without pairs."""
    if seen.size == 0:
        return float("nan")
    _, scale = explained_share(seen, predicted)
    return float(1 - ((seen - scale * predicted) ** 2).sum() / max(((seen - seen.mean()) ** 2).sum(), 1e-12))


def within_pixel(values: np.ndarray, attached: np.ndarray) -> np.ndarray:
    """(n, m) ``values`` where ``attached``, less each pixel's mean over its attached images,
    flat; pixels attached in fewer than two images left out."""
    count = attached.sum(0)
    mean = np.where(attached, values, 0).sum(0) / np.maximum(count, 1)
    return (values - mean[None])[attached & (count >= 2)[None]]


def changed_share(seen: np.ndarray, changes: np.ndarray) -> float:
    """Σ ``changes``² over Σ ``seen``² for the (k,) values seen in attached shadows and the
    (j,) changes of :func:`within_pixel`; nan without changes.

    Example:
        >>> round(changed_share(np.array([1.0, 1.0, 2.0, 0.0]), np.array([1.0, -1.0])), 3)
        0.333
    """
    if changes.size == 0:
        return float("nan")
    return float((changes ** 2).sum() / max((seen ** 2).sum(), 1e-12))


def attached_cues(subject, lights, normals: np.ndarray) -> dict[str, float]:
    """The light seen in attached shadows and how each reading's one-bounce prediction explains
    it (:func:`unps.lights.reversal.attached_predictions`; keys as the columns, see the module)."""
    maps = attached_predictions(subject, lights, normals)
    attached = maps["attached"]
    seen, changes = maps["observed"][attached], within_pixel(maps["observed"], attached)
    summary = summarise_attached(maps)
    cues = {"level": summary.level if seen.size else float("nan"), "pairs": summary.pairs,
            "cur": summary.current_share, "rev": summary.reversed_share,
            "rev scale": summary.reversed_scale, "pixel pairs": int(changes.size),
            "warns": summary.points_to_reversal,
            "change": changed_share(seen, changes)}
    for reading, key in (("current", "cur"), ("reversed", "rev")):
        cues[f"{key} flat"] = over_flat(seen, maps[reading][attached])
        cues[f"{key} pixel"] = (explained_share(changes, within_pixel(maps[reading], attached))[0]
                                if changes.size else float("nan"))
    return cues


def main():
    parser = benchmark.case_parser(__doc__.split("\n")[0])
    args = parser.parse_args()
    logging.basicConfig(level=logging.ERROR)
    print(f"{'group':<9} {'case':<12} {'set':>3} {'network':>8} {'turned':>7} {'inside out':>10} "
          f"{'rlift':>6} {'clift':>6} {'contour':>8} {'level':>6} {'cur':>6} {'rev':>6} {'pairs':>6} "
          f"{'flat':>13} {'pixel':>13} {'pairs':>6} {'change':>6} {'scale':>6} {'warns':>5}")
    for group, name, label, read in benchmark.asked_cases(args):
        subject = read()
        lights, _ = network_lights(subject, device="cpu")
        error = angular_error(lights.directions, subject.light_directions).mean()
        turned = angular_error(lights.directions @ HALF_TURN, subject.light_directions).mean()
        normals = robust_init(with_lights(subject, lights), lights.directions, device="cpu").normals
        evidence = shadow_evidence(subject, lights, normals)
        cue = attached_cues(subject, lights, normals)
        print(f"{group:<9} {name:<12} {label:>3} {error:>7.2f}° {turned:>6.1f}° "
              f"{'yes' if turned < error else '':>10} {evidence.reversed_lift:>6.1f} "
              f"{evidence.current_lift:>6.1f} {contour_facing(normals, subject.mask):>+8.2f} "
              f"{cue['level']:>6.3f} {cue['cur']:>+6.2f} {cue['rev']:>+6.2f} {cue['pairs']:>6} "
              f"{cue['cur flat']:>+6.2f} {cue['rev flat']:>+6.2f} {cue['cur pixel']:>+6.2f} "
              f"{cue['rev pixel']:>+6.2f} {cue['pixel pairs']:>6} {cue['change']:>6.3f} "
              f"{cue['rev scale']:>6.2f} "
              f"{'yes' if cue['warns'] else '':>5}", flush=True)


if __name__ == "__main__":
    main()

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
  level there (``level``, in units of the images' 99th percentile).

``inside out`` marks the readings whose half turn is nearer the true lights.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import numpy as np

from unps.lightnet.estimate import network_lights
from unps.lights import with_lights
from unps.lights.contour import outward_normals
from unps.lights.reversal import HALF_TURN, shadow_evidence
from unps.geometry import integrate_normals
from unps.metrics import angular_error
from unps.solvers.nayar import interreflection_kernel
from unps.solvers.rpca import robust_init
from unps.solvers.woodham import rgb_albedo

sys.path.insert(0, str(Path(__file__).resolve().parent))
import benchmark  # noqa: E402
import scenes  # noqa: E402

ATTACHED = -0.05        # n·l below which a pixel is in attached shadow
FACETS = 1500           # object pixels of the interreflection grid, at most


def contour_facing(normals: np.ndarray, mask: np.ndarray) -> float:
    """Mean outward component of (H, W, 3) unit ``normals`` on the occluding contour of ``mask``
    (nan without one)."""
    contour, outward = outward_normals(mask)
    if not contour.any():
        return float("nan")
    return float((normals[contour][:, :2] * outward[contour][:, :2]).sum(1).mean())


def attached_light(subject, lights, normals: np.ndarray) -> tuple[float, float, float, int]:
    """(level, explained by the current reading, by the reversed one, pairs) of the light seen in
    attached shadows; see the module."""
    observed = with_lights(subject, lights).replace(normals=normals, depth=None)
    factor = max(1, int(np.ceil(np.sqrt(observed.mask.sum() / FACETS))))
    grid = observed.crop_to_mask(1).downsample(factor)
    gray = grid.images[:, grid.mask].mean(-1)                                   # (n, m)
    scale = np.quantile(gray, 0.99)
    gray = gray / scale
    facet_normals = grid.normals[grid.mask].astype(np.float64)
    directions = lights.directions.astype(np.float64)
    albedo = rgb_albedo(grid.images[:, grid.mask], facet_normals, directions).mean(-1) / scale
    attached = (facet_normals @ directions.T).T < ATTACHED                     # (n, m)
    depth = np.nan_to_num(integrate_normals(grid.normals, grid.mask))
    seen = gray[attached]
    explained = []
    for z, n in ((depth, grid.normals), (-depth, grid.normals @ HALF_TURN)):
        bounce = (interreflection_kernel(z, n, grid.mask) @ gray.T).T * albedo[None]
        predicted = bounce[attached]
        a = max((seen * predicted).sum() / max((predicted ** 2).sum(), 1e-12), 0.0)
        explained.append(1 - ((seen - a * predicted) ** 2).sum() / max((seen ** 2).sum(), 1e-12))
    level = float(seen.mean()) if seen.size else float("nan")
    return level, float(explained[0]), float(explained[1]), int(attached.sum())


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=benchmark.DEFAULT_DATA)
    parser.add_argument("--cache", type=Path, default=benchmark.DEFAULT_CACHE)
    parser.add_argument("--only", nargs="+", choices=benchmark.GROUPS, default=list(benchmark.GROUPS))
    parser.add_argument("--sets", nargs="+", choices=list(scenes.LIGHT_SETS), default=list(scenes.LIGHT_SETS))
    parser.add_argument("--names", nargs="*", help="only these objects or subjects")
    args = parser.parse_args()
    logging.basicConfig(level=logging.ERROR)
    print(f"{'group':<9} {'case':<12} {'set':>3} {'network':>8} {'turned':>7} {'inside out':>10} "
          f"{'rlift':>6} {'clift':>6} {'contour':>8} {'level':>6} {'cur':>6} {'rev':>6} {'pairs':>6}")
    for group, name, label, read in benchmark.cases(args.only, args.sets, args.data, args.cache, args.names):
        subject = read()
        lights, _ = network_lights(subject, device="cpu")
        error = angular_error(lights.directions, subject.light_directions).mean()
        turned = angular_error(lights.directions @ HALF_TURN, subject.light_directions).mean()
        normals = robust_init(with_lights(subject, lights), lights.directions, device="cpu").normals
        evidence = shadow_evidence(subject, lights, normals)
        level, current, reversed_, pairs = attached_light(subject, lights, normals)
        print(f"{group:<9} {name:<12} {label:>3} {error:>7.2f}° {turned:>6.1f}° "
              f"{'yes' if turned < error else '':>10} {evidence.reversed_lift:>6.1f} "
              f"{evidence.current_lift:>6.1f} {contour_facing(normals, subject.mask):>+8.2f} "
              f"{level:>6.3f} {current:>+6.2f} {reversed_:>+6.2f} {pairs:>6}", flush=True)


if __name__ == "__main__":
    main()

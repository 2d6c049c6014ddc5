"""Where do free self-calibrations go? The shared frame, the lights' elevation and the outline.

    python experiments/light_benchmark/free_fits.py                 # benchmark and DiLiGenT cases
    python experiments/light_benchmark/free_fits.py --report        # the tables from what has run

Each case runs the network and the reversal test (the *start*), then two self-calibrations from
it: the one shipped until 2026-11-27 (held near the network's lights, black values not yet
censored) and a free one (``prior_weight=0``, pixels black in every image left out: the best of
the free fits measured). It reports, per case:

- how much of the free fit's move one 3×3 transform of all the start's lights explains (the
  *frame*: a rotation, a bas-relief, a stretch of the elevations), against the truth;
- the *elevation stretch* of the network: the factor on the lights' angles from the view that
  best maps the start's onto the true ones (1: the spread of the elevations is right);
- how much of the start's own error is one transform of all its lights, read off the truth: the
  error left after the 3×3 transform, and after the bas-relief (μ, ν, λ), that bring the start
  nearest the true lights;
- the mean n_z, on the object's outline, of the robust initialisation's normals under each set of
  lights, and what keeping the free fit only where it raises that n_z would give.

Results are kept case by case in ``--out`` (default ``<cache>/free_fits``); a rerun resumes.
None of it feeds training.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
from scipy import ndimage
from scipy.optimize import least_squares

from unps.lightnet.estimate import network_lights
from unps.lights.reversal import ReversalTest
from unps.lights.selfcal import SelfCalibration
from unps.metrics import angular_error
from unps.solvers.rpca import robust_init

sys.path.insert(0, str(Path(__file__).resolve().parent))
import benchmark  # noqa: E402
import runs  # noqa: E402
import scenes  # noqa: E402

FREE = SelfCalibration(device="cpu", prior_weight=0.0, skip_black=True, censor_black=False,
                       frame_held_first=False, rounds=1)
HELD = SelfCalibration(device="cpu", censor_black=False, frame_held_first=False,
                       rounds=1)                                  # shipped to 2026-11-27
MARGINS = (0.0, 0.02, 0.05)      # n_z margins the outline rule tries


def run_case(subject) -> dict:
    """Directions (n, 3) of the truth, the start and both fits, with the outline's mean n_z under
    each."""
    began = time.perf_counter()
    network, _ = network_lights(subject, device="cpu")
    start, _ = ReversalTest(device="cpu")(subject, network)
    lights = {"truth": subject.light_directions, "start": start.directions,
              "held": HELD(subject, start)[0].directions, "free": FREE(subject, start)[0].directions}
    return {**{k: np.asarray(v, np.float64).tolist() for k, v in lights.items()},
            "outline_nz": {k: outline_nz(subject, np.asarray(v, np.float32)) for k, v in lights.items()},
            "seconds": time.perf_counter() - began}


def outline_nz(subject, directions: np.ndarray) -> float:
    """Mean n_z of the robust initialisation's normals under ``directions`` on the outline: the
    object pixels with a 4-neighbour off the mask."""
    mask = subject.mask
    outline = mask & ~ndimage.binary_erosion(mask)
    return float(robust_init(subject, directions).normals[outline][:, 2].mean())


def frame_only(start: np.ndarray, fitted: np.ndarray, rounds: int = 50) -> np.ndarray:
    """(n, 3) unit directions: the one 3×3 transform T of all of ``start`` (n, 3) whose images
    s_i·T come nearest ``fitted``'s directions, applied. Least squares of s_i·T against k_i·f_i,
    alternating with each light's length k_i (their mean held at 1), so that a shared transform,
    which changes the lights' lengths, is found whole."""
    lengths = np.ones(len(start))
    for _ in range(rounds):
        transform, *_ = np.linalg.lstsq(start, fitted * lengths[:, None], rcond=None)
        lengths = np.maximum((start @ transform * fitted).sum(1), 1e-6)
        lengths /= lengths.mean()
    moved = start @ transform
    return moved / np.linalg.norm(moved, axis=1, keepdims=True)


def bas_relief_only(start: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(n, 3) unit directions: the bas-relief s_i ↦ (s_x, s_y, μ s_x + ν s_y + λ s_z) of all of
    ``start`` (n, 3) whose directions come nearest ``target``'s (least squares from the identity),
    applied."""
    def moved(p: np.ndarray) -> np.ndarray:
        out = start @ np.array([[1.0, 0.0, p[0]], [0.0, 1.0, p[1]], [0.0, 0.0, p[2]]])
        return out / np.linalg.norm(out, axis=1, keepdims=True)
    return moved(least_squares(lambda p: (moved(p) - target).ravel(), [0.0, 0.0, 1.0]).x)


def elevation_stretch(start: np.ndarray, truth: np.ndarray) -> float:
    """The factor k minimising Σ (k·θ_start − θ_true)² over the lights' angles θ from the view."""
    def polar(d):
        return np.degrees(np.arccos(np.clip(d[:, 2], -1, 1)))
    a, b = polar(start), polar(truth)
    return float((a * b).sum() / max((a * a).sum(), 1e-12))


def summarise(result: dict) -> dict:
    """The case's light errors (mean degrees), its free fit's frame part, its elevation stretch
    and outline n_z."""
    d = {k: np.asarray(result[k], np.float64) for k in ("truth", "start", "held", "free")}
    error = {k: float(angular_error(d[k], d["truth"]).mean()) for k in ("start", "held", "free")}
    def error_after(moved: np.ndarray) -> float:
        return float(angular_error(moved, d["truth"]).mean())
    return {**error, "frame": error_after(frame_only(d["start"], d["free"])),
            "nearest_3x3": error_after(frame_only(d["start"], d["truth"])),
            "nearest_gbr": error_after(bas_relief_only(d["start"], d["truth"])),
            "stretch": elevation_stretch(d["start"], d["truth"]), "nz": result["outline_nz"]}


def progress(case: tuple, s: dict, result: dict) -> str:
    """The line printed when a case has run."""
    return (f"{' '.join(case)}: start {s['start']:.2f}° held {s['held']:.2f}° free {s['free']:.2f}° "
            f"({result['seconds']:.0f} s)")


def report(rows: dict) -> str:
    """Per case, then per light count: the fits' errors and the outline rule."""
    lines = [f"{'group':<9} {'case':<12} {'set':>3} {'start':>7} {'held':>7} {'free':>7} {'frame':>7} "
             f"{'stretch':>7}   outline n_z: {'truth':>6} {'start':>6} {'held':>6} {'free':>6}   "
             f"start nearest the truth: {'3×3':>7} {'GBR':>7}"]
    for (group, name, label), s in rows.items():
        nz = s["nz"]
        lines.append(f"{group:<9} {name:<12} {label:>3} {s['start']:>6.2f}° {s['held']:>6.2f}° "
                     f"{s['free']:>6.2f}° {s['frame']:>6.2f}° {s['stretch']:>7.2f}                "
                     f"{nz['truth']:>6.3f} {nz['start']:>6.3f} {nz['held']:>6.3f} {nz['free']:>6.3f}   "
                     f"{'':>24} {s['nearest_3x3']:>6.2f}° {s['nearest_gbr']:>6.2f}°")
    lines.append(f"\n{'group':<9} {'set':>4} {'cases':>5} {'start':>7} {'held':>7} {'free':>7} "
                 + " ".join(f"{f'n_z +{m:g}':>16}" for m in MARGINS)
                 + "   (mean error / worst raise over held)")
    for group, label, chosen in runs.by_light_set(rows):
        cells = []
        for margin in MARGINS:
            final = [s["free"] if s["nz"]["free"] > s["nz"]["held"] + margin else s["held"] for s in chosen]
            worst = max(f - s["held"] for f, s in zip(final, chosen))
            cells.append(f"{np.mean(final):>7.2f}° / {worst:>5.2f}°")
        means = [np.mean([s[k] for s in chosen]) for k in ("start", "held", "free")]
        lines.append(f"{group:<9} {label:>4} {len(chosen):>5} " + " ".join(f"{m:>6.2f}°" for m in means)
                     + " " + " ".join(cells))
    lines.append(f"\nthe start's error, and what is left of it after the one transform of all its lights "
                 f"that brings them nearest the truth:\n{'group':<9} {'set':>4} {'cases':>5} {'start':>7} "
                 f"{'3×3':>7} {'GBR':>7}")
    for group, label, chosen in runs.by_light_set(rows):
        means = [np.mean([s[k] for s in chosen]) for k in ("start", "nearest_3x3", "nearest_gbr")]
        lines.append(f"{group:<9} {label:>4} {len(chosen):>5} " + " ".join(f"{m:>6.2f}°" for m in means))
    stretches = np.array([s["stretch"] for k, s in rows.items() if k[0] == "benchmark"])
    if len(stretches):
        lines.append(f"\nnetwork's elevation stretch on the benchmark: median {np.median(stretches):.2f}, "
                     f"{(stretches < 0.9).sum()} cases below 0.9, {(stretches > 1.1).sum()} above 1.1 "
                     f"of {len(stretches)}")
    return "\n".join(lines)


def main():
    parser = benchmark.study_parser(__doc__.split("\n")[0], "default: <cache>/free_fits",
                                    groups=("benchmark", "diligent"))
    args = parser.parse_args()
    cases = benchmark.study_cases(args)
    out = args.out or args.cache / "free_fits"
    try:
        runs.claim(out, {"scenes": scenes.SCENE_VERSION, "held": repr(HELD), "free": repr(FREE),
                         "weights": runs.weights_digest(None),
                         **benchmark.capture_options(args)})
    except ValueError as e:
        parser.error(str(e))
    print(report(runs.summaries(cases, out, run_case, summarise, progress, args.report)))


if __name__ == "__main__":
    main()

"""Does the self-calibration's loss say where the lights' shared frame is?

Fits from the network's lights, from those lights turned and stretched, and from the true lights:

    python experiments/light_benchmark/frame_landscape.py --only benchmark diligent --sets 12 --names …
    python experiments/light_benchmark/frame_landscape.py --sets 12 --report   # the table from what has run

The held fit (``hold_frame=true``: each light moves by its own residual, the 3×3 frame all the
lights share stays where it starts; no pull, no decline for flattening: ``--set`` changes any of
them) leaves the network's frame error in the lights. Each case runs the network and the reversal
test as ``python -m unps.fit light=selfcal`` does, then the held fit from eleven starts — those
lights, turned by ±5° about the image's x and y axes (the 3 × 3 grid), and stretched along the
bas-relief's λ (their z component × 0.85 and × 1.15, renormalised) — and from the true lights, and
the free fit (the frame let go as well) from the network's lights and from the true ones. The
report asks three things: is the held fit's loss lower from the true frame than from the
network's (a frame the images prefer), does picking the start whose held fit ends lowest take the
lights nearer the truth (a search over the frame, scored by the loss), and does the free fit stay
at the truth when started there (whether the model's own minimum over the frame is the true one).

Results are kept case by case in ``--out`` (default ``<cache>/frame_landscape/<tag>``); a rerun
resumes. None of it feeds training.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from itertools import product
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation
from scipy.stats import spearmanr

from unps.data.lights import Lights
from unps.lightnet.estimate import network_lights
from unps.lights.reversal import ReversalTest
from unps.metrics import angular_error

sys.path.insert(0, str(Path(__file__).resolve().parent))
import benchmark  # noqa: E402
import scenes  # noqa: E402

TURN_DEG = 5.0
STRETCH = 0.15
HELD = {"hold_frame": True, "frame_held_first": False, "prior_weight": 0.0, "max_flattening_deg": None}
START = "turn +0 +0"


def frames(directions: np.ndarray) -> dict[str, np.ndarray]:
    """(n, 3) unit directions to start the held fit from, by name: the given ones turned by each
    of 0, ±:data:`TURN_DEG` about the x and the y axis (``START`` is the given ones), and with
    their z component × (1 ∓ :data:`STRETCH`), renormalised.

    >>> d = frames(np.array([[0.0, 0.0, 1.0]]))
    >>> len(d), np.round(d["turn +5 +0"], 3).tolist(), np.round(d["z x 0.85"], 3).tolist()
    (11, [[0.0, -0.087, 0.996]], [[0.0, 0.0, 1.0]])
    """
    out = {}
    for ax, ay in product((0, TURN_DEG, -TURN_DEG), repeat=2):
        turn = Rotation.from_euler("xy", [ax, ay], degrees=True)
        out[f"turn {ax:+.0f} {ay:+.0f}"] = turn.apply(directions)
    for factor in (1 - STRETCH, 1 + STRETCH):
        stretched = directions * np.array([1.0, 1.0, factor])
        out[f"z x {factor:g}"] = stretched / np.linalg.norm(stretched, axis=1, keepdims=True)
    return out


def run_case(subject, held) -> dict:
    """Each fit's directions (n, 3) and its loss, by start, with the truth, the network's and the
    reversal test's directions and the seconds taken."""
    begin = time.perf_counter()
    network, _ = network_lights(subject, device="cpu")
    reversed_, _ = ReversalTest(device="cpu")(subject, network)
    intensities = subject.light_intensities
    truth = Lights(subject.light_directions.astype(np.float32),
                   None if intensities is None else intensities.astype(np.float32), "truth")
    free = dataclasses.replace(held, hold_frame=False)
    fits = {}
    for name, directions in frames(reversed_.directions.astype(np.float64)).items():
        start = dataclasses.replace(reversed_, directions=directions.astype(np.float32))
        fits[f"held from {name}"] = held(subject, start)
    fits["held from truth"] = held(subject, truth)
    fits["free from network"] = free(subject, reversed_)
    fits["free from truth"] = free(subject, truth)
    return {"truth": subject.light_directions.tolist(), "network": network.directions.tolist(),
            "reversal": reversed_.directions.tolist(),
            "fits": {k: {"directions": lights.directions.tolist(), "loss": verdict.evidence.get("loss")}
                     for k, (lights, verdict) in fits.items()},
            "seconds": time.perf_counter() - begin}


def _off(directions, truth: np.ndarray) -> float:
    """Mean direction error (degrees) of ``directions`` (n, 3; a list as stored) from ``truth``."""
    return float(angular_error(np.asarray(directions, np.float64), truth).mean())


def _searched(keys) -> list[str]:
    """The held fits from the eleven frames (not the one from the truth)."""
    return [k for k in keys if k.startswith("held from") and k != "held from truth"]


def summarise(result: dict) -> dict:
    """Each fit's light error (mean degrees) and loss; the start's error; the frame whose held
    fit ended lowest; the rank correlation of the held fits' losses and errors over the frames;
    how far the free fit from the network ended from the held one (``moved``, degrees) and what
    it gained over it (``gain``)."""
    truth = np.asarray(result["truth"], np.float64)
    fits = result["fits"]
    error = {k: _off(f["directions"], truth) for k, f in fits.items()}
    loss = {k: f["loss"] for k, f in fits.items()}
    searched = _searched(error)
    held = fits[f"held from {START}"]["directions"]
    return {"network": _off(result["network"], truth), "start": _off(result["reversal"], truth),
            "error": error, "loss": loss, "lowest": min(searched, key=loss.get),
            "rank": float(spearmanr([loss[k] for k in searched], [error[k] for k in searched]).correlation),
            "moved": _off(fits["free from network"]["directions"], np.asarray(held, np.float64)),
            "gain": error[f"held from {START}"] - error["free from network"]}


def progress(case: tuple, s: dict, result: dict) -> str:
    """The line printed when a case has run."""
    e = s["error"]
    return (f"{' '.join(case)}: start {s['start']:.2f}° held {e['held from ' + START]:.2f}° "
            f"lowest-loss frame ({s['lowest'][10:]}) {e[s['lowest']]:.2f}° held from truth "
            f"{e['held from truth']:.2f}° free from truth {e['free from truth']:.2f}° "
            f"({result['seconds']:.0f} s)")


def report(rows: dict) -> str:
    """Per case the errors of the fits and the two losses that matter; over all cases the means,
    how often the true frame's held fit ends lower, the median rank correlation of loss and error
    over the frames, and that of the free fit's move and gain."""
    held = f"held from {START}"
    lines = [f"{'group':<9} {'case':<12} {'set':>3} {'start':>7} {'held':>7} {'lowest-loss frame':>24} "
             f"{'free':>7} {'moved':>6} {'held@truth':>10} {'free@truth':>10} {'loss held':>10} "
             f"{'@truth':>8} {'rank':>6}"]
    for (group, name, label), s in rows.items():
        e, loss = s["error"], s["loss"]
        lines.append(f"{group:<9} {name:<12} {label:>3} {s['start']:>6.2f}° {e[held]:>6.2f}° "
                     f"{s['lowest'][10:]:>15} {e[s['lowest']]:>7.2f}° {e['free from network']:>6.2f}° "
                     f"{s['moved']:>5.2f}° {e['held from truth']:>9.2f}° {e['free from truth']:>9.2f}° "
                     f"{loss[held]:>10.5f} {loss['held from truth']:>8.5f} {s['rank']:>+6.2f}")
    if not rows:
        return "\n".join(lines)
    values = list(rows.values())
    mean = {key: np.mean([s["error"][key] for s in values])
            for key in (held, "free from network", "held from truth", "free from truth")}
    chosen = [s["error"][s["lowest"]] - s["error"][held] for s in values]
    best = np.mean([min(s["error"][k] for k in _searched(s["error"])) for s in values])
    truer = sum(s["loss"]["held from truth"] < s["loss"][held] for s in values)
    move_gain = spearmanr([s["moved"] for s in values], [s["gain"] for s in values]).correlation
    lines.append(
        f"\n{len(values)} cases: start {np.mean([s['start'] for s in values]):.2f}°; held fit "
        f"{mean[held]:.2f}°; the frame whose held fit ends lowest {mean[held] + np.mean(chosen):.2f}° "
        f"(better / worse than the held fit by > 0.1° on {sum(c < -0.1 for c in chosen)} / "
        f"{sum(c > 0.1 for c in chosen)}; the best of the eleven frames {best:.2f}°); free fit "
        f"{mean['free from network']:.2f}°\nfrom the truth: held {mean['held from truth']:.2f}°, free "
        f"{mean['free from truth']:.2f}°; the held fit ends lower from the true frame than from the "
        f"network's on {truer} of {len(values)}; median rank correlation of the held fits' loss and "
        f"error over the eleven frames {np.median([s['rank'] for s in values]):+.2f}; rank correlation "
        f"of how far the free fit moved from the held one and its gain over it {move_gain:+.2f}")
    return "\n".join(lines)


def main():
    benchmark.selfcal_study(__doc__.split("\n")[0], "frame_landscape",
                            {"scenes": scenes.SCENE_VERSION, "frames": [TURN_DEG, STRETCH],
                             "stages": ["reversal", "selfcal"]},
                            run_case, summarise, progress, report, HELD)


if __name__ == "__main__":
    main()

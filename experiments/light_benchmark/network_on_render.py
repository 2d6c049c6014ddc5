"""Does the light network err alike on the self-calibration's own render of the object?

    python experiments/light_benchmark/network_on_render.py --only benchmark diligent synthetic
    python experiments/light_benchmark/network_on_render.py --report   # the table from what has run

The self-calibration with the shared frame held keeps the frame of the network's lights, and
with it most of their error. Each case runs the network and the reversal test as ``python -m
unps.fit light=selfcal`` does, then the held fit (``light.selfcal``'s first fit: each light moves
by its own residual, no pull); renders its model (depth, albedo, lobes, cast shadows) under its
own lights on the working grid; and reads those images with the network again. Were the
network's error a transform of the whole set that depends on the object alone, the transform
carrying the held lights onto the network's reading of the render would be the one to undo on
the held lights (a parametric bootstrap of the network's bias). Undone three ways: the 3×3
linear map fitted by least squares (*linear*), half of it (*half*), the best rotation (*rotation*).

Results are kept case by case in ``--out`` (default ``<cache>/network_on_render/<tag>``); a
rerun resumes. None of it feeds training.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from unps.inverse.fit import unit
from unps.lightnet.estimate import network_lights
from unps.lights.reversal import ReversalTest
from unps.lights.selfcal import fit, frame_held, initial_model, working_images
from unps.metrics import angular_error

sys.path.insert(0, str(Path(__file__).resolve().parent))
import benchmark  # noqa: E402
import scenes  # noqa: E402

UNDONE = ("linear", "half", "rotation")


def undone(held: np.ndarray, read: np.ndarray) -> dict[str, np.ndarray]:
    """(n, 3) ``held`` directions with the transform that carries them onto the network's
    reading ``read`` (n, 3) of their render undone, by :data:`UNDONE`'s ways.

    >>> turn = Rotation.from_euler("x", 10, degrees=True).as_matrix()
    >>> held = unit(np.array([[0.3, 0.1, 0.9], [-0.4, 0.2, 0.8], [0.1, -0.5, 0.8], [0.0, 0.0, 1.0]]))
    >>> back = undone(held @ turn, held @ turn @ turn)
    >>> [round(float(angular_error(back[k], held).max()), 4) for k in ("linear", "rotation")]
    [0.0, 0.0]
    """
    linear = np.linalg.lstsq(held, read, rcond=None)[0]            # held @ linear ≈ read
    rotation = Rotation.align_vectors(read, held)[0].as_matrix().T  # held @ rotation ≈ read
    return {"linear": unit(held @ np.linalg.inv(linear)),
            "half": unit(held @ np.linalg.inv((linear + np.eye(3)) / 2)),
            "rotation": unit(held @ rotation.T)}


def render_of(images, model):
    """The working grid with the model's images (cast shadows of its own depth) in place of the
    captured ones, the model's lights as its true ones."""
    with torch.no_grad():
        rendered = model(model.visibility()).numpy()                        # (m, n, 3)
        directions = model.lights()[0].numpy()
    grid = images.grid
    stack = np.zeros((rendered.shape[1], *grid.mask.shape, 3), np.float32)
    stack[:, grid.mask] = rendered.transpose(1, 0, 2)
    return grid.replace(images=stack, light_intensities=None, normals=None,
                        light_directions=directions.astype(np.float32))


def run_case(subject, selfcal) -> dict:
    """The truth's, the network's, the held fit's and the network's reading of the held fit's
    render's directions (n, 3), and the seconds taken."""
    begin = time.perf_counter()
    network, _ = network_lights(subject, device="cpu")
    reversed_, _ = ReversalTest(device="cpu")(subject, network)
    held_settings = frame_held(selfcal)
    images = working_images(subject, reversed_, held_settings)
    model = initial_model(images.grid, images.target, reversed_.directions.astype(np.float64), held_settings)
    fit(model, images.target, held_settings, None, images.weight, images.ceiling)
    render = render_of(images, model)
    read, _ = network_lights(render, device="cpu")
    return {"truth": subject.light_directions.tolist(), "network": network.directions.tolist(),
            "reversal": reversed_.directions.tolist(), "held": render.light_directions.tolist(),
            "read": read.directions.tolist(), "seconds": time.perf_counter() - begin}


def summarise(result: dict) -> dict:
    """Mean direction errors (degrees): the start, the held fit, the network's reading of the
    render against the held lights, and the held lights with the transform undone each way."""
    truth, held, read = (np.asarray(result[k], np.float64) for k in ("truth", "held", "read"))
    error = {"start": float(angular_error(np.asarray(result["reversal"], np.float64), truth).mean()),
             "held": float(angular_error(held, truth).mean()),
             "read off": float(angular_error(read, held).mean())}
    return error | {k: float(angular_error(v, truth).mean()) for k, v in undone(held, read).items()}


def progress(case: tuple, s: dict, result: dict) -> str:
    """The line printed when a case has run."""
    return (f"{' '.join(case)}: held {s['held']:.2f}°, the network {s['read off']:.2f}° off on its render; "
            + ", ".join(f"{k} {s[k]:.2f}°" for k in UNDONE) + f" ({result['seconds']:.0f} s)")


def report(rows: dict) -> str:
    """Per case the errors; per group and light set the means and how many cases each way of
    undoing raised or lowered by more than 1°."""
    lines = [f"{'group':<9} {'case':<12} {'set':>3} {'start':>7} {'held':>7} {'read off':>8} "
             + " ".join(f"{k:>8}" for k in UNDONE)]
    for (group, name, label), s in rows.items():
        lines.append(f"{group:<9} {name:<12} {label:>3} {s['start']:>6.2f}° {s['held']:>6.2f}° "
                     f"{s['read off']:>7.2f}° " + " ".join(f"{s[k]:>7.2f}°" for k in UNDONE))
    lines.append(f"\n{'group':<9} {'set':>4} {'cases':>5} {'held':>7} "
                 + " ".join(f"{k + ' (raised / lowered by > 1°)':>34}" for k in UNDONE))
    for group, label in sorted({(k[0], k[2]) for k in rows}, key=lambda k: (k[0], -int(k[1]))):
        chosen = [s for k, s in rows.items() if k[0] == group and k[2] == label]
        cells = []
        for way in UNDONE:
            change = np.array([s[way] - s["held"] for s in chosen])
            cells.append(f"{np.mean([s[way] for s in chosen]):>7.2f}° ({int((change > 1).sum())} / "
                         f"{int((change < -1).sum())})")
        lines.append(f"{group:<9} {label:>4} {len(chosen):>5} {np.mean([s['held'] for s in chosen]):>6.2f}° "
                     + " ".join(f"{c:>34}" for c in cells))
    return "\n".join(lines)


def main():
    benchmark.selfcal_study(__doc__.split("\n")[0], "network_on_render",
                            {"scenes": scenes.SCENE_VERSION, "stages": ["reversal", "selfcal"]},
                            run_case, summarise, progress, report)


if __name__ == "__main__":
    main()

"""Does the spread of the lights' intensities set how flat the light network reads the lights?

    python experiments/light_benchmark/intensity_spread.py     # DiLiGenT's three, unps's renders: ~5 min
    python experiments/light_benchmark/intensity_spread.py --draws 5 --subjects Sphere Face
    python experiments/light_benchmark/intensity_spread.py --set checkpoint=W.pt   # other weights

The network is trained on stacks whose lights' intensities are drawn from U(0.2, 2) image by
image (``unps.lightnet.synthesis``). DiLiGenT's dome spreads as widely (0.38-2.3, a relative
spread of 0.48 against U(0.2, 2)'s 0.47); rigs of matched lamps, the light benchmark's renders
(U(0.6, 1.4)) and unps's subjects (U(0.5, 1.5)) spread less. Per subject (DiLiGenT's three at 96
images, unps's renders of ``--subjects``), its images divided by their own lights' intensities
(``Subject.images``) are read by the network (``light=selfcal``'s first stage, eight passes) as
they are — every light equally bright — and after each image is scaled by an intensity drawn
from U(0.6, 1.4) and from U(0.2, 2) (``--draws`` draws each, their figures averaged): the slant
bias of the lights (:func:`unps.metrics.light_slant_bias`, < 0 where they are read nearer the view
axis than they are) and their direction error. Nothing is kept between runs. None of it feeds
training.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import numpy as np
import torch

from unps.errors import InputError
from unps.metrics import light_direction_mae, light_slant_bias

sys.path.insert(0, str(Path(__file__).resolve().parent))
import benchmark  # noqa: E402

SPREADS = {"equal": None, "U(0.6, 1.4)": (0.6, 1.4), "U(0.2, 2)": (0.2, 2.0)}
RENDERS = ("Sphere", "Face", "Golf-ball", "Tablet1", "Tablet2")   # the Vase, BrokenPot, Rose: 12-72 deg off


def rescaled(images: np.ndarray, spread: tuple[float, float] | None, rng: np.random.Generator) -> np.ndarray:
    """(n, H, W, 3) ``images`` each scaled by its own intensity drawn from U(*spread); as they are
    where ``spread`` is None."""
    if spread is None:
        return images
    return images * rng.uniform(*spread, (len(images), 1, 1, 1)).astype(images.dtype)


def read_spreads(subject, network, draws: int, seed: int = 0) -> dict[str, tuple[float, float]]:
    """{spread: (slant bias, direction error) of the network's lights}, each averaged over
    ``draws`` draws of the intensities (one for ``equal``)."""
    rng = np.random.default_rng(seed)
    out = {}
    for name, spread in SPREADS.items():
        figures = []
        for _ in range(1 if spread is None else draws):
            images = np.ascontiguousarray(rescaled(subject.images, spread, rng), dtype=np.float32)
            directions = network(subject.replace(images=images, light_intensities=None)).directions
            figures.append((light_slant_bias(directions, subject.light_directions),
                            light_direction_mae(directions, subject.light_directions)))
        out[name] = tuple(np.mean(figures, axis=0))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=benchmark.DEFAULT_DATA)
    parser.add_argument("--subjects", nargs="*", default=list(RENDERS),
                        help="unps's rendered subjects to read beside DiLiGenT's three")
    parser.add_argument("--draws", type=int, default=3, help="draws of the intensities per spread")
    parser.add_argument("--set", dest="settings", nargs="*", default=[],
                        help="light.<key>=<value> overrides, e.g. checkpoint=W.pt")
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    if args.draws < 1:
        parser.error(f"--draws must be at least 1, got {args.draws}")
    logging.basicConfig(level=logging.ERROR)
    torch.set_num_threads(args.threads)
    try:
        weights = benchmark.weights_used(args.settings)
    except InputError as e:
        parser.error(str(e))
    network, _ = benchmark.light_source([], args.settings)
    cases = [(name, read) for _, name, _, read in benchmark.cases(["diligent"], ["96"], args.data, None)]
    cases += [(name, lambda name=name: benchmark.synthetic(name)) for name in args.subjects]
    print(f"slant bias / direction error of the network's lights (weights {weights}), "
          "the images' intensities drawn from:")
    print(f"{'subject':<12}" + "".join(f"{name:>20}" for name in SPREADS))
    rows = []
    for name, read in cases:
        try:
            subject = read()
        except InputError as e:
            print(f"{name:<12} skipped: {e}")
            continue
        row = read_spreads(subject, network, args.draws)
        rows.append(row)
        print(f"{name:<12}" + "".join(f"{f'{s:+.2f}° / {e:.2f}°':>20}" for s, e in row.values()), flush=True)
    if rows:
        print(f"{'mean':<12}" + "".join(
            f"{f'{np.mean([r[k][0] for r in rows]):+.2f}° / {np.mean([r[k][1] for r in rows]):.2f}°':>20}"
            for k in SPREADS))


if __name__ == "__main__":
    main()

"""A picture of the light benchmark: every object, its true normals, and what each light stage did.

    python experiments/light_benchmark/gallery.py                      # objects.png beside this file
    python experiments/light_benchmark/gallery.py --tag runP-default   # with that run's light errors

One panel per object of the benchmark group: the 96-light capture's image lit nearest the view
(scaled to the stack's 99th percentile, as stored: 8-bit or 16-bit), and its true normals (RGB =
(n + 1) / 2). With ``--tag``, the panel's title gives the light direction error of the network and
of the final lights under 96, 20 and 12 lights, read from ``<cache>/results/<tag>`` (what
``benchmark.py --tag`` wrote); a case not run there reads "–". Renders what is not in the cache
(about 5 minutes an object).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import scenes  # noqa: E402
from benchmark import DEFAULT_CACHE, DEFAULT_DATA, cases  # noqa: E402

COLUMNS = 6


def frontal_image(images: np.ndarray, directions: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The image lit nearest the view axis, scaled so the stack's 99th percentile on the object is 1.

    Args:
        images: (n, H, W, 3) linear RGB; directions: (n, 3) unit, z toward the camera; mask (H, W).

    Returns:
        (H, W, 3) in [0, 1], white off the object.
    """
    level = np.percentile(images[:, mask], 99)
    picture = np.clip(images[int(np.argmax(directions[:, 2]))] / max(level, 1e-12), 0, 1)
    picture[~mask] = 1.0
    return picture


def normal_picture(normals: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(H, W, 3) unit normals as RGB = (n + 1) / 2, white off the object."""
    picture = (normals + 1) / 2
    picture[~mask] = 1.0
    return np.clip(picture, 0, 1)


def stage_errors(results: Path, name: str) -> str:
    """'network → final' light direction errors under each light set, from a results folder.

    >>> stage_errors(Path("/nonexistent"), "blob01")
    '96: –  20: –  12: –'
    """
    parts = []
    for label in scenes.LIGHT_SETS:
        path = results / f"benchmark-{name}-{label}.json"
        if path.is_file():
            stages = json.loads(path.read_text())["stages"]
            parts.append(f"{label}: {stages[0]['dir']:.1f}→{stages[-1]['dir']:.1f}°")
        else:
            parts.append(f"{label}: –")
    return "  ".join(parts)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    parser.add_argument("--tag", default=None, help="light errors from <cache>/results/<tag> in the titles")
    parser.add_argument("--out", type=Path, default=Path(__file__).with_name("objects.png"))
    args = parser.parse_args()
    results = args.cache / "results" / args.tag if args.tag else None
    if results is not None and not results.is_dir():
        parser.error(f"--tag {args.tag}: no results folder {results} "
                     f"(run benchmark.py --tag {args.tag} first)")
    panels = [(name, read()) for _, name, _, read in cases(["benchmark"], ["96"], args.data, args.cache)]
    rows = -(-len(panels) // (COLUMNS // 2))
    fig, axes = plt.subplots(rows, COLUMNS, figsize=(COLUMNS * 1.9, rows * 2.15), squeeze=False)
    storage = {obj.name: obj.storage for obj in scenes.OBJECTS}
    for k, (name, subject) in enumerate(panels):
        left, right = axes[k // (COLUMNS // 2), 2 * (k % (COLUMNS // 2)):][:2]
        left.imshow(frontal_image(subject.observed_images(), subject.light_directions, subject.mask))
        right.imshow(normal_picture(subject.normals, subject.mask))
        title = f"{name} ({storage[name]})"
        if results is not None:
            title += "\n" + stage_errors(results, name)
        left.set_title(title, fontsize=7, loc="left")
    for ax in axes.flat:
        ax.axis("off")
    caption = "image lit nearest the view, true normals"
    if results is not None:
        caption += f"; light direction error, network → final ({args.tag})"
    fig.suptitle(caption, fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.985))
    partial = args.out.with_name(args.out.stem + ".partial.png")
    fig.savefig(partial, dpi=80)
    partial.replace(args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()

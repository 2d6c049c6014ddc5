"""Normals read off specular highlights (``preset.highlights``), its thresholds measured on fits
made without it.

    python experiments/light_benchmark/normals.py --methods unps --set threads=1 \
        preset.highlights=false --tag plain
    python experiments/light_benchmark/highlights.py --run plain                   # ~2 min
    python experiments/light_benchmark/highlights.py --run plain --diligent ball=<run> cat=<run> pot1=<run> \
        --synthetic Rose=<run> Vase=<run>

For each object of a ``normals.py`` run made with ``preset.highlights=false`` (and each DiLiGenT
or synthetic subject given as ``name=<run folder of python -m unps.fit subject=name light=gt
preset.highlights=false>``), the pixels that :func:`unps.inverse.highlights.highlight_normals`
finds lit by a highlight are given its half vector, under the shipped thresholds and under the
variants below, and the mean error is printed against the fit's. The fits are not rerun: the
rule acts on the finished normals, as the fit applies it.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import scenes  # noqa: E402

from hydra import compose, initialize_config_module  # noqa: E402
from hydra.utils import instantiate  # noqa: E402

from unps.data.checks import usable_subject  # noqa: E402
from unps.data.diligent import read_diligent_object, read_folder  # noqa: E402
from unps.inverse import highlights  # noqa: E402
from unps.metrics import angular_error  # noqa: E402

DEFAULT_CACHE = Path("~/.cache/unps/light_benchmark").expanduser()
THRESHOLDS = ("PEAK_RATIO", "NOT_LAMBERTIAN", "MIN_LIT", "MAX_SPACING_DEG")   # of unps.inverse.highlights
VARIANTS = {   # label: the THRESHOLDS
    "shipped": tuple(getattr(highlights, name) for name in THRESHOLDS),
    "peak 5": (5.0, 0.4, 6, 15.0),
    "peak 5, cosine 0.3": (5.0, 0.3, 6, 15.0),
    "peak 12": (12.0, 0.4, 6, 15.0),
    "cosine 0.5": (8.0, 0.5, 6, 15.0),
    "no cosine test": (8.0, -1.0, 6, 15.0),
    "any lit count": (8.0, 0.4, 0, 15.0),
}


def with_rule(fit: np.ndarray, gt: np.ndarray, shading: np.ndarray, lights: np.ndarray,
              variant: tuple[float, float, int, float]) -> tuple[float, float]:
    """Mean error of ``fit`` (P, 3) against ``gt`` with the highlight rule of ``variant`` applied,
    and the share of pixels it changed."""
    saved = tuple(getattr(highlights, name) for name in THRESHOLDS)
    try:
        for name, value in zip(THRESHOLDS, variant):
            setattr(highlights, name, value)
        half, lit = highlights.highlight_normals(shading, lights)
    finally:
        for name, value in zip(THRESHOLDS, saved):
            setattr(highlights, name, value)
    return float(angular_error(np.where(lit[:, None], half, fit), gt).mean()), float(lit.mean())


def cases(cache: Path, run: str, diligent: list[str], synthetic: list[str]):
    """(name, subject, normals file) of each object of the run, then of each DiLiGenT and
    synthetic one."""
    for obj in scenes.OBJECTS:
        normals = cache / "normals" / run / f"{obj.name}-unps" / "normals.npy"
        if normals.is_file():
            folder = cache / f"{obj.name}-{obj.key()}" / "96"
            subject = read_folder(folder, name=obj.name, quantization=scenes.quantization(obj.storage))
            yield obj.name, subject, normals
    for item in diligent:
        name, folder = item.split("=", 1)
        yield name, read_diligent_object(os.environ["UNPS_DILIGENT_DIR"], name), Path(folder) / "normals.npy"
    for item in synthetic:
        name, folder = item.split("=", 1)
        with initialize_config_module("unps.conf", version_base="1.3"):
            config = compose("fit", overrides=[f"subject={name}"])
        subject = usable_subject(instantiate(config.subject, _partial_=True)())
        yield name, subject, Path(folder) / "normals.npy"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    parser.add_argument("--run", required=True, help="tag of a normals.py run with preset.highlights=false")
    parser.add_argument("--diligent", nargs="*", default=[], metavar="NAME=RUN")
    parser.add_argument("--synthetic", nargs="*", default=[], metavar="NAME=RUN")
    args = parser.parse_args(argv)
    print(f"fits of normals.py --tag {args.run} (96 lights, light=gt); normal MAE °, "
          f"share of pixels changed in brackets")
    print(f"{'object':<12}{'fit':>7}" + "".join(f"{label:>22}" for label in VARIANTS))
    gains = {label: [] for label in VARIANTS}
    names = []
    for name, subject, file in cases(args.cache, args.run, args.diligent, args.synthetic):
        mask = subject.mask & (np.linalg.norm(subject.normals, axis=-1) > 0.5)
        fit, gt = np.load(file)[mask], subject.normals[mask]
        shading = subject.images[:, mask].mean(-1)
        base = float(angular_error(fit, gt).mean())
        line = f"{name:<12}{base:>6.2f}°"
        for label, variant in VARIANTS.items():
            error, share = with_rule(fit, gt, shading, subject.light_directions, variant)
            gains[label].append(error - base)
            line += f"{error:>14.2f}° ({share:.2f})"
        names.append(name)
        print(line, flush=True)
    benchmark = [k for k, name in enumerate(names) if name in {o.name for o in scenes.OBJECTS}]
    print("\nchange of the benchmark's mean; objects worse by > 0.05°; the other subjects' changes")
    for label, change in gains.items():
        change = np.array(change)
        others = ", ".join(f"{names[k]} {change[k]:+.2f}°" for k in range(len(names)) if k not in benchmark)
        print(f"{label:<20}{change[benchmark].mean():+7.2f}°  worse on {(change[benchmark] > 0.05).sum():>2}"
              f"   {others}")


if __name__ == "__main__":
    main()

"""Reading a sweep folder: its finished runs, picked by setting, and formatted for tables."""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from unps.data.catalogue import subjects
from unps.errors import InputError

SYNTHETIC = subjects("synthetic")

DILIGENT = subjects("diligent")

PAPER_SUBJECTS = SYNTHETIC[:6]

METHODS = ("woodham", "rpca", "nayar", "unps")

METHOD_NAMES = {"woodham": "Woodham", "rpca": "robust init. (RPCA)", "nayar": "Nayar (15 it.)",
                "unps": "ours (unps)"}

LIGHTS = ("gt", "estimated", "refine")


@dataclass(frozen=True)


class Run:
    """One finished run: its folder and its ``metrics.json``."""

    folder: Path
    metrics: dict

    def __getitem__(self, key):
        return self.metrics.get(key)


def collect(sweep: Path) -> tuple[list[Run], list[Path]]:
    """Finished runs (a ``metrics.json``) and unfinished ones (a ``.hydra`` folder without it)
    under ``sweep``, in path order.

    Raises:
        InputError: ``sweep`` is not a folder or holds no finished run.
    """
    if not sweep.is_dir():
        raise InputError(f"{sweep}: not a folder (expected a sweep folder, e.g. multirun/noise)")
    runs = []
    for path in sorted(sweep.rglob("metrics.json")):
        try:
            runs.append(Run(path.parent, json.loads(path.read_text())))
        except json.JSONDecodeError as error:
            raise InputError(f"{path}: not valid JSON ({error})") from error
    unfinished = sorted(p.parent for p in sweep.rglob(".hydra") if not (p.parent / "metrics.json").exists())
    if not runs:
        raise InputError(f"{sweep}: no finished run (no metrics.json below it)")
    return runs, unfinished


def subject_order(names: Iterable[str]) -> list[str]:
    """Synthetic subjects in the paper's order, then DiLiGenT's, then any others by name."""
    known = SYNTHETIC + DILIGENT
    names = set(names)
    return [n for n in known if n in names] + sorted(names - set(known))


def pick(runs: Sequence[Run], **where) -> Run | None:
    """The run whose metrics match every ``key=value``; None if there is none.

    Raises:
        InputError: more than one run matches (a sweep folder mixing two sweeps).
    """
    found = [r for r in runs if all(r[k] == v for k, v in where.items())]
    if len(found) > 1:
        raise InputError(f"{len(found)} runs match {where}: {', '.join(str(r.folder) for r in found)}; "
                         f"report one sweep at a time")
    return found[0] if found else None


def mae(run: Run | None) -> float | None:
    return None if run is None else run["normal_mae"]


def fmt(value: float | None, digits: int = 2, sign: bool = False) -> str:
    if value is None or not np.isfinite(value):
        return "—"
    return f"{value:+.{digits}f}" if sign else f"{value:.{digits}f}"


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def mean_of(values: Iterable[float | None]) -> float | None:
    """The mean, or None when any value is missing (a partial average would mislead)."""
    values = list(values)
    if not values or any(v is None for v in values):
        return None
    return float(np.mean(values))


def settings_line(runs: Sequence[Run]) -> str:
    """Preset, images and resolution of the runs, as the report's header states them."""
    def distinct(key, show=str):
        return ", ".join(sorted({show(r[key]) for r in runs if r[key] is not None})) or "—"
    resolution = distinct("resolution", lambda v: f"{v[0]}×{v[1]}")
    return (f"{len(runs)} runs; method {distinct('method')}; preset {distinct('preset')}; "
            f"images {distinct('n_images')}; resolution (H×W) {resolution}; seed {distinct('seed')}")

"""Any other sweep: one row per run, with the settings that vary."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
import json

from unps.report.collect import Run, fmt, markdown_table


def report_sweep(runs: Sequence[Run], out: Path) -> tuple[str, list[Path]]:
    """Any other sweep: one row per run, with the settings that differ between runs."""
    keys = ["subject", "method", "light", "noise", "preset", "interreflection", "facet_downsample", "seed"]
    varying = [k for k in keys if len({json.dumps(r[k]) for r in runs}) > 1] or ["subject"]
    rows = [[str(r[k]) for k in varying] + [fmt(r["normal_mae"]), fmt(r["light_dir_mae"]),
                                           fmt(r["runtime_s"], 1), r.folder.name] for r in runs]
    return markdown_table(varying + ["normal MAE (°)", "light MAE (°)", "time (s)", "folder"], rows), []

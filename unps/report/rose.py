"""Case study 3: the failure case, Rose."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from unps.paper import PAPER_ROSE_MAE
from unps.report.collect import LIGHTS, Run, fmt, markdown_table
from unps.report.figures import picture_grid, qualitative_row, read_rgb, save


def report_rose(runs: Sequence[Run], out: Path) -> tuple[str, list[Path]]:
    ordered = sorted(runs, key=lambda r: (LIGHTS.index(r["light"]) if r["light"] in LIGHTS else 9))
    rows = [[r["subject"], r["light"], fmt(r["normal_mae"]), fmt(r["normal_median"]),
             f"{100 * r['acc_30']:.1f} %"] for r in ordered]
    rows.append(["Rose (paper)", "estimated", fmt(PAPER_ROSE_MAE), "—", "—"])
    table = markdown_table(["subject", "light", "MAE (°)", "median (°)", "< 30°"], rows)
    cells = [[("ground truth", read_rgb(r.folder / "normals_gt.png")), *qualitative_row(r),
              ("reconstruction", read_rgb(r.folder / "reconstruction.png"))]
             for r in ordered]
    fig = picture_grid(cells, "The failure case: Rose (supplementary Fig. 1)")
    return table, [save(fig, out / "rose.png")]

"""Supplementary Fig. 2: robustness to image noise."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from unps.report.collect import Run, fmt, mae, markdown_table, mean_of, pick, subject_order
from unps.report.figures import pyplot, save


def report_noise(runs: Sequence[Run], out: Path) -> tuple[str, list[Path]]:
    import matplotlib.ticker

    subjects = subject_order(r["subject"] for r in runs)
    sigmas = sorted({r["noise"] for r in runs})
    found = {(s, sigma): pick(runs, subject=s, noise=sigma) for s in subjects for sigma in sigmas}
    grid = {key: mae(run) for key, run in found.items()}
    average = {sigma: mean_of(grid[s, sigma] for s in subjects) for sigma in sigmas}
    header = ["subject"] + [f"σ = {sigma:g}" for sigma in sigmas]
    rows = [[s] + [fmt(grid[s, sigma]) for sigma in sigmas] for s in subjects]
    rows.append(["**average**"] + [fmt(average[sigma]) for sigma in sigmas])
    table = "Normal MAE (°):\n\n" + markdown_table(header, rows)
    light_rows = [[s] + [fmt(None if found[s, sigma] is None else found[s, sigma]["light_dir_mae"])
                         for sigma in sigmas] for s in subjects]
    if any(cell != "—" for row in light_rows for cell in row[1:]):
        table += ("\n\nDirection MAE (°) of the lights used (the light network sees the noisy images "
                  "too):\n\n" + markdown_table(header, light_rows))

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.2, 3.6))
    for s in subjects:
        ax.plot(sigmas, [grid[s, sigma] if grid[s, sigma] is not None else np.nan for sigma in sigmas],
                "o-", lw=1, ms=3, label=s)
    ax.plot(sigmas, [average[sigma] if average[sigma] is not None else np.nan for sigma in sigmas],
            "s-", color="black", lw=2.5, label="average")
    ax.set_xlabel("noise σ (relative to the 99th percentile of the pixels)")
    ax.set_ylabel("normal MAE (°), log scale")
    ax.set_yscale("log")
    for axis_format in (ax.yaxis.set_major_formatter, ax.yaxis.set_minor_formatter):
        axis_format(matplotlib.ticker.FormatStrFormatter("%g"))
    ax.set_xticks(sigmas)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))   # beside: no curve hidden
    ax.set_title("MAE against image noise (supplementary Fig. 2)")
    return table, [save(fig, out / "noise.png")]

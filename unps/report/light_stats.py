"""Supplementary Fig. 6: the estimated lights on the calibration sphere and the subjects."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from unps.paper import PAPER_SPHERE_LIGHT_MAE
from unps.report.collect import Run, fmt, markdown_table, subject_order
from unps.report.figures import pyplot, read_light_file, save


def report_light_stats(runs: Sequence[Run], out: Path) -> tuple[str, list[Path]]:
    by_subject = {r["subject"]: r for r in runs}
    subjects = subject_order(by_subject)
    rows = [[s, str(by_subject[s]["n_images"]), fmt(by_subject[s]["light_dir_mae"]),
             fmt(by_subject[s]["light_int_err"], 3)] for s in subjects]
    rows.append(["Sphere (paper)", "—", fmt(PAPER_SPHERE_LIGHT_MAE), "—"])
    table = markdown_table(["subject", "images", "direction MAE (°)", "intensity error"], rows)
    figures = []
    plt = pyplot()
    for s in subjects:
        folder = by_subject[s].folder
        if not (folder / "lights_gt.txt").exists():
            continue
        true, est = read_light_file(folder / "lights_gt.txt"), read_light_file(folder / "lights.txt")
        order = np.argsort(np.arctan2(true[:, 1], true[:, 0]))
        fig, axes = plt.subplots(3, 1, figsize=(8, 6), sharex=True)
        for k, (ax, axis) in enumerate(zip(axes, "xyz")):
            ax.plot(true[order, k], "-", color="tab:green", label="ground truth")
            ax.plot(est[order, k], ".-", color="tab:red", lw=0.8, ms=3, label="estimated")
            ax.set_ylabel(f"l_{axis}")
            ax.grid(alpha=0.3)
        axes[0].legend(loc="upper right", fontsize=8)
        axes[0].set_title(f"{s}: light directions per image (MAE {fmt(by_subject[s]['light_dir_mae'])}°)")
        axes[-1].set_xlabel("image (ordered by true azimuth)")
        figures.append(save(fig, out / f"lights_{s}.png"))
    return table, figures

"""Supplementary Figs. 7–14: the baselines, qualitative grids and reflectance maps."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from unps.report.collect import (METHODS, METHOD_NAMES, Run, fmt, mae, markdown_table, mean_of, pick,
                                 subject_order)
from unps.report.figures import error_picture, picture_grid, pyplot, read_rgb, save


def report_baselines(runs: Sequence[Run], out: Path) -> tuple[str, list[Path]]:
    subjects = subject_order(r["subject"] for r in runs)
    methods = [m for m in METHODS if any(r["method"] == m for r in runs)]
    grid = {(s, m): pick(runs, subject=s, method=m) for s in subjects for m in methods}
    rows = [[s] + [fmt(mae(grid[s, m])) for m in methods] for s in subjects]
    rows.append(["**average**"] + [fmt(mean_of(mae(grid[s, m]) for s in subjects)) for m in methods])
    table = markdown_table(["subject"] + [METHOD_NAMES[m] for m in methods], rows)
    figures = []
    for s in subjects:
        present = [grid[s, m] for m in methods if grid[s, m] is not None]
        gt = next((read_rgb(r.folder / "normals_gt.png") for r in present), None)
        cells = [[("ground truth", gt)] + [(f"{METHOD_NAMES[r['method']]}\n{fmt(r['normal_mae'])}°",
                                           read_rgb(r.folder / "normals.png")) for r in present],
                 [("", None)] + [("error", error_picture(r.folder)) for r in present]]
        figures.append(save(picture_grid(cells, f"{s} (light={present[0]['light']})"), out / f"grid_{s}.png"))
    reflectance = [(s, read_rgb(grid[s, "unps"].folder / "reflectance.png"))
                   for s in subjects if "unps" in methods and grid[s, "unps"] is not None]
    reflectance = [(s, image) for s, image in reflectance if image is not None]
    if reflectance:
        plt = pyplot()
        width = 10.0   # inches; each row as tall as its contact sheet at this width, plus its title
        heights = [width * image.shape[0] / image.shape[1] + 0.3 for _, image in reflectance]
        fig, axes = plt.subplots(len(reflectance), 1, figsize=(width, sum(heights) + 0.5), squeeze=False,
                                 gridspec_kw={"height_ratios": heights}, layout="constrained")
        for ax, (s, image) in zip(axes[:, 0], reflectance):
            ax.imshow(image, interpolation="nearest")
            ax.set_axis_off()
            ax.set_title(s, fontsize=8, loc="left")
        fig.suptitle("Reflectance maps of the fit, 6 of the images (supplementary Figs. 13–14)")
        figures.append(save(fig, out / "reflectance_maps.png"))
    return table, figures

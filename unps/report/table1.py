"""Supplementary Table 1: calibrated against estimated (and refined) lights."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from unps.paper import PAPER_MAE
from unps.report.collect import (LIGHTS, PAPER_SUBJECTS, Run, fmt, mae, markdown_table, mean_of, pick,
                                 subject_order)
from unps.report.figures import pyplot, save


def report_table1(runs: Sequence[Run], out: Path) -> tuple[str, list[Path]]:
    subjects = subject_order(r["subject"] for r in runs)
    found = {(s, light): pick(runs, subject=s, light=light) for s in subjects for light in LIGHTS}
    ours = {key: mae(run) for key, run in found.items()}
    rows = []
    for s in subjects:
        gt, est, refine = (ours[s, light] for light in LIGHTS)
        paper_gt, paper_est = PAPER_MAE["gt"].get(s), PAPER_MAE["estimated"].get(s)
        light_errors = " → ".join(fmt(found[s, light]["light_dir_mae"]) for light in LIGHTS[1:]
                                  if found[s, light] is not None)
        rows.append([s, fmt(gt), fmt(est), fmt(None if None in (gt, est) else est - gt, sign=True),
                     fmt(refine), light_errors or "—", fmt(paper_gt), fmt(paper_est),
                     fmt(None if None in (paper_gt, paper_est) else paper_est - paper_gt, sign=True)])
    groups = [("average, the paper's six", PAPER_SUBJECTS)]
    if set(subjects) != set(PAPER_SUBJECTS):
        groups.append(("average, all", subjects))
    for label, group in groups:
        if not set(group) <= set(subjects):
            continue
        gt, est, refine = (mean_of(ours[s, light] for s in group) for light in LIGHTS)
        paper_gt = mean_of(PAPER_MAE["gt"].get(s) for s in group)
        paper_est = mean_of(PAPER_MAE["estimated"].get(s) for s in group)
        rows.append([f"**{label}**", fmt(gt), fmt(est),
                     fmt(None if None in (gt, est) else est - gt, sign=True), fmt(refine), "",
                     fmt(paper_gt), fmt(paper_est),
                     fmt(None if None in (paper_gt, paper_est) else paper_est - paper_gt, sign=True)])
    table = markdown_table(["subject", "GT light", "estimated", "est. − GT", "refine",
                            "light error: est. → refined", "paper GT", "paper est.", "paper est. − GT"],
                           rows)
    table += ("\n\nNormal MAE in degrees; the light error is the direction MAE of the lights used "
              "(degrees).")

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(1.1 * len(subjects) + 2, 3.6))
    x = np.arange(len(subjects))
    for k, (light, colour) in enumerate(zip(LIGHTS, ("tab:green", "tab:red", "tab:blue"))):
        values = [ours[s, light] if ours[s, light] is not None else np.nan for s in subjects]
        ax.bar(x + (k - 1) * 0.27, values, 0.27, color=colour, label=f"ours, light={light}")
    for light, marker in (("gt", "o"), ("estimated", "D")):
        values = [PAPER_MAE[light].get(s, np.nan) for s in subjects]
        ax.plot(x, values, marker, mfc="none", mec="black", ls="none", label=f"paper, {light}")
    ax.set_xticks(x, subjects)
    ax.set_ylabel("normal MAE (°)")
    ax.legend(fontsize=7, ncol=2)
    ax.grid(axis="y", alpha=0.3)
    ax.set_title("Calibrated vs uncalibrated (supplementary Table 1)")
    figure = save(fig, out / "table1.png")
    return table, [figure]

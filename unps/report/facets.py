"""§2.3, Table 3: the facet grid of the interreflection kernel."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from unps.errors import InputError
from unps.paper import PAPER_FACETS
from unps.report.collect import Run, fmt, markdown_table, mean_of, subject_order
from unps.report.figures import pyplot, save


def facet_setting(run: Run) -> str:
    return f"×{run['facet_downsample']}" if run["interreflection"] else "off"


def report_facets(runs: Sequence[Run], out: Path) -> tuple[str, list[Path]]:
    subjects = subject_order(r["subject"] for r in runs)
    settings = sorted({facet_setting(r) for r in runs}, key=lambda s: (s == "off", len(s), s))
    cell = {(facet_setting(r), r["subject"]): r for r in runs}
    if len(cell) != len(runs):
        raise InputError("two runs share a subject and facet setting; report one sweep at a time")

    def rows(value: Callable[[Run], float | None], digits: int) -> list[list[str]]:
        body = [[s] + [fmt(value(cell[k]) if (k := (setting, s)) in cell else None, digits)
                       for setting in settings] for s in subjects]
        averages = [mean_of(value(cell[setting, s]) if (setting, s) in cell else None for s in subjects)
                    for setting in settings]
        return body + [["**average**"] + [fmt(a, digits) for a in averages]]

    header = ["subject"] + settings
    facet_rows = [[s] + [str(cell[setting, s]["facets"]) if (setting, s) in cell else "—"
                         for setting in settings if setting != "off"]
                  + [str(PAPER_FACETS[s]) if s in PAPER_FACETS else "—"] for s in subjects]
    table = "\n\n".join([
        "Normal MAE (°):\n\n" + markdown_table(header, rows(lambda r: r["normal_mae"], 2)),
        "Fit time (s, the whole method: robust initialisation, kernel updates and steps):\n\n"
        + markdown_table(header, rows(lambda r: r["runtime_s"], 0)),
        "Facets in the interreflection kernel (the paper's counts are at its own resolution, ×4):\n\n"
        + markdown_table(["subject"] + [s for s in settings if s != "off"] + ["paper (×4)"], facet_rows)])

    # MAE as the change from interreflection=off where that run exists: the subjects' MAEs differ
    # by tens of degrees, the settings' by tenths.
    def mae_shown(setting: str, s: str) -> float:
        if (setting, s) not in cell:
            return np.nan
        return cell[setting, s]["normal_mae"] - (cell["off", s]["normal_mae"] if ("off", s) in cell else 0)

    relative = any(("off", s) in cell for s in subjects)
    plt = pyplot()
    fig, (ax_mae, ax_time) = plt.subplots(1, 2, figsize=(9, 3.4))
    x = np.arange(len(settings))
    for s in subjects:
        ax_mae.plot(x, [mae_shown(setting, s) for setting in settings], "o-",
                    label=s if ("off", s) in cell or not relative else f"{s} (absolute)")
        ax_time.plot(x, [cell[k]["runtime_s"] if (k := (setting, s)) in cell else np.nan
                         for setting in settings], "o-", label=s)
    mae_label = "normal MAE − MAE with it off (°)" if relative else "normal MAE (°)"
    if relative:
        ax_mae.axhline(0, color="grey", lw=0.8)
    for ax, label in ((ax_mae, mae_label), (ax_time, "fit time (s)")):
        ax.set_xticks(x, settings)
        ax.set_xlabel("facet grid (interreflection kernel)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    ax_mae.legend(fontsize=7)
    fig.suptitle("Facet downsampling of the interreflection kernel")
    return table, [save(fig, out / "facets.png")]

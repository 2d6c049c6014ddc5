"""``python -m unps.report <sweep folder> [--out DIR]``: the table and figures of a study.

    python -m unps.fit -m experiment=noise          # runs land in multirun/noise/<overrides>/
    python -m unps.report multirun/noise            # writes multirun/noise/report/
    python -m unps.report multirun/noise --out experiments/noise

Every run folder with a ``metrics.json`` under the sweep folder is read; its ``study`` (set by
``experiment=…``) picks the report: ``table1``, ``noise``, ``facets``, ``rose``, ``light_stats``,
``baselines``, or, for any other sweep, one row per run with the settings that vary. Folders
that a sweep started but did not finish are listed, never silently left out. The report is
``results.md`` (markdown tables, next to the paper's published figures where it has them) and
PNG figures; it is a function of the runs' files only, so a rerun of the same sweep with the
same seed on the same kind of machine regenerates it (run times apart).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path

from unps.errors import InputError
from unps.io.files import atomic_path
from unps.report.baselines import report_baselines
from unps.report.collect import collect, settings_line
from unps.report.facets import report_facets
from unps.report.light_stats import report_light_stats
from unps.report.noise import report_noise
from unps.report.rose import report_rose
from unps.report.sweep import report_sweep
from unps.report.table1 import report_table1

log = logging.getLogger("unps.report")

REPORTS: dict[str, tuple[str, Callable]] = {
    "table1": ("Calibrated vs uncalibrated light (supplementary Table 1)", report_table1),
    "noise": ("Robustness to image noise (supplementary Fig. 2)", report_noise),
    "facets": ("Facet downsampling of the interreflection kernel", report_facets),
    "rose": ("The failure case: Rose (supplementary case study 3)", report_rose),
    "light_stats": ("Light estimation statistics (supplementary Fig. 6)", report_light_stats),
    "baselines": ("Baselines and qualitative results (supplementary Figs. 7–14)", report_baselines),
}


def report(sweep: Path, out: Path | None = None) -> Path:
    """Write ``results.md`` and the figures of the study in ``sweep`` into ``out``
    (default ``<sweep>/report``); returns the markdown's path.

    Raises:
        InputError: no finished run, or runs of different studies in one folder.
    """
    runs, unfinished = collect(sweep)
    studies = {r["study"] for r in runs}
    if len(studies) > 1:
        names = ", ".join(sorted(map(str, studies)))
        raise InputError(f"{sweep}: runs of several studies ({names}); report one sweep folder at a time")
    study = studies.pop()
    title, write = REPORTS.get(study, ("Sweep", report_sweep))
    out = Path(out) if out is not None else sweep / "report"
    out.mkdir(parents=True, exist_ok=True)
    table, figures = write(runs, out)
    lines = [f"# {title}", "", f"Study `{study}`: {settings_line(runs)}.", "", table, ""]
    lines += [f"![{f.stem}]({f.name})" for f in figures]
    if unfinished:
        lines += ["", f"**{len(unfinished)} unfinished runs** (no metrics.json): "
                  + ", ".join(f"`{p.relative_to(sweep)}`" for p in unfinished)]
    path = out / "results.md"
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    log.info("%s: %d runs → %s (%d figures)", study, len(runs), path, len(figures))
    return path

"""The light benchmark's run folders: each holds results made with one set of settings."""

from __future__ import annotations

import json
from pathlib import Path


def claim(out: Path, made_with) -> None:
    """Record in run folder ``out`` what its results are made with (any JSON value) on first use;
    later, refuse anything else, so that a folder never mixes rows made with different settings
    and a rerun resumes only its own.

    Raises:
        ValueError: ``out`` holds results made otherwise; the message names both and the way out.
    """
    recorded = out / "settings.json"
    if recorded.is_file():
        before = json.loads(recorded.read_text())
        if before != made_with:
            raise ValueError(f"{out} holds results made with {json.dumps(before)}, not "
                             f"{json.dumps(made_with)}: give another --tag or --out")
        return
    out.mkdir(parents=True, exist_ok=True)
    recorded.write_text(json.dumps(made_with) + "\n")


def kept_or_run(cases, out: Path, run, report_only: bool = False):
    """For each case of :func:`benchmark.cases` (group, name, label, read), its result as kept in
    run folder ``out``, or, where it has not run yet, ``run(read())`` kept there (skipped when
    ``report_only``). Yields (group, name, label, result, ran_now)."""
    for group, name, label, read in cases:
        path = out / f"{group}-{name}-{label}.json"
        if path.is_file():
            yield group, name, label, json.loads(path.read_text()), False
        elif not report_only:
            result = run(read())
            path.write_text(json.dumps(result))
            yield group, name, label, result, True

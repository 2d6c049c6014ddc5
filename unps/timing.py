"""Where a run's seconds go: named stages, timed while a :func:`recording` is open.

    with recording() as seconds:
        with stage("robust initialisation"):
            ...
    seconds   # {"robust initialisation": 0.41}

Stages nest freely (a parent's seconds include its children's: "system assembly" holds a
"robust initialisation") and add up when entered again (every step's "normal network" lands in one
total); every open recording sees every stage. With no recording open, :func:`stage` costs one
attribute lookup, so library code can mark its stages unconditionally; ``@stage(name)`` also
decorates a function. ``python -m unps.fit`` records every run into ``metrics.json``
(``stage_seconds``); ``experiments/speed/stages.py`` prints them as a table.
"""

from __future__ import annotations

import time
from collections import defaultdict
from contextlib import contextmanager
from typing import Iterator

_open: list[defaultdict] = []        # the recordings open now


@contextmanager
def recording() -> Iterator[dict[str, float]]:
    """Collect the seconds of every :func:`stage` entered inside; yields the dict it fills."""
    seconds: defaultdict = defaultdict(float)
    _open.append(seconds)
    try:
        yield seconds
    finally:
        del _open[next(i for i, totals in enumerate(_open) if totals is seconds)]   # by identity:
        # two recordings of the same stages compare equal


@contextmanager
def stage(name: str) -> Iterator[None]:
    """Add the wall-clock seconds spent inside to ``name`` in every open recording."""
    if not _open:
        yield
        return
    start = time.perf_counter()
    try:
        yield
    finally:
        _add(name, time.perf_counter() - start)


def _add(name: str, seconds: float) -> None:
    for totals in _open:
        totals[name] += seconds


class Span:
    """A stage whose start and end are two calls apart (e.g. two Lightning hooks)."""

    def __init__(self, name: str):
        self.name, self._start = name, None

    def start(self) -> None:
        self._start = time.perf_counter() if _open else None

    def stop(self) -> None:
        if self._start is not None:
            _add(self.name, time.perf_counter() - self._start)
        self._start = None

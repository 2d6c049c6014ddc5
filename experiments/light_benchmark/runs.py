"""The light benchmark's run folders: each holds results made with one set of settings."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

MARK = "running.pid"
FIT_SETTINGS = ("method", "light", "preset", "interreflection", "seed", "noise", "device")


def weights_digest(checkpoint: str | None) -> str:
    """The first 12 hex digits of the SHA-256 of the light-network weights a run reads: the file
    ``checkpoint`` names, else (``None``, ``""`` or ``"null"``) the weights shipped with unps. A
    study that estimates lights records it in its folder's claim, so that a rerun after new weights
    are shipped is refused rather than mixed with rows of the old network.

    Raises:
        InputError: the weights file is not there.
    """
    from unps.errors import InputError
    from unps.lightnet.system import SHIPPED

    path = Path(checkpoint).expanduser() if checkpoint not in (None, "", "null") else SHIPPED
    if not path.is_file():
        raise InputError(f"{path}: light-network weights not found")
    return hashlib.sha256(path.read_bytes()).hexdigest()[:12]


def claim(out: Path, made_with, way_out: str = "give another --tag or --out") -> None:
    """Record in run folder ``out`` what its results are made with (any JSON value) on first use;
    later, refuse anything else, so that a folder never mixes rows made with different settings
    and a rerun resumes only its own.

    Raises:
        ValueError: ``out`` holds results made otherwise; the message names both and ``way_out``.
    """
    recorded = out / "settings.json"
    if recorded.is_file():
        before = json.loads(recorded.read_text())
        if before != made_with:
            raise ValueError(f"{out} holds results made with {json.dumps(before)}, not "
                             f"{json.dumps(made_with)}: {way_out}")
        return
    out.mkdir(parents=True, exist_ok=True)
    recorded.write_text(json.dumps(made_with) + "\n")


def differences(before, now, where: str = "") -> list[str]:
    """Where two JSON values differ, one ``key.path: before → now`` per differing leaf, ``(none)``
    for a key only one of them has; [] where they are equal.

    A cached row records the settings it was made with, resolved (the defaults included), so
    that a rerun after a default changed makes that row again instead of printing the old one.

    >>> differences({"selfcal": {"steps": 1000, "hold_frame": False}},
    ...             {"selfcal": {"steps": 500, "hold_frame": False}})
    ['selfcal.steps: 1000 → 500']
    >>> differences(None, {"steps": 1})
    ['(none) → {"steps": 1}']
    """
    if before == now:
        return []
    if isinstance(before, dict) and isinstance(now, dict):
        found = []
        for key in sorted(set(before) | set(now), key=str):
            inner = f"{where}.{key}" if where else str(key)
            if key not in before or key not in now:
                found.append(f"{inner}: {_shown(before, key)} → {_shown(now, key)}")
            else:
                found += differences(before[key], now[key], inner)
        return found
    return [f"{where + ': ' if where else ''}{_plain(before)} → {_plain(now)}"]


def listed(changed: list[str], most: int = 3) -> str:
    """The first ``most`` of :func:`differences`' lines, joined, with ``…`` where there are more.

    >>> listed(["a: 1 → 2", "b: 3 → 4"], most=1)
    'a: 1 → 2; …'
    """
    return "; ".join(changed[:most]) + ("; …" if len(changed) > most else "")


def _shown(values: dict, key) -> str:
    return _plain(values[key]) if key in values else "(none)"


def _plain(value) -> str:
    return "(none)" if value is None else json.dumps(value) if isinstance(value, (dict, list, str)) \
        else str(value)


@contextmanager
def held(run_dir: Path) -> Iterator[None]:
    """Mark ``run_dir`` as being run by this process for the length of the block (a file
    ``running.pid`` holding its process id), so that another process of the benchmark — a second
    half run beside this one, or a table read before the rows are done — does not start the same
    run beside it. A mark left by a process that has ended is taken over. (Two processes reaching
    the same folder in the same instant are not kept apart: the benchmark's halves name disjoint
    objects.)

    Raises:
        RuntimeError: a live process holds the folder; the message names it.
    """
    mark = run_dir / MARK
    holder = _holder(mark)
    if holder is not None and _alive(holder):
        raise RuntimeError(f"{run_dir} is being run by process {holder}: wait for it to finish, "
                           f"then read the table again")
    run_dir.mkdir(parents=True, exist_ok=True)
    mark.write_text(str(os.getpid()))
    try:
        yield
    finally:
        mark.unlink(missing_ok=True)


def discard(run_dir: Path) -> None:
    """Delete what a run left in ``run_dir`` (its checkpoints, metrics, pictures and Hydra record)
    so that a fit made again there starts afresh: ``unps.fit`` resumes from a checkpoint it
    finds, and refuses one made with other settings. The mark of :func:`held` stays."""
    if not run_dir.is_dir():
        return
    for child in run_dir.iterdir():
        if child.name == MARK:
            continue
        if child.is_dir() and not child.is_symlink():
            shutil.rmtree(child)
        else:
            child.unlink()


def steps_kept(run_dir: Path, expected: dict) -> bool:
    """Whether the fit kept in ``run_dir`` left a checkpoint and was made with the settings
    ``expected`` (:func:`fit_settings`) but for the preset's read-out ones
    (:data:`unps.inverse.settings.READ_OUT_FIELDS`): ``unps.fit`` resumes from that checkpoint
    (at the last step, where the fit finished) and reads the normals out again, in seconds."""
    recorded = recorded_settings(run_dir)
    if recorded is None or not (run_dir / "checkpoints" / "last.ckpt").is_file():
        return False
    return not differences(_without_read_out(recorded), _without_read_out(expected))


def clear(run_dir: Path, keep_steps: bool) -> None:
    """Make way in ``run_dir`` for a fit with other settings: all it left goes (:func:`discard`),
    but where ``keep_steps`` (:func:`steps_kept`), only its ``metrics.json``, so that the fit
    resumes from its checkpoint."""
    if keep_steps:
        (run_dir / "metrics.json").unlink(missing_ok=True)
    else:
        discard(run_dir)


def _without_read_out(settings: dict) -> dict:
    from unps.inverse.settings import READ_OUT_FIELDS

    preset = {k: v for k, v in (settings.get("preset") or {}).items() if k not in READ_OUT_FIELDS}
    return {**settings, "preset": preset}


def _holder(mark: Path) -> int | None:
    """The process id in ``mark``, or None where it cannot be read."""
    try:
        return int(mark.read_text())
    except (OSError, ValueError):
        return None


def _alive(pid: int) -> bool:
    """Whether process ``pid`` is running (on this machine)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def summaries(cases, out: Path, run, summarise, progress, report_only: bool = False) -> dict:
    """{(group, name, label): summarise(result)} for each case of :func:`benchmark.cases`: its
    result as kept in run folder ``out``, or, where it has not run yet, ``run(read())`` kept
    there, with the line ``progress(case, summary, result)`` printed (skipped when
    ``report_only``)."""
    rows = {}
    for group, name, label, read in cases:
        path = out / f"{group}-{name}-{label}.json"
        if path.is_file():
            rows[group, name, label] = summarise(json.loads(path.read_text()))
        elif not report_only:
            result = run(read())
            path.write_text(json.dumps(result))
            summary = rows[group, name, label] = summarise(result)
            print(progress((group, name, label), summary, result), flush=True)
    return rows


def by_light_set(rows: dict):
    """(group, label, [summary, …]) for each group and light set of ``rows`` (keyed by (group,
    name, label)), groups in name order, light sets from the most lights down."""
    for group, label in sorted({(k[0], k[2]) for k in rows}, key=lambda k: (k[0], -int(k[1]))):
        yield group, label, [s for k, s in rows.items() if k[0] == group and k[2] == label]


def fit_settings(overrides: list[str]) -> dict:
    """The settings of ``python -m unps.fit <overrides>`` that make its results
    (:data:`FIT_SETTINGS`: not the subject's paths, the threads or the output folders), as its run
    folder's ``.hydra/config.yaml`` records them."""
    from hydra import compose, initialize_config_module
    from omegaconf import OmegaConf

    with initialize_config_module("unps.conf", version_base=None):
        config = OmegaConf.to_container(compose("fit", overrides=overrides))
    return {key: config.get(key) for key in FIT_SETTINGS}


def begun(run_dir: Path) -> bool:
    """Whether a fit has run in ``run_dir``: finished (its ``metrics.json``) or stopped part way (the
    settings Hydra records as it starts), so that :func:`stale_run` has something to judge."""
    return (run_dir / "metrics.json").is_file() or (run_dir / ".hydra" / "config.yaml").is_file()


def recorded_settings(run_dir: Path) -> dict | None:
    """The settings of :data:`FIT_SETTINGS` that the run in ``run_dir`` was made with, as its
    ``.hydra/config.yaml`` records them; None where there is no record."""
    from omegaconf import OmegaConf

    recorded = run_dir / ".hydra" / "config.yaml"
    if not recorded.is_file():
        return None
    config = OmegaConf.to_container(OmegaConf.load(recorded))
    return {key: config.get(key) for key in FIT_SETTINGS}


def stale_run(run_dir: Path, expected: dict) -> str | None:
    """Why the run kept in ``run_dir`` cannot stand for a run with the settings ``expected``
    (:func:`fit_settings`): the settings that differ (a default changed since it ran), or no
    record of them; None where it can."""
    recorded = recorded_settings(run_dir)
    if recorded is None:
        return "no record of the settings it was made with"
    changed = differences(recorded, expected)
    if not changed:
        return None
    return f"made with other settings ({listed(changed)})"

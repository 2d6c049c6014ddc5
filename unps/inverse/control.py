"""Running a fit: the Lightning trainer, checkpoints that only resume their own run, random
state carried across a resume, and a clear stop when the loss diverges."""

from __future__ import annotations

import hashlib
import json
import logging
import time
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch

from unps.data.subject import Subject
from unps.device import trainer_placement
from unps.errors import Diverged, InputError, Interrupted

if TYPE_CHECKING:
    from unps.inverse.schedule import Schedule
    from unps.inverse.system import InverseRendering

log = logging.getLogger(__name__)


# Lightning warnings that do not apply to a one-subject fit: the "data loader" is a step counter
# whose random draws the checkpoints restore, and a deprecation inside Lightning itself.
LIGHTNING_NOISE = (".*dataloader is not resumable.*", ".*does not have many workers.*",
                   ".*LeafSpec.*is deprecated.*")


def fingerprint(subject: Subject, light_directions: np.ndarray, settings: dict) -> str:
    """SHA-256 of the working data and the settings the steps depend on (the preset's
    :meth:`~unps.inverse.settings.Preset.fit_fields`, not its read-out ones): a checkpoint resumes
    only the run it came from."""
    digest = hashlib.sha256()
    for array in (subject.images, subject.mask, light_directions):
        digest.update(np.ascontiguousarray(array).tobytes())
    digest.update(json.dumps(settings, sort_keys=True, default=lambda v: np.asarray(v).tolist()).encode())
    return digest.hexdigest()


def train(system: InverseRendering, schedule: Schedule, output_dir: str | Path | None,
          name: str, device: torch.device = torch.device("cpu")) -> tuple[float, int]:
    """Run the schedule with Lightning on ``device``, resuming from
    ``<output_dir>/checkpoints/last.ckpt`` when it holds this run (same fingerprint); returns the
    seconds spent and the step resumed from.

    Raises:
        InputError: the checkpoint belongs to another run.
        Diverged: the loss stopped being finite; the message names the last good checkpoint.
    """
    import lightning as L
    from lightning.pytorch.callbacks import ModelCheckpoint
    from lightning.pytorch.loggers import TensorBoardLogger

    from unps.inverse.callbacks import PROGRESS_SECONDS, FitPictures, ProgressLog, StallWatch

    ckpt_path, resumed_from = None, 0
    progress = ProgressLog(every=schedule.update_every, at_least_every_s=PROGRESS_SECONDS,
                           fresh_every=system.log_every)
    watch = StallWatch(every=schedule.update_every, until=schedule.lr_drop_at)
    options: dict = dict(logger=False, enable_checkpointing=False, callbacks=[progress, watch])
    if output_dir is not None:
        out = Path(output_dir)
        last = out / "checkpoints" / "last.ckpt"
        if last.is_file():
            saved = torch.load(last, map_location="cpu", weights_only=False)
            if saved.get("unps_fingerprint") != system.fingerprint:
                raise InputError(f"{last}: this checkpoint belongs to another run (different images, "
                                 f"lights or settings); choose a new hydra.run.dir or delete it")
            ckpt_path, resumed_from = str(last), int(saved["global_step"])
            log.info("resuming from %s at step %d", last, resumed_from)
        options = dict(
            logger=TensorBoardLogger(str(out), name="tensorboard", version=""),
            callbacks=[ModelCheckpoint(dirpath=out / "checkpoints", save_last=True, save_top_k=0,
                                       every_n_train_steps=schedule.update_every),
                       FitPictures(every=schedule.update_every), progress, watch])
    trainer = L.Trainer(max_steps=schedule.steps, **trainer_placement(device),
                        log_every_n_steps=system.log_every, enable_model_summary=False,
                        enable_progress_bar=False, num_sanity_val_steps=0, **options)
    start = time.perf_counter()
    try:
        with warnings.catch_warnings():
            for message in LIGHTNING_NOISE:
                warnings.filterwarnings("ignore", message=message)
            trainer.fit(system, ckpt_path=ckpt_path)
    except SystemExit:                      # Lightning's answer to Ctrl-C
        if not trainer.interrupted:
            raise
        raise Interrupted(interruption(trainer.global_step, schedule, output_dir)) from None
    except Diverged as e:
        kept = (f"; the last good state (step {schedule.update_every}·k) is kept in "
                f"{Path(output_dir) / 'checkpoints' / 'last.ckpt'}" if output_dir is not None else "")
        raise Diverged(f"unps diverged on {name!r}: {e}{kept}; try a lower preset.lr") from None
    if trainer.global_step < schedule.steps:
        raise RuntimeError(f"the fit stopped at step {trainer.global_step} of {schedule.steps}; "
                           f"rerun in the same folder to resume")
    return time.perf_counter() - start, resumed_from


def interruption(step: int, schedule: Schedule, output_dir: str | Path | None) -> str:
    """What to tell a user who stopped a fit at ``step``.

    >>> from unps.inverse.schedule import Schedule
    >>> print(interruption(37, Schedule(steps=100, update_every=10), "run"))
    interrupted at step 37 of 100: the same command resumes from the checkpoint of step 30 in run/checkpoints
    >>> interruption(50, Schedule(steps=1000, update_every=100), None)
    'interrupted at step 50 of 1000: the same command starts the fit again'
    """
    saved = step // schedule.update_every * schedule.update_every
    if output_dir is None or saved == 0:
        return f"interrupted at step {step} of {schedule.steps}: the same command starts the fit again"
    return (f"interrupted at step {step} of {schedule.steps}: the same command resumes from the "
            f"checkpoint of step {saved} in {Path(output_dir) / 'checkpoints'}")

"""What a fit in progress shows: TensorBoard pictures and log lines (rank zero only)."""

from __future__ import annotations

import logging
import time

import lightning as L
import numpy as np
import torch
from lightning.pytorch.utilities import rank_zero_only

from unps.geometry import integrate_normals
from unps.io.pictures import error_rgb, normal_rgb, to_display
from unps.metrics import angular_error
from unps.timing import stage

log = logging.getLogger("unps.inverse.fit")


def depth_rgb(depth: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(H, W) depth → (H, W, 3) uint8 gray, near = bright, stretched over the object's range."""
    values = depth[mask]
    low, high = float(values.min()), float(values.max())
    t = np.zeros(mask.shape, np.float32)
    t[mask] = (values - low) / max(high - low, 1e-12)
    return np.repeat((np.round(t * 255) * mask)[..., None], 3, -1).astype(np.uint8)


def side_by_side(observed: np.ndarray, reconstructed: np.ndarray) -> np.ndarray:
    """Two (H, W, 3) images on one scale (the observed 99th percentile) → (H, 2W, 3) uint8."""
    return to_display(np.concatenate([observed, reconstructed], 1), observed)


class FitPictures(L.Callback):
    """Every ``every`` steps: normals, error map (with ground truth), depth, and for one image
    the observed | reconstructed pair and its reflectance map."""

    def __init__(self, every: int = 100):
        self.every = every

    @rank_zero_only
    def on_train_batch_end(self, trainer, module, outputs, batch, batch_idx) -> None:
        step = trainer.global_step
        if trainer.logger is None or (step % self.every and step != trainer.max_steps):
            return
        with stage("progress pictures"):
            self.write(trainer.logger.experiment, module, step)

    def write(self, writer, module, step: int) -> None:
        mask = module.mask_np
        with torch.no_grad():
            index = torch.tensor([(step // self.every) % module.images.shape[0]], device=module.device)
            out = module.render(index, noise=False)
        normals = out["normals"][0].permute(1, 2, 0).cpu().numpy()
        writer.add_image("fit/normals", normal_rgb(normals, mask), step, dataformats="HWC")
        writer.add_image("fit/depth", depth_rgb(integrate_normals(normals, mask), mask), step,
                         dataformats="HWC")
        if module.true_normals is not None:
            truth = module.true_normals[0].permute(1, 2, 0).cpu().numpy()
            error = angular_error(normals, truth)
            writer.add_image("fit/error_0_45deg", error_rgb(error, mask), step, dataformats="HWC")
        observed = out["observed"][0].permute(1, 2, 0).cpu().numpy() * mask[..., None]
        reconstructed = out["reconstruction"][0].permute(1, 2, 0).cpu().numpy() * mask[..., None]
        writer.add_image("fit/observed_vs_reconstructed", side_by_side(observed, reconstructed), step,
                         dataformats="HWC")
        reflectance = out["reflectance"][0].permute(1, 2, 0).cpu().numpy() * mask[..., None]
        writer.add_image("fit/reflectance", to_display(reflectance, reflectance[mask]), step,
                         dataformats="HWC")


PROGRESS_SECONDS = 60.0
"""The longest a fit goes without a progress line: on a 2-core CPU the paper preset took 2.4 s a
step on ball alone and 24-31 s on pot1 beside other work (2026-12-03), so a line every 100 steps
alone left a user four minutes to over forty without a word."""


class ProgressLog(L.Callback):
    """One log line every ``every`` steps and at the end: step, loss, MAE when the truth is
    known, seconds per step and time left. Readable in a terminal and in the run's log file,
    where a progress bar is not."""

    FIT = (("loss", "loss/reconstruction", "{:.4f}"), ("normal error", "mae", "{:.2f}°"))

    def __init__(self, every: int = 100, shown: tuple[tuple[str, str, str], ...] = FIT,
                 logger: logging.Logger = log, after_validation: bool = False,
                 at_least_every_s: float | None = None, fresh_every: int = 1):
        """``shown``: (label, logged metric, format) of each figure on the line, when logged.
        ``after_validation``: one line at the end of each validation instead of every ``every``
        steps, so that the line carries the figures of the validation just run.
        ``at_least_every_s``: a line also once that many seconds have passed since the last one,
        on the next step that logs its figures (every ``fresh_every`` steps); None: never."""
        self.every, self.shown, self._log = every, shown, logger
        self.after_validation = after_validation
        self.at_least_every_s, self.fresh_every = at_least_every_s, fresh_every
        self._start: float | None = None
        self._last_line: float | None = None
        self._first_step = 0

    def on_train_start(self, trainer, module) -> None:
        self._start, self._first_step = time.perf_counter(), trainer.global_step
        self._last_line = self._start

    @rank_zero_only
    def on_train_batch_end(self, trainer, module, outputs, batch, batch_idx) -> None:
        if self.after_validation:
            return
        step = trainer.global_step
        due = step % self.every == 0 or step == trainer.max_steps
        if due or self._overdue(step):
            self._line(trainer)

    def _overdue(self, step: int) -> bool:
        return (self.at_least_every_s is not None and step % self.fresh_every == 0
                and time.perf_counter() - self._last_line >= self.at_least_every_s)

    @rank_zero_only
    def on_validation_end(self, trainer, module) -> None:
        if self.after_validation and not trainer.sanity_checking and self._start is not None:
            self._line(trainer)

    def _line(self, trainer) -> None:
        step = trainer.global_step
        self._last_line = time.perf_counter()
        per_step = (self._last_line - self._start) / max(step - self._first_step, 1)
        metrics = trainer.callback_metrics
        shown = [f"{label} {form.format(float(metrics[key]))}" for label, key, form in self.shown
                 if key in metrics]
        self._log.info("step %d/%d: %s (%.3f s/step, %s left)", step, trainer.max_steps, ", ".join(shown),
                       per_step, duration(per_step * (trainer.max_steps - step)))


class StallWatch(L.Callback):
    """Warns, once, when a fit stops moving before its learning rates drop: every ``every``
    steps the normals N_o are compared with those of ``every`` steps before, and a mean change
    under ``least_change_deg`` means that no gradient reaches them any more (a dead fit: its
    result is whatever the networks gave when they stopped, and the run would otherwise end
    looking like any other)."""

    def __init__(self, every: int, until: int, least_change_deg: float = 1e-3):
        self.every, self.until, self.least_change_deg = every, until, least_change_deg
        self._previous: np.ndarray | None = None
        self._previous_loss: float | None = None
        self.stalled_at: int | None = None

    @rank_zero_only
    def on_train_batch_end(self, trainer, module, outputs, batch, batch_idx) -> None:
        step = trainer.global_step
        if step % self.every or step > self.until or self.stalled_at is not None:
            return
        with torch.no_grad():
            normals = module.normals()[0][0].permute(1, 2, 0).double().cpu().numpy()
        loss = float(trainer.callback_metrics.get("loss/reconstruction", float("nan")))
        if self._previous is not None:
            change = float(angular_error(normals, self._previous)[module.mask_np].mean())
            if change < self.least_change_deg:
                self.stalled_at = step
                log.warning("the fit stopped moving at step %d of %d: the normals changed by %.1e° "
                            "over the last %d steps (loss %.4g, %.4g before), so its result is where "
                            "it stalled; try a lower preset.lr or another seed", step,
                            trainer.max_steps, change, self.every, loss, self._previous_loss)
        self._previous, self._previous_loss = normals, loss


def duration(seconds: float) -> str:
    """'42 s', '3 min 05 s'."""
    seconds = int(round(seconds))
    return f"{seconds} s" if seconds < 60 else f"{seconds // 60} min {seconds % 60:02d} s"

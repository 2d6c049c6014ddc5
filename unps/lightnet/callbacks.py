"""Callbacks of the light network's training: TensorBoard pictures (rank zero only), the training rate."""

from __future__ import annotations

import time

import lightning as L
import numpy as np
import torch
from lightning.pytorch.utilities import rank_zero_only


def light_sphere(true: np.ndarray, predicted: np.ndarray, size: int = 128) -> np.ndarray:
    """Directions drawn on the unit sphere seen from the camera (x right, y up).

    Args:
        true, predicted: (n, 3) unit directions; true in green, predicted in red, each pair
            joined by a grey line.

    Returns:
        (3, size, size) uint8.
    """
    image = np.zeros((size, size, 3), np.uint8)
    r, c = np.mgrid[0:size, 0:size]
    radius = (size - 1) / 2
    rho = np.hypot(c - radius, r - radius) / radius
    image[np.abs(rho - 1) < 1.5 / radius] = 90
    to_pixel = lambda d: (np.round(radius - d[:, 1] * radius).astype(int),    # noqa: E731
                          np.round(radius + d[:, 0] * radius).astype(int))
    for a, b in zip(true, predicted):
        for t in np.linspace(0, 1, 24):
            (pr,), (pc,) = to_pixel(((1 - t) * a + t * b)[None])
            image[np.clip(pr, 0, size - 1), np.clip(pc, 0, size - 1)] = 70
    for d, colour in ((true, (60, 220, 60)), (predicted, (230, 60, 60))):
        rows, cols = to_pixel(d)
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                image[np.clip(rows + dr, 0, size - 1), np.clip(cols + dc, 0, size - 1)] = colour
    return image.transpose(2, 0, 1)


class LightSamples(L.Callback):
    """After each validation, log a few input stacks with true vs predicted lights on a sphere."""

    def __init__(self, samples: int = 3):
        self.samples = samples
        self._batch = None

    def on_validation_batch_end(self, trainer, module, outputs, batch, batch_idx, dataloader_idx=0):
        if batch_idx == 0:
            self._batch = (batch, outputs)

    @rank_zero_only
    def on_validation_epoch_end(self, trainer, module):
        if self._batch is None or trainer.logger is None:
            return
        batch, outputs = self._batch
        writer = trainer.logger.experiment
        for i in range(min(self.samples, len(batch["images"]))):
            stack = batch["images"][i, :4].clamp(0, 1) ** (1 / 2.2)
            writer.add_images(f"samples/{i}/inputs", stack, trainer.global_step)
            sphere = light_sphere(batch["directions"][i].cpu().numpy(),
                                  outputs["directions"][i].detach().cpu().numpy())
            writer.add_image(f"samples/{i}/lights_true_green_predicted_red",
                             torch.as_tensor(sphere), trainer.global_step)
        self._batch = None


class SampleRate(L.Callback):
    """Training samples per second once the run is under way: counted from the end of its first
    ``skip`` steps (data workers starting, the device warming up) to its last step, validations
    left out; on a GPU the clock waits for the device at both ends. ``samples_per_s`` is None
    until a step past ``skip`` has run."""

    def __init__(self, skip: int = 5):
        self.skip = skip
        self._batches = self._samples = 0
        self._start: float | None = None
        self._active = self._paused = 0.0
        self._validation_start: float | None = None

    def on_train_batch_end(self, trainer, module, outputs, batch, batch_idx) -> None:
        self._batches += 1
        first = max(self.skip, 1)                 # the clock starts at the end of this batch
        last = trainer.max_steps > 0 and trainer.global_step >= trainer.max_steps
        if self._batches == first or (last and self._batches > first):
            if module.device.type == "cuda":
                torch.cuda.synchronize(module.device)
        now = time.perf_counter()
        if self._batches == first:
            self._start, self._paused = now, 0.0
        elif self._batches > first:
            self._samples += len(batch["images"])
            self._active = now - self._start - self._paused

    def on_validation_start(self, trainer, module) -> None:
        self._validation_start = time.perf_counter()

    def on_validation_end(self, trainer, module) -> None:
        if self._start is not None and self._validation_start is not None:
            self._paused += time.perf_counter() - self._validation_start

    @property
    def samples_per_s(self) -> float | None:
        return self._samples / self._active if self._samples and self._active > 0 else None

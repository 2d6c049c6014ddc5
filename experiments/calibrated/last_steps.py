"""Would the mean of the normal network's output over the last steps beat the last step's?

    python experiments/calibrated/last_steps.py subject=ball light=gt threads=1 hydra.run.dir=<dir>
    python experiments/calibrated/last_steps.py subject=pot1 light=gt threads=1 hydra.run.dir=<dir>

Runs ``python -m unps.fit`` with the arguments given (a subject with true normals) and a trainer
callback that reads N_o after each of the last steps. Printed at the end, on the working grid
against the true normals there: the error of each of those steps (mean, lowest, highest, last)
and that of the unit mean of N_o over the last 25, 50, 100, 200 and 300 steps. The fit itself,
its read-out and its files are those of the command without the callback.
"""

from __future__ import annotations

import runpy
import sys

import lightning as L
import numpy as np
import torch

WINDOWS = (25, 50, 100, 200, 300)


class LastSteps(L.Callback):
    """Sums N_o (1, 3, h, w) over the last ``WINDOWS`` steps and records each step's error."""

    def __init__(self):
        self.sums: dict[int, torch.Tensor] = {}
        self.errors: list[float] = []

    def on_train_batch_end(self, trainer, module, outputs, batch, batch_idx) -> None:
        left = trainer.max_steps - trainer.global_step          # steps still to run
        if left >= max(WINDOWS) or module.true_normals is None:
            return
        with torch.no_grad():
            normals = module.normals()[0].float()
            self.errors.append(float(module.normal_mae(normals)))
            for window in WINDOWS:
                if left < window:
                    self.sums[window] = self.sums.get(window, 0) + normals

    def on_train_end(self, trainer, module) -> None:
        if not self.errors:
            return
        errors = np.array(self.errors)
        print(f"N_o over the last {len(errors)} steps (working grid): mean {errors.mean():.2f}°, "
              f"lowest {errors.min():.2f}°, highest {errors.max():.2f}°, last {errors[-1]:.2f}°")
        for window, total in sorted(self.sums.items()):
            mean = total / total.norm(dim=1, keepdim=True).clamp_min(1e-12)
            print(f"unit mean of N_o over the last {window:3d} steps: {float(module.normal_mae(mean)):.2f}°")


def with_callback(init):
    def patched(self, *args, **kwargs):
        kwargs["callbacks"] = [*(kwargs.get("callbacks") or []), LastSteps()]
        init(self, *args, **kwargs)
    return patched


if __name__ == "__main__":
    L.Trainer.__init__ = with_callback(L.Trainer.__init__)
    sys.argv = ["unps.fit", *sys.argv[1:]]
    runpy.run_module("unps.fit", run_name="__main__")

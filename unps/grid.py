"""Pixel grids: where a subject's grid lies in its source images, and block averaging.

Images are indexed (row, col) with row 0 at the top.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Frame:
    """Where a subject's pixel grid lies in the images it was read from.

    Subject pixel ``(r, c)`` covers source rows ``top + r*step … top + r*step + step - 1``
    and the matching columns; ``step`` is the downsampling factor.
    """

    source_size: tuple[int, int]
    top: int = 0
    left: int = 0
    step: int = 1

    def source_coords(self, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Centres of subject pixels in source pixel coordinates (row, col), as floats."""
        centre = (self.step - 1) / 2
        return (self.top + np.asarray(rows) * self.step + centre,
                self.left + np.asarray(cols) * self.step + centre)

    def to_dict(self) -> dict:
        return {"source_size": list(self.source_size), "top": self.top, "left": self.left,
                "step": self.step}

    @classmethod
    def from_dict(cls, d: dict) -> Frame:
        return cls(tuple(int(v) for v in d["source_size"]), int(d["top"]), int(d["left"]),
                   int(d["step"]))


def block_mean(values: np.ndarray, mask: np.ndarray, factor: int) -> tuple[np.ndarray, np.ndarray]:
    """Average (H, W, C) values over the object's pixels in factor×factor blocks.

    Blocks with no object pixel get the plain mean. The grid is padded with background to a
    multiple of ``factor``.

    Returns:
        (h, w, C) float64 means and the (h, w) bool mask of blocks at least half on the object.
    """
    weight = _split_blocks(mask.astype(np.float64), factor)                 # (h, w, f*f)
    blocks = _split_blocks(np.asarray(values, np.float64), factor)          # (h, w, C, f*f)
    total = weight.sum(-1)
    on = weight[..., None, :] > 0                      # NaN off the object (e.g. depth) must not leak in
    masked = np.where(on, blocks * weight[..., None, :], 0).sum(-1) / np.maximum(total, 1e-12)[..., None]
    mean = np.where((total > 0)[..., None], masked, blocks.mean(-1))
    return mean, weight.mean(-1) >= 0.5


def _split_blocks(a: np.ndarray, f: int) -> np.ndarray:
    """Split the (H, W) axes of a (H, W) or (H, W, C) array into f×f blocks.

    Returns (h, w, f*f) or (h, w, C, f*f) with h = ceil(H/f), w = ceil(W/f); padding is 0.
    """
    h, w = a.shape[:2]
    ph, pw = -h % f, -w % f
    a = np.pad(a, [(0, ph), (0, pw)] + [(0, 0)] * (a.ndim - 2))
    h2, w2 = a.shape[0] // f, a.shape[1] // f
    a = a.reshape(h2, f, w2, f, *a.shape[2:])
    a = np.moveaxis(a, (1, 3), (-2, -1))
    return a.reshape(*a.shape[:-2], f * f)

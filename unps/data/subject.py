"""One photometric-stereo subject in memory, and the operations that reshape it.

Frame (everywhere in unps): x right, y up, z toward the camera; images are indexed
(row, col) with row 0 at the top, so +x is +col and +y is -row. Light directions point
from the surface to the light.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from unps.data.lights import check_light_directions, check_light_intensities
from unps.errors import InputError
from unps.grid import Frame, block_mean

@dataclass(frozen=True, eq=False)
class Subject:
    """Images of one object under n lights, with whatever is known about them.

    Attributes:
        name: a label for logs and outputs.
        images: (n, H, W, 3) float32 linear RGB, already divided by ``light_intensities``
            when those are known.
        mask: (H, W) bool, True on the object.
        light_directions: (n, 3) float32 unit surface-to-light directions, or None
            (uncalibrated).
        light_intensities: (n, 3) float32 RGB intensities the images were divided by, or None.
        normals: (H, W, 3) float32 ground-truth unit normals, or None.
        depth: (H, W) float32 ground-truth depth along +z in units of this grid's pixel
            pitch, or None.
        filenames: the source file of each image.
        frame: where this grid lies in the source images.
    """

    name: str
    images: np.ndarray
    mask: np.ndarray
    light_directions: np.ndarray | None = None
    light_intensities: np.ndarray | None = None
    normals: np.ndarray | None = None
    depth: np.ndarray | None = None
    filenames: tuple[str, ...] = ()
    frame: Frame | None = field(default=None)

    def __post_init__(self):
        source = f"subject {self.name!r}"
        images = np.asarray(self.images)
        if images.ndim != 4 or images.shape[-1] != 3:
            raise InputError(f"{source}: images must have shape (n, H, W, 3), got {images.shape}")
        n, h, w, _ = images.shape
        if n == 0:
            raise InputError(f"{source}: no images")
        images = images.astype(np.float32, copy=False)
        if not all(np.isfinite(image).all() for image in images):   # image by image: no stack-sized mask
            raise InputError(f"{source}: images contain NaN or Inf")
        self._set("images", images)

        mask = np.asarray(self.mask)
        if mask.shape != (h, w):
            raise InputError(f"{source}: mask has shape {mask.shape}, expected the image size "
                             f"{(h, w)}")
        mask = mask.astype(bool, copy=False)
        if not mask.any():
            raise InputError(f"{source}: mask is empty (no pixel on the object)")
        self._set("mask", mask)

        if self.light_directions is not None:
            self._set("light_directions", check_light_directions(self.light_directions, n, source))
        if self.light_intensities is not None:
            self._set("light_intensities",
                      check_light_intensities(self.light_intensities, n, source))
        if self.normals is not None:
            normals = np.asarray(self.normals, dtype=np.float32)
            if normals.shape != (h, w, 3):
                raise InputError(f"{source}: ground-truth normals have shape {normals.shape}, "
                                 f"expected {(h, w, 3)}")
            if not np.isfinite(normals[mask]).all():
                raise InputError(f"{source}: ground-truth normals contain NaN or Inf in the mask")
            self._set("normals", normals)
        if self.depth is not None:
            depth = np.asarray(self.depth, dtype=np.float32)
            if depth.shape != (h, w):
                raise InputError(f"{source}: ground-truth depth has shape {depth.shape}, "
                                 f"expected {(h, w)}")
            self._set("depth", depth)
        filenames = tuple(self.filenames) or tuple(f"{i + 1:03d}" for i in range(n))
        if len(filenames) != n:
            raise InputError(f"{source}: {len(filenames)} filenames for {n} images")
        self._set("filenames", filenames)
        if self.frame is None:
            self._set("frame", Frame((h, w)))

    def _set(self, name, value):
        object.__setattr__(self, name, value)

    @property
    def n_images(self) -> int:
        return self.images.shape[0]

    @property
    def resolution(self) -> tuple[int, int]:
        """(H, W) of this grid."""
        return self.images.shape[1], self.images.shape[2]

    @property
    def calibrated(self) -> bool:
        return self.light_directions is not None

    def observed_images(self) -> np.ndarray:
        """(n, H, W, 3) float32: the images as captured, before division by intensities."""
        if self.light_intensities is None:
            return self.images
        return self.images * self.light_intensities[:, None, None, :]

    def replace(self, **changes) -> Subject:
        return dataclasses.replace(self, **changes)

    def select(self, indices: Sequence[int]) -> Subject:
        """Keep only the images at ``indices`` (0-based, in this order)."""
        idx = np.asarray(indices, dtype=int)
        return self.replace(images=self.images[idx],
                            light_directions=_index(self.light_directions, idx),
                            light_intensities=_index(self.light_intensities, idx),
                            filenames=tuple(self.filenames[i] for i in idx))

    def crop(self, top: int, left: int, height: int, width: int) -> Subject:
        """The window rows [top, top+height) × cols [left, left+width) of this grid."""
        rows, cols = slice(top, top + height), slice(left, left + width)
        frame = dataclasses.replace(self.frame, top=self.frame.top + top * self.frame.step,
                                    left=self.frame.left + left * self.frame.step)
        return self.replace(images=self.images[:, rows, cols], mask=self.mask[rows, cols],
                            normals=_index(self.normals, (rows, cols)),
                            depth=_index(self.depth, (rows, cols)), frame=frame)

    def crop_to_mask(self, margin: int) -> Subject:
        """Crop to the mask's bounding box grown by ``margin`` pixels (kept inside the image)."""
        if margin < 0:
            raise InputError(f"crop margin must be >= 0 pixels, got {margin}")
        rows, cols = np.nonzero(self.mask)
        h, w = self.resolution
        top, left = max(rows.min() - margin, 0), max(cols.min() - margin, 0)
        bottom, right = min(rows.max() + 1 + margin, h), min(cols.max() + 1 + margin, w)
        return self.crop(int(top), int(left), int(bottom - top), int(right - left))

    def downsample(self, factor: int) -> Subject:
        """Average ``factor``×``factor`` blocks over the object's pixels.

        The grid is padded with background at the bottom/right to a multiple of ``factor``
        (recorded in the frame, nothing is dropped). A block is on the object when at least
        half of its pixels are. Normals are averaged and renormalised; depth is averaged and
        divided by ``factor`` (it is in units of the pixel pitch).
        """
        if int(factor) != factor or factor < 1:
            raise InputError(f"downsample factor must be a whole number >= 1, got {factor}")
        f = int(factor)
        if f == 1:
            return self

        def average(a):  # (H, W, C) -> (h, w, C) float32
            return block_mean(a, self.mask, f)[0].astype(np.float32)

        images = np.stack([average(im) for im in self.images])
        mask = block_mean(self.images[0], self.mask, f)[1]
        normals = depth = None
        if self.normals is not None:
            normals = average(self.normals)
            norm = np.linalg.norm(normals, axis=-1, keepdims=True)
            normals = np.where(norm > 0, normals / np.maximum(norm, 1e-12), 0).astype(np.float32)
        if self.depth is not None:
            depth = average(self.depth[..., None])[..., 0] / f
        frame = dataclasses.replace(self.frame, step=self.frame.step * f)
        return self.replace(images=images, mask=mask, normals=normals, depth=depth, frame=frame)


def _index(a: np.ndarray | None, index) -> np.ndarray | None:
    """``a[index]``, or None for a missing (None) array."""
    return None if a is None else a[index]

"""One photometric-stereo subject in memory, and the operations that reshape it.

Frame (everywhere in unps): x right, y up, z toward the camera; images are indexed
(row, col) with row 0 at the top, so +x is +col and +y is -row. Light directions point
from the surface to the light.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from unps.errors import InputError

log = logging.getLogger(__name__)

UNIT_TOLERANCE = 1e-3


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


def check_light_directions(directions, n_images: int, source: str) -> np.ndarray:
    """Validate light directions and return them as unit float32 vectors.

    Args:
        directions: (n, 3) surface-to-light directions in the unps frame.
        n_images: the number of images they must match.
        source: the file or subject named in error messages.

    Returns:
        (n, 3) float32 unit vectors. Non-unit rows are normalised with a warning.

    Raises:
        InputError: wrong shape, NaN/Inf, or a zero-length direction.
    """
    d = np.asarray(directions, dtype=np.float64)
    if d.ndim == 1 and d.size == 3:
        d = d[None]
    if d.shape != (n_images, 3):
        raise InputError(f"{source}: expected {n_images} light directions of 3 values (one per "
                         f"image), got an array of shape {d.shape}")
    bad = ~np.isfinite(d).all(axis=1)
    if bad.any():
        raise InputError(f"{source}: light direction {int(np.argmax(bad))} is not finite: "
                         f"{d[bad][0].tolist()}")
    norm = np.linalg.norm(d, axis=1)
    if (norm < 1e-8).any():
        raise InputError(f"{source}: light direction {int(np.argmax(norm < 1e-8))} has zero length")
    off = np.abs(norm - 1) > UNIT_TOLERANCE
    if off.any():
        log.warning("%s: %d light directions are not unit length (e.g. row %d, |l| = %.4f); "
                    "normalising them", source, off.sum(), int(np.argmax(off)), norm[off][0])
    return (d / norm[:, None]).astype(np.float32)


def check_light_intensities(intensities, n_images: int, source: str) -> np.ndarray:
    """Validate RGB light intensities: (n, 3), or (n,) shared by RGB; finite and > 0."""
    e = np.asarray(intensities, dtype=np.float64)
    if e.ndim == 1 and e.shape == (n_images,):
        e = np.repeat(e[:, None], 3, axis=1)
    if e.shape != (n_images, 3):
        raise InputError(f"{source}: expected {n_images} light intensities of 3 (RGB) values, "
                         f"got an array of shape {e.shape}")
    bad = ~(np.isfinite(e) & (e > 0)).all(axis=1)
    if bad.any():
        raise InputError(f"{source}: light intensities must be finite and > 0; row "
                         f"{int(np.argmax(bad))} is {e[bad][0].tolist()}")
    return e.astype(np.float32)


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
        if not np.isfinite(images).all():
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

    def gray(self) -> np.ndarray:
        """(n, H, W) float32: mean of the RGB channels."""
        return self.images.mean(axis=-1)

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


def parse_indices(items: Sequence[int | str], n: int, what: str) -> list[int]:
    """Expand ``[0, 3, "5-9"]`` into sorted unique 0-based indices, all in [0, n).

    A string ``"a-b"`` is the inclusive range a…b (so ``"0-19"`` is DiLiGenT bear's first 20).
    """
    out: set[int] = set()
    for item in items or ():
        try:
            if isinstance(item, str) and "-" in item.strip()[1:]:
                a, b = item.split("-", 1)
                lo, hi = int(a), int(b)
                if hi < lo:
                    raise ValueError
                out.update(range(lo, hi + 1))
            else:
                out.add(int(item))
        except ValueError:
            raise InputError(f"{what}: {item!r} is neither an index nor a range 'a-b'") from None
    bad = [i for i in out if not 0 <= i < n]
    if bad:
        raise InputError(f"{what}: index {min(bad)} is outside the {n} images (0 … {n - 1})")
    return sorted(out)


def prepare(subject: Subject, drop: Sequence[int | str] = (), crop_margin: int | None = None,
            downsample: int = 1) -> Subject:
    """Apply the user's reading options in a fixed order: drop images, crop, downsample."""
    if drop:
        dropped = set(parse_indices(drop, subject.n_images, "drop"))
        keep = [i for i in range(subject.n_images) if i not in dropped]
        if not keep:
            raise InputError(f"drop removes all {subject.n_images} images of {subject.name!r}")
        log.info("%s: dropping %d of %d images", subject.name, len(dropped), subject.n_images)
        subject = subject.select(keep)
    if crop_margin is not None:
        subject = subject.crop_to_mask(int(crop_margin))
    return subject.downsample(downsample)


def add_noise(subject: Subject, sigma: float, seed: int) -> tuple[Subject, float]:
    """Add zero-mean Gaussian noise to the captured images (supplementary case study 2).

    The standard deviation is σ times the reference level: the 99th percentile of the observed
    (not intensity-normalised) pixel values on the object, so σ = 0.05 is 5 % of a bright
    pixel whatever the exposure. Nothing is clipped: noisy values may be negative.

    Returns:
        The noisy subject (images divided by the intensities again) and the reference level.
    """
    try:
        sigma = float(sigma)
    except (TypeError, ValueError):
        raise InputError(f"noise must be a number (a standard deviation >= 0), got {sigma!r}") from None
    if not np.isfinite(sigma) or sigma < 0:
        raise InputError(f"noise must be a standard deviation >= 0, got {sigma}")
    observed = subject.observed_images()
    reference = float(np.percentile(observed[:, subject.mask], 99))
    if sigma == 0:
        return subject, reference
    rng = np.random.default_rng(seed)
    noisy = observed + np.float32(sigma * reference) * rng.standard_normal(observed.shape,
                                                                          dtype=np.float32)
    if subject.light_intensities is not None:
        noisy /= subject.light_intensities[:, None, None, :]
    return subject.replace(images=noisy), reference

"""Between the subject's grid and the fit's working grid: crop, block-average, upsample, uncrop.

Grids are (row, col) with row 0 at the top; normals are (…, 3) in the unps frame.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from scipy.ndimage import distance_transform_edt

from unps.data.subject import Subject
from unps.grid import block_mean
from unps.solvers.woodham import rgb_albedo


def working_factor(object_pixels: int, max_pixels: int | None) -> int:
    """The smallest whole factor f with object_pixels / f² ≤ max_pixels (1 when uncapped)."""
    if max_pixels is None or object_pixels <= max_pixels:
        return 1
    return math.ceil(math.sqrt(object_pixels / max_pixels))


def upsample_normals(normals: np.ndarray, mask: np.ndarray, shape: tuple[int, int],
                     factor: int) -> np.ndarray:
    """(h, w, 3) normals of a grid ``factor`` times coarser → (H, W, 3) unit normals.

    Values off the coarse mask are first filled from the nearest object pixel, so the bilinear
    interpolation near the silhouette mixes only object normals.
    """
    up = upsample_map(normals, mask, shape, factor)
    return up / np.maximum(np.linalg.norm(up, axis=-1, keepdims=True), 1e-12)


def upsample_map(values: np.ndarray, mask: np.ndarray, shape: tuple[int, int], factor: int) -> np.ndarray:
    """(h, w, C) values of a grid ``factor`` times coarser → (H, W, C) float32, bilinear, the values
    off the coarse ``mask`` first filled from the nearest object pixel (so that near the silhouette
    only object values mix)."""
    _, (rows, cols) = distance_transform_edt(~mask, return_indices=True)
    filled = values[rows, cols].astype(np.float32)
    size = (mask.shape[1] * factor, mask.shape[0] * factor)
    up = cv2.resize(filled, size, interpolation=cv2.INTER_LINEAR)[: shape[0], : shape[1]]
    return up.reshape(*shape, values.shape[-1])


def unclipped(clipped: np.ndarray, mask: np.ndarray, factor: int) -> np.ndarray | None:
    """(n, h, w) float32 on the working grid (the (H, W) grid of ``mask`` block-averaged by
    ``factor``): 0 where a value holds a clipped pixel, 1 elsewhere; None when no value is clipped.
    Clipped values are darker than the truth, so the fit leaves them out.

    Args:
        clipped: (n, H, W) bool, :func:`unps.data.checks.clipped_values` of the images as captured.
    """
    if not clipped.any():
        return None
    if factor > 1:
        clipped = np.stack([block_mean(c[..., None], mask, factor)[0][..., 0] > 0 for c in clipped])
    return (~clipped).astype(np.float32)


MOSTLY_ZERO = 0.5   # a pixel read as 0 in more of its images than this is of a dark material, not grazed


def black_headroom(observed: np.ndarray, mask: np.ndarray, factor: int, ceiling: float,
                   intensities: np.ndarray | None) -> np.ndarray | None:
    """(n, h, w, 3) float32 on the working grid (the (H, W) grid of ``mask`` block-averaged by
    ``factor``): how much brighter than it reads each value may be, in the units of the images
    divided by their intensities, because it holds pixels read as 0; None when no value is 0.

    A 0 in a quantised stack says only that the light there was below the ``ceiling`` at which
    the stack's first level begins (:func:`unps.data.checks.zero_ceiling`), not that none
    arrived: each value's headroom is the share of its block's pixels that read 0, times that
    ceiling, divided by the image's and the channel's intensity. The pixels read as 0 (every
    channel) in more than :data:`MOSTLY_ZERO` of their images are left as read: they are of a
    dark material, whose zeros say its albedo is below the first level rather than that a light
    grazes it; bounding theirs too took the light benchmark's objects with such a material up to
    1.9° further from the truth (``experiments/calibrated/README.md``, "Values read as 0").

    Args:
        observed: (n, H, W, 3) the images as captured.
        mask: (H, W) bool.
        factor: the working grid's block size.
        ceiling: the light below which a value reads 0, in the units of ``observed``.
        intensities: (n, 3) the lights' RGB intensities the images are divided by; None: 1.
    """
    all_zero = np.zeros(mask.shape, np.int32)                 # image by image: no copy of the stack
    for image in observed:
        all_zero += (image[..., 0] == 0) & (image[..., 1] == 0) & (image[..., 2] == 0)
    bounded = mask & (all_zero <= MOSTLY_ZERO * len(observed))
    per_value = np.full((len(observed), 3), ceiling, np.float32)
    if intensities is not None:
        per_value = per_value / np.asarray(intensities, np.float32)
    headroom, any_zero = [], False
    for image, ceilings in zip(observed, per_value):
        zeros = (image == 0) & bounded[..., None]
        any_zero = any_zero or bool(zeros.any())
        share = zeros if factor == 1 else block_mean(zeros, mask, factor)[0]
        headroom.append(share.astype(np.float32) * ceilings)
    return np.stack(headroom) if any_zero else None


def upsample_with_detail(normals: np.ndarray, coarse_init: np.ndarray, fine_init: np.ndarray,
                         mask: np.ndarray, factor: int) -> np.ndarray:
    """Fitted (h, w, 3) normals on a grid ``factor`` times coarser (object ``mask``) → (H, W, 3)
    unit normals on the fine grid, with the detail the coarse grid cannot hold put back.

    The detail is what the robust initialisation has on the fine grid and loses on the coarse
    one: fine_init − upsampled coarse_init. It is added to the upsampled fit before normalising,
    so the fit decides the shape at its own scale and the initialisation only adds the finer
    scales (on DiLiGenT at ×2 this lowers the MAE by 0.4–0.6° on pot1 and 0.1–0.2° on cat).

    Args:
        normals: (h, w, 3) fitted unit normals.
        coarse_init: (h, w, 3) robust initialisation on the coarse grid.
        fine_init: (H, W, 3) robust initialisation on the fine grid, with H ≤ h·factor, W ≤ w·factor.
        mask: (h, w) bool, the coarse grid's object.

    Returns:
        (H, W, 3) unit normals on the fine grid's object (where fine_init is nonzero); off it the
        values are not normals and the caller masks them (:func:`uncrop` does).
    """
    shape = fine_init.shape[:2]
    detail = fine_init - upsample_normals(coarse_init, mask, shape, factor)
    combined = upsample_normals(normals, mask, shape, factor) + detail
    return combined / np.maximum(np.linalg.norm(combined, axis=-1, keepdims=True), 1e-12)


def on_subject_grid(normals: np.ndarray, cropped: Subject, subject: Subject,
                    light_directions: np.ndarray, light_scales: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(h, w, 3) unit normals on ``cropped``'s grid (a crop of ``subject``) → (H, W, 3) unit
    normals on the subject's grid, and the RGB albedo there by least squares under the lights used
    (directions (n, 3), intensity scales (n,)).
    """
    full_normals = uncrop(normals, cropped, subject)
    pixels = subject.images[:, subject.mask] / light_scales[:, None, None]
    albedo = np.zeros_like(full_normals)
    albedo[subject.mask] = rgb_albedo(pixels, full_normals[subject.mask], light_directions)
    return full_normals, albedo


def uncrop(normals: np.ndarray, cropped: Subject, subject: Subject) -> np.ndarray:
    """(h, w, 3) normals on ``cropped``'s grid (a crop of ``subject``) → (H, W, 3) on the
    subject's, zero off its mask."""
    full = np.zeros(subject.resolution + (3,), np.float32)
    top = cropped.frame.top - subject.frame.top
    left = cropped.frame.left - subject.frame.left
    h, w = cropped.resolution
    full[top: top + h, left: left + w] = normals
    full[~subject.mask] = 0
    return full

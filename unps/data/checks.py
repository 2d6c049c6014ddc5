"""Can a subject be solved? Checks that run before any method does.

A check raises :class:`~unps.errors.InputError` when no method could give an answer (fewer than
3 images, lights that do not span 3D, nothing left between black and clipped values) and logs
a warning when the answer will be worse than the user may expect (few images, nearly coplanar
lights, many clipped or black values). Images that carry nothing (every object pixel black, or
every one clipped) are dropped, each named in a warning. ``python -m unps.fit`` records every
warning in ``metrics.json`` (``warnings``); ``docs/own_photos.md`` says what each means.
"""

from __future__ import annotations

import logging
from contextlib import contextmanager
from typing import Iterator

import numpy as np

from unps.data.subject import Subject
from unps.errors import InputError

log = logging.getLogger(__name__)

MIN_IMAGES = 3          # three lights fix a normal and an albedo (Woodham)
FEW_IMAGES = 6          # below this, shadows and highlights leave pixels with fewer than 3 good values
MAX_CONDITION = 30.0    # σ1/σ3 of the light matrix above which a warning says the lights are nearly coplanar
MIN_SPAN = 1e-3         # σ3/σ1 below which the lights do not span 3D at all
TOP_LEVEL = 1 - 1e-5     # a value this close to its channel's maximum sits at the top level (closer
                         # than one 16-bit level, looser than float32 rounding after dividing by intensities)
FIRST_LEVEL_AT_MOST = 2 / 255     # above an 8-bit file's first level (1/255 read as round, 1.5/255 as floor)
BLACK_LEVELS = 2        # a pixel none of whose values passes this many first levels is black
FAINT_LEVELS = 10       # a pixel none of whose values passes this many first levels …
FAINT_SHARE = 0.5       # … and at most this share of whose images hold more than the first: faintly lit
MIN_CLIPPED_VALUES = 8   # a top level held by this many values is a clipping plateau, not one bright pixel
CLIPPED_WARNING = 0.02  # share of the object's values at the top level that warns
DARK_WARNING = 0.5      # share of the object's values that are exactly 0 that warns


def check_image_count(n: int, source: str) -> None:
    """Error below :data:`MIN_IMAGES`, warning below :data:`FEW_IMAGES`."""
    if n < MIN_IMAGES:
        raise InputError(f"{source}: {n} image{'s' if n != 1 else ''}; photometric stereo needs at least "
                         f"{MIN_IMAGES} images under different lights")
    if n < FEW_IMAGES:
        log.warning("%s: only %d images; with fewer than %d, shadows and highlights leave many pixels "
                    "with too few usable values and the normals are less accurate", source, n, FEW_IMAGES)


def light_condition(directions: np.ndarray) -> float:
    """σ1/σ3 of the (n, 3) light matrix: 1 for lights spread evenly in 3D, ∞ when they do not
    span it.

    Example:
        >>> round(light_condition(np.eye(3)), 3)
        1.0
    """
    s = np.linalg.svd(np.asarray(directions, np.float64), compute_uv=False)
    return float(s[0] / s[2]) if s.size == 3 and s[2] > MIN_SPAN * s[0] else float("inf")


def check_light_span(directions: np.ndarray, source: str, estimated: bool = False) -> float:
    """Error when given lights do not span 3D, warning when they nearly do not; returns σ1/σ3.

    Estimated lights that do not span 3D are the estimator's failure, not the capture's: they
    get a warning that says so, and the run goes on.
    """
    condition = light_condition(directions)
    if not np.isfinite(condition) and estimated:
        log.warning("%s: the estimated lights do not span 3D, so the normals are not determined; the "
                    "estimate failed on this subject — try light=selfcal, light=gt or other weights", source)
        return condition
    if not np.isfinite(condition):
        raise InputError(f"{source}: the light directions do not span 3D (they are identical or lie in "
                         f"one plane through the object), so the normals are not determined; "
                         f"photograph it under lights from at least 3 non-coplanar directions")
    if condition > MAX_CONDITION:
        log.warning("%s: the lights are nearly coplanar (condition number %.0f > %.0f); the normals' "
                    "component along the weakly lit direction is poorly determined", source, condition,
                    MAX_CONDITION)
    return condition


def clipped_values(images: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Where the camera clipped: any channel at its channel's top level over the whole stack,
    when that level is a plateau held by at least :data:`MIN_CLIPPED_VALUES` values. Per channel,
    because white balance after clipping scales each channel's ceiling differently; a maximum
    held by one bright pixel is not clipping.

    Args:
        images: (n, H, W, 3) as captured; mask: (H, W) bool.

    Returns:
        (n, H, W) bool, False off the mask.

    Example:
        >>> images = np.zeros((2, 1, 10, 3)); images[0, 0, :8] = 0.9; images[1, 0, 9] = 0.5
        >>> clipped_values(images, np.ones((1, 10), bool)).astype(int)[:, 0]
        array([[1, 1, 1, 1, 1, 1, 1, 1, 0, 0],
               [0, 0, 0, 0, 0, 0, 0, 0, 0, 0]])
    """
    clipped = np.zeros(images.shape[:3], bool)
    if not mask.any():
        return clipped
    channels = range(images.shape[-1])                         # channel by channel: reductions over
    top = np.zeros(len(channels))                              # the last, 3-long axis are slow
    for values in _object_values(images, mask):
        top = np.maximum(top, [values[:, c].max() for c in channels])
    at_top = np.zeros(len(channels), int)
    for values in _object_values(images, mask):
        at_top += [np.count_nonzero(values[:, c] >= TOP_LEVEL * top[c]) for c in channels]
    plateaus = [c for c in channels if top[c] > 0 and at_top[c] >= MIN_CLIPPED_VALUES]
    if plateaus:
        index = np.flatnonzero(mask)
        for image_clipped, values in zip(clipped, _object_values(images, mask)):
            image_clipped.reshape(-1)[index] = np.logical_or.reduce(
                [values[:, c] >= TOP_LEVEL * top[c] for c in plateaus])
    return clipped


def black_everywhere(images: np.ndarray, mask: np.ndarray, levels: int = BLACK_LEVELS) -> np.ndarray:
    """Object pixels that are black in every image: no value above the stack's ``levels`` lowest
    quantisation levels, in any image or channel. Such a pixel holds no shading, so any normal
    explains it.

    The first level is the smallest positive value over the object (1/255 for 8-bit files, 1.5/255
    for 8-bit files read as ``floor``, far less for 16-bit captures, whose noise fills the lowest
    levels); a stack with no positive value below 2/255 has no quantisation step to go by, and
    nothing in it is called black.

    Args:
        images: (n, H, W, 3) as captured; mask: (H, W) bool.

    Returns:
        (H, W) bool, False off the mask.

    Example:
        >>> images = np.array([[0, 1, 2, 3], [2, 0, 1, 9]], float).reshape(2, 1, 4, 1).repeat(3, -1) / 255
        >>> black_everywhere(images, np.ones((1, 4), bool)).astype(int)
        array([[1, 1, 1, 0]])
    """
    first = first_level(images, mask)
    black = np.zeros(mask.shape, bool)
    if first is not None:
        black[mask] = _peak_and_lit_count(images, mask, first)[0] <= levels * first * (1 + 1e-4)
    return black


def faintly_lit(images: np.ndarray, mask: np.ndarray, levels: int = FAINT_LEVELS,
                share: float = FAINT_SHARE) -> np.ndarray:
    """Object pixels that are not black in every image (:func:`black_everywhere`) but nearly so:
    no value above the stack's ``levels`` lowest quantisation levels, and a value above its first
    level in at most ``share`` of the images. On 8-bit captures of dark glossy materials such
    pixels hold a few specks of light, and the fit's normals there were 30-60° off; a dark diffuse
    material's few levels may still hold its shading, which :func:`unps.inverse.fit.unshaded`
    asks of them before the read-out treats them as black (``experiments/light_benchmark``,
    "Pixels nearly black").

    Args:
        images: (n, H, W, 3) as captured; mask: (H, W) bool.
        levels: the brightest value allowed, in first levels (:func:`first_level`).
        share: in [0, 1], the most images that may hold more than the first level.

    Returns:
        (H, W) bool, False off the mask and on the pixels black in every image; all False for a
        stack with no first level (16-bit captures' noise, float renders).

    Example:
        >>> images = np.zeros((4, 1, 3, 3))
        >>> images[0, 0] = 9 / 255               # one image of four at 9 levels: faint
        >>> images[:3, 0, 1] = 9 / 255           # three of four: lit
        >>> images[0, 0, 2] = 20 / 255           # one, but at 20 levels: lit
        >>> images[1:, 0, :, 0] = 1 / 255        # the first level, which counts for none
        >>> faintly_lit(images, np.ones((1, 3), bool)).astype(int)
        array([[1, 0, 0]])
    """
    first = first_level(images, mask)
    faint = np.zeros(mask.shape, bool)
    if first is not None:
        peak, lit = _peak_and_lit_count(images, mask, first)
        faint[mask] = ((peak > BLACK_LEVELS * first * (1 + 1e-4)) & (peak <= levels * first * (1 + 1e-4))
                       & (lit <= share * len(images)))
    return faint


def _peak_and_lit_count(images: np.ndarray, mask: np.ndarray, first: float) -> tuple[np.ndarray, np.ndarray]:
    """Per object pixel, its brightest value over the images and channels, and the number of
    images in which a channel is above the ``first`` level: (P,) each, in the order of
    ``images[:, mask]``. Image by image, so that no copy of the stack is made."""
    peak = np.zeros(int(mask.sum()), images.dtype)
    lit = np.zeros(int(mask.sum()), np.int32)
    for values in _object_values(images, mask):
        brightest = np.maximum(np.maximum(values[:, 0], values[:, 1]), values[:, 2])  # not .max(-1): slow
        np.maximum(peak, brightest, out=peak)
        lit += brightest > first * (1 + 1e-4)
    return peak, lit


def _object_values(images: np.ndarray, mask: np.ndarray) -> Iterator[np.ndarray]:
    """Each image's (P, 3) values on the object, in the order of ``images[:, mask]``, one image at
    a time, so that no copy of the stack is made (``np.take`` on flat indices: faster than
    indexing by the mask)."""
    index = np.flatnonzero(mask)
    for image in images:
        yield np.take(image.reshape(-1, image.shape[-1]), index, axis=0)


def first_level(images: np.ndarray, mask: np.ndarray) -> float | None:
    """The stack's first quantisation level: its smallest positive value over the object (1/255
    for 8-bit files, 1.5/255 for 8-bit files read as ``floor``, 1/65535 or more for 16-bit), or
    None where there is none or it is above :data:`FIRST_LEVEL_AT_MOST` (no step to go by, as
    in a float stack). A value of 0 stands for light below this level.

    Args:
        images: (n, H, W, 3) as captured; mask: (H, W) bool.

    Example:
        >>> images = np.array([0, 1, 2, 3], float).reshape(1, 1, 4, 1).repeat(3, -1) / 255
        >>> round(first_level(images, np.ones((1, 4), bool)) * 255, 6)
        1.0
    """
    first = min((_smallest_above(values, 0.0) for values in _object_values(images, mask)), default=np.inf)
    return None if not np.isfinite(first) or first > FIRST_LEVEL_AT_MOST else first


def _smallest_above(values: np.ndarray, floor: float) -> float:
    """The smallest of ``values`` above ``floor``; ∞ where none is."""
    above = values[values > floor]
    return float(above.min()) if above.size else np.inf


def zero_ceiling(images: np.ndarray, mask: np.ndarray) -> float | None:
    """The light below which a value of the stack reads 0: its first level (:func:`first_level`)
    less half the step to the next one, which is where the encoder's rounding or truncation
    switches from 0 to the first level (1/255 for 8-bit files read as ``floor``, whose level k > 0
    reads k + ½; ½/255 read as ``round``); None where the stack has no first level.

    Args:
        images: (n, H, W, 3) as captured; mask: (H, W) bool.

    Example:
        >>> floor_read = np.array([0, 1.5, 2.5, 3.5], float).reshape(1, 1, 4, 1).repeat(3, -1) / 255
        >>> round(zero_ceiling(floor_read, np.ones((1, 4), bool)) * 255, 6)
        1.0
        >>> round(zero_ceiling(floor_read - 0.5 / 255 * (floor_read > 0), np.ones((1, 4), bool)) * 255, 6)
        0.5
    """
    first = first_level(images, mask)
    if first is None:
        return None
    past_first = first * (1 + 1e-3)                           # past float rounding of the first level
    second = min((_smallest_above(values, past_first) for values in _object_values(images, mask)),
                 default=np.inf)
    step = min(second - first, first)
    return first - step / 2


def value_levels(images: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per image, the share of object pixels clipped (:func:`clipped_values`) and the share that
    are black (every channel 0).

    Args:
        images: (n, H, W, 3) as captured; mask: (H, W) bool.

    Returns:
        clipped, black: (n,) shares in [0, 1].
    """
    black = np.array([np.logical_and.reduce([values[:, c] <= 0 for c in range(values.shape[-1])]).mean()
                      for values in _object_values(images, mask)])
    if (black == 1).all():
        return np.zeros(len(images)), black
    clipped = clipped_values(images, mask)[:, mask].mean(1)
    return clipped, black


def usable_subject(subject: Subject) -> Subject:
    """The subject without its unusable images, after the checks on counts and values.

    Raises:
        InputError: fewer than 3 images (before or after dropping), or no usable value at all.
    """
    source = f"subject {subject.name!r}"
    check_image_count(subject.n_images, source)
    clipped, black = value_levels(subject.observed_images(), subject.mask)
    if (black == 1).all():
        raise InputError(f"{source}: every image is black on the object; nothing to solve")
    empty = (black == 1) | (clipped == 1)
    for i in np.flatnonzero(empty):
        log.warning("%s: image %s is %s on the whole object and is left out", source,
                    subject.filenames[i], "black" if black[i] == 1 else "clipped")
    if empty.all():
        raise InputError(f"{source}: every image is clipped on the whole object (over-exposed); "
                         f"nothing to solve — capture with a shorter exposure")
    if empty.any():
        subject = subject.select(np.flatnonzero(~empty))
        check_image_count(subject.n_images, f"{source} (after leaving out blank images)")
        clipped, black = clipped[~empty], black[~empty]
    if clipped.mean() > CLIPPED_WARNING:
        worst = int(np.argmax(clipped))
        log.warning("%s: %.0f%% of the object's pixels are clipped at the brightest level (worst: %s, "
                    "%.0f%%); clipped values are darker than the truth: method=unps leaves them out of "
                    "its fit, the other methods use them as they are — capture with a shorter "
                    "exposure where you can", source, 100 * clipped.mean(),
                    subject.filenames[worst], 100 * clipped[worst])
    if black.mean() > DARK_WARNING:
        log.warning("%s: %.0f%% of the object's pixels are black (0 in every channel); the images are "
                    "too dark for reliable normals — capture with a longer exposure", source,
                    100 * black.mean())
    return subject


class _Collect(logging.Handler):
    def __init__(self, messages: list[str]):
        super().__init__(logging.WARNING)
        self.messages = messages

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


@contextmanager
def collected_warnings() -> Iterator[list[str]]:
    """Every warning logged under ``unps`` while open, as messages in a list (for metrics.json)."""
    messages: list[str] = []
    handler = _Collect(messages)
    logger = logging.getLogger("unps")
    logger.addHandler(handler)
    try:
        yield messages
    finally:
        logger.removeHandler(handler)

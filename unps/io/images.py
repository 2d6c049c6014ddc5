"""Reading and writing images with their full bit depth.

PIL, imageio and skimage.io silently truncate 16-bit RGB PNGs to 8 bits; OpenCV reads
them as they are, so every image in unps goes through here. Arrays are RGB (row, col, 3).
"""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from unps.errors import InputError
from unps.io.files import atomic_path

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")
QUANTIZATIONS = ("round", "floor")


def check_quantization(quantization: str) -> str:
    """``quantization`` if it is one of :data:`QUANTIZATIONS`.

    Raises:
        InputError: any other value.
    """
    if quantization not in QUANTIZATIONS:
        raise InputError(f"quantization must be {' or '.join(QUANTIZATIONS)} (or auto for DiLiGenT "
                         f"folders and objects), got {quantization!r}")
    return quantization


def read_image(path: str | os.PathLike, quantization: str = "round") -> np.ndarray:
    """Read an image as (H, W, 3) float32 RGB.

    8- and 16-bit files are scaled by their type's maximum (255 or 65535); float files are
    returned as stored. Gray images are repeated to three channels and an alpha channel is dropped.

    Args:
        quantization: how the file's integers were made from the light, for integer files.
            ``round`` (cameras and encoders): level k stands for k. ``floor`` (images truncated
            from a deeper source, e.g. DiLiGenT's 8-bit crops, ``floor(16-bit / 256)``): level
            k > 0 stands for the interval [k, k + 1) and is read as its middle, k + ½, so values
            reach (max + ½) / max; level 0 stays 0, since on a photometric-stereo subject it is
            mostly shadow. Reading a truncated image as ``round`` darkens every pixel by half a
            level, which matters on dark ones: it steepens the normals
            (``experiments/classical_diligent``).

    Raises:
        InputError: the file is missing or OpenCV cannot decode it, or ``quantization`` is
            unknown.
    """
    check_quantization(quantization)
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: image file not found")
    raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if raw is None:
        raise InputError(f"{path}: not an image OpenCV can read (corrupt or unsupported format)")
    if raw.dtype == np.uint8:
        scale = 255.0
    elif raw.dtype == np.uint16:
        scale = 65535.0
    elif raw.dtype in (np.float32, np.float64):
        scale = 1.0
    else:
        raise InputError(f"{path}: unsupported pixel type {raw.dtype} (expected 8/16-bit or float)")
    if raw.ndim == 2:
        rgb = np.repeat(raw[..., None], 3, axis=-1)
    elif raw.shape[-1] in (3, 4):
        rgb = raw[..., 2::-1]
    else:
        raise InputError(f"{path}: expected a gray, RGB or RGBA image, got {raw.shape[-1]} channels")
    if scale == 1.0:
        return rgb.astype(np.float32)
    levels = rgb.astype(np.float32)
    if quantization == "floor":
        levels[levels > 0] += 0.5
    return levels / np.float32(scale)


def read_mask(path: str | os.PathLike, shape: tuple[int, int]) -> np.ndarray:
    """Read a mask image as (H, W) bool (pixels above half the type's maximum are on)."""
    gray = read_image(path).mean(axis=-1)
    if gray.shape != tuple(shape):
        raise InputError(f"{path}: mask is {gray.shape[1]}×{gray.shape[0]} pixels, but the images "
                         f"are {shape[1]}×{shape[0]}")
    mask = gray > 0.5
    if not mask.any():
        raise InputError(f"{path}: mask is empty (no pixel above half brightness)")
    return mask


def write_png16(path: str | os.PathLike, rgb: np.ndarray) -> None:
    """Write (H, W, 3) values in [0, 1] as a 16-bit RGB PNG (rounded to the nearest level)."""
    rgb = np.asarray(rgb)
    if rgb.min() < 0 or rgb.max() > 1:
        raise ValueError(f"{path}: values must lie in [0, 1] for a 16-bit PNG, got "
                         f"[{rgb.min():.4g}, {rgb.max():.4g}]")
    _write(path, np.round(rgb * 65535.0).astype(np.uint16))


def write_png8(path: str | os.PathLike, rgb: np.ndarray) -> None:
    """Write (H, W, 3) or (H, W) uint8 as a PNG."""
    _write(path, np.asarray(rgb, dtype=np.uint8))


def write_tiff32(path: str | os.PathLike, rgb: np.ndarray) -> None:
    """Write (H, W, 3) float32 RGB as a float TIFF (lossless, any range)."""
    _write(path, np.asarray(rgb, dtype=np.float32))


def _write(path, data: np.ndarray) -> None:
    bgr = data[..., ::-1] if data.ndim == 3 else data
    with atomic_path(path) as tmp:
        if not cv2.imwrite(str(tmp), np.ascontiguousarray(bgr)):
            raise OSError(f"OpenCV could not write {path}")


def srgb_to_linear(v: np.ndarray) -> np.ndarray:
    """Invert the sRGB transfer curve (IEC 61966-2-1) on values in [0, 1]."""
    v = np.asarray(v, dtype=np.float32)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4).astype(np.float32)

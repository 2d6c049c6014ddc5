"""The DiLiGenT folder layout, file by file, read into arrays with errors that name the file.

A folder holds ``filenames.txt`` (one image file per line), the images,
``light_directions.txt`` (n×3, unit, surface to light, x right / y up / z toward the camera),
``light_intensities.txt`` (n×3 RGB), ``mask.png`` and optionally ``Normal_gt.mat``
(key ``Normal_gt``, H×W×3, same frame). unps adds ``Depth_gt.mat`` (key ``Depth_gt``) and
``unps_subject.json`` (name, frame) when it writes a subject.
"""

from __future__ import annotations

import json
import logging
import os
import re
from concurrent.futures import ThreadPoolExecutor
from functools import partial
from pathlib import Path

import numpy as np
import scipy.io

from unps.data.lights import check_light_directions, check_light_intensities
from unps.data.subject import Subject
from unps.errors import InputError
from unps.grid import Frame
from unps.io.images import read_image, read_mask, srgb_to_linear

log = logging.getLogger(__name__)


FILENAMES = "filenames.txt"


DIRECTIONS = "light_directions.txt"


INTENSITIES = "light_intensities.txt"


MASK = "mask.png"


NORMALS = "Normal_gt.mat"


DEPTH = "Depth_gt.mat"


META = "unps_subject.json"


IMAGE_FORMATS = {"png16": ".png", "tiff32": ".tiff"}


def check_root(root) -> Path:
    root = Path(root).expanduser()
    if not root.is_dir():
        raise InputError(f"{root}: not a folder (expected one object's folder of images)")
    return root


def read_filenames(path: Path) -> list[str]:
    if not path.is_file():
        raise InputError(f"{path}: missing (the DiLiGenT layout lists its images there)")
    names = [line.strip() for line in path.read_text().splitlines() if line.strip()]
    if not names:
        raise InputError(f"{path}: lists no images")
    return names


def read_matrix(path: Path, what: str) -> np.ndarray:
    """A text file of whitespace-separated numbers as a 2-D array (``#`` starts a comment)."""
    try:
        return np.loadtxt(path, ndmin=2)
    except ValueError:
        raise InputError(f"{path}: cannot parse {what} as rows of numbers ({first_misfit(path)})") from None


def first_misfit(path: Path) -> str:
    """Where a text file stops being rows of numbers, as a text editor counts (from 1)."""
    widths = set()
    for number, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
        words = line.split("#")[0].split()
        for column, word in enumerate(words, 1):
            try:
                float(word)
            except ValueError:
                return f"line {number}, column {column}: {word!r} is not a number"
        if words and widths and len(words) not in widths:
            return f"line {number} has {len(words)} values, the lines before {widths.pop()}"
        widths.update([len(words)] if words else [])
    return "unreadable"


def read_layout(root: Path, filenames: list[str], mask_file: Path, require_mask: bool,
                 require_lights: bool, encoding: str, quantization: str,
                 name: str | None) -> Subject:
    """Read images, lights, mask and ground truth; every check runs before the images load."""
    paths = [root / f for f in filenames]
    missing = [p for p in paths if not p.is_file()]
    if missing:
        raise InputError(f"{missing[0]}: listed image is missing ({len(missing)} of "
                         f"{len(paths)} listed files are missing)")
    n = len(paths)
    directions = intensities = None
    if (root / DIRECTIONS).is_file():
        directions = check_light_directions(read_matrix(root / DIRECTIONS, "light directions"),
                                            n, str(root / DIRECTIONS))
    elif require_lights:
        raise InputError(f"{root / DIRECTIONS}: missing")
    if (root / INTENSITIES).is_file():
        intensities = check_light_intensities(
            read_matrix(root / INTENSITIES, "light intensities"), n, str(root / INTENSITIES))
    elif require_lights:
        raise InputError(f"{root / INTENSITIES}: missing (images must be divided by them)")
    if require_mask and not mask_file.is_file():
        raise InputError(f"{mask_file}: missing")

    images = None                             # filled image by image: the stack is the only copy
    read = partial(read_image, quantization=quantization)
    with ThreadPoolExecutor(os.cpu_count()) as pool:
        for k, (p, im) in enumerate(zip(paths, pool.map(read, paths))):
            if images is None:
                images = np.empty((len(paths), *im.shape), np.float32)
            size = images.shape[1:]
            if im.shape != size:
                raise InputError(f"{p}: image is {im.shape[1]}×{im.shape[0]}, but {paths[0].name} "
                                 f"is {size[1]}×{size[0]}; all images must have one size")
            if not np.isfinite(im).all():
                row, col = np.argwhere(~np.isfinite(im))[0][:2] + 1
                raise InputError(f"{p}: contains NaN or Inf (first at row {row}, column {col}, "
                                 f"counting from 1)")
            images[k] = srgb_to_linear(im) if encoding == "srgb" else im
    if intensities is not None:
        images /= intensities[:, None, None, :]

    mask = read_mask(mask_file, size[:2]) if mask_file.is_file() else np.ones(size[:2], bool)

    normals = read_mat(root / NORMALS, "Normal_gt", size[:2] + (3,))
    depth = read_mat(root / DEPTH, "Depth_gt", size[:2])
    meta = json.loads((root / META).read_text()) if (root / META).is_file() else {}
    frame = Frame.from_dict(meta["frame"]) if "frame" in meta else None
    name = name or meta.get("name") or root.name.removesuffix("PNG")
    return Subject(name=name, images=images, mask=mask, light_directions=directions,
                   light_intensities=intensities, normals=normals, depth=depth,
                   filenames=tuple(filenames), frame=frame)


def read_mat(path: Path, key: str, shape: tuple[int, ...]) -> np.ndarray | None:
    if not path.is_file():
        return None
    try:
        data = scipy.io.loadmat(path)
    except Exception as e:  # scipy raises several types for a corrupt file
        raise InputError(f"{path}: cannot read the MATLAB file ({e})") from None
    if key not in data:
        found = sorted(k for k in data if not k.startswith("__"))
        raise InputError(f"{path}: has no variable {key!r} (found {found})")
    value = np.asarray(data[key], dtype=np.float32)
    if value.shape != shape:
        raise InputError(f"{path}: {key} has shape {value.shape}, expected {shape} (the image size)")
    return value


def natural_key(name: str):
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]

"""Reading subjects: DiLiGenT objects by name (original 16-bit and 8-bit crops), folders in its
layout (:mod:`unps.data.layout`) and plain folders of images; writing is
:mod:`unps.data.writer`.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from unps.data.automask import auto_mask
from unps.data.layout import FILENAMES, MASK, check_root, natural_key, read_filenames, read_layout
from unps.data.prepare import prepare
from unps.data.subject import Subject
from unps.errors import InputError
from unps.io.images import IMAGE_SUFFIXES, check_quantization

log = logging.getLogger(__name__)


def read_diligent(root: str | os.PathLike, drop: Sequence[int | str] = (),
                  crop_margin: int | None = None, downsample: int = 1,
                  name: str | None = None, quantization: str = "round") -> Subject:
    """Read one object folder in the DiLiGenT layout.

    Images are divided by their RGB light intensities (without this, errors double).

    Args:
        root: the object folder, e.g. ``pmsData/ballPNG``.
        drop: 0-based image indices (or ranges ``"a-b"``) to leave out, e.g. ``["0-19"]``
            for bear's first 20.
        crop_margin: if set, crop to the mask's bounding box grown by this many pixels.
        downsample: block-average by this factor.
        name: the subject's name; defaults to the folder name without ``PNG``.
        quantization: ``round``, or ``floor`` for images truncated from a deeper source, such as
            the 8-bit crops (see :func:`unps.io.images.read_image`); ``auto``: ``floor`` for
            8-bit PNGs in PS-FCN's crop layout (``…/pmsData_crop/<name>PNG``), else ``round``.

    Raises:
        InputError: a required file is missing, unreadable or inconsistent.
    """
    root = check_root(root)
    filenames = read_filenames(root / FILENAMES)
    if quantization == "auto":
        quantization = _layout_quantization(root, filenames)
    check_quantization(quantization)
    subject = read_layout(root, filenames, mask_file=root / MASK, require_mask=True,
                           require_lights=True, encoding="linear", quantization=quantization,
                           name=name)
    return prepare(subject, drop=drop, crop_margin=crop_margin, downsample=downsample)


LAYOUTS = ("pmsData", "pmsData_crop")   # the original release, then PS-FCN's 8-bit crops


def _layout_quantization(root: Path, filenames: Sequence[str]) -> str:
    """``floor`` for 8-bit PNGs in PS-FCN's crop layout, which were made as ⌊16-bit / 256⌋;
    ``round`` otherwise. Logs the choice for the crops."""
    first = root / filenames[0]
    try:
        with open(first, "rb") as f:
            header = f.read(25)
    except OSError:
        return "round"          # the reader names the missing file
    eight_bit = header[:8] == b"\x89PNG\r\n\x1a\n" and len(header) == 25 and header[24] == 8
    if root.parent.name == LAYOUTS[1] and eight_bit:
        log.info("%s: 8-bit PNGs in PS-FCN's crop layout, read as quantization=floor (they were "
                 "made as floor(16-bit / 256); subject.quantization=round reads them as given)", root)
        return "floor"
    return "round"


def find_diligent_object(data_dir: str | os.PathLike, name: str) -> Path:
    """The folder of one DiLiGenT object: ``<data_dir>/pmsData/<name>PNG`` if present, else the
    crop ``<data_dir>/pmsData_crop/<name>PNG``.

    Raises:
        InputError: ``data_dir`` or the object's folder is missing.
    """
    data_dir = Path(data_dir).expanduser()
    if not data_dir.is_dir():
        raise InputError(f"{data_dir}: DiLiGenT not found (expected the folder holding pmsData/); "
                         f"set UNPS_DILIGENT_DIR or paths.diligent_dir")
    for layout in LAYOUTS:
        folder = data_dir / layout / f"{name}PNG"
        if folder.is_dir():
            return folder
    raise InputError(f"{data_dir}: no DiLiGenT object {name!r} (looked for "
                     f"{' and '.join(f'{layout}/{name}PNG' for layout in LAYOUTS)})")


def read_diligent_object(data_dir: str | os.PathLike, object: str, quantization: str = "auto",
                         **options) -> Subject:
    """Read one DiLiGenT object by name (``subject=ball``, ``subject=cat``…); ``options`` are
    :func:`read_diligent`'s. Where only the crop is present it is read, and the log says so.

    ``quantization="auto"`` reads the crops as ``floor`` (PS-FCN made them as
    ``floor(16-bit / 256)``) and the original release as ``round``.
    """
    if quantization != "auto":
        check_quantization(quantization)
    root = find_diligent_object(data_dir, object)
    crop = root.parent.name != LAYOUTS[0]
    if quantization == "auto":
        quantization = "floor" if crop else "round"
    if crop:
        log.info("%s: reading the crop %s (the original release is not in %s), quantization=%s",
                 object, root, Path(data_dir).expanduser(), quantization)
    return read_diligent(root, name=object, quantization=quantization, **options)


def read_folder(root: str | os.PathLike, mask: str = MASK, encoding: str = "auto",
                drop: Sequence[int | str] = (), crop_margin: int | None = None,
                downsample: int = 1, name: str | None = None,
                quantization: str = "round") -> Subject:
    """Read a plain folder of photos of one object; lights, mask and GT are optional.

    Images are those listed in ``filenames.txt`` if present, else every image file in the
    folder in natural name order (the mask and ``Normal_gt*`` excluded). Without
    ``light_directions.txt`` the subject is uncalibrated.

    Args:
        mask: the mask's file name in the folder; ``auto``: found from the images
            (:func:`unps.data.automask.auto_mask`), which is also what a missing ``mask.png``
            gives; ``none``: the whole image is the object.
        encoding: ``linear`` (raw or 16-bit captures), ``srgb`` (camera JPEGs/PNGs, inverted
            to linear), or ``auto``: ``srgb`` for JPEG files, ``linear`` otherwise.
        quantization: ``round`` (cameras), or ``floor`` for images truncated from a deeper
            source (see :func:`unps.io.images.read_image`).
    """
    root = check_root(root)
    if encoding not in ("auto", "linear", "srgb"):
        raise InputError(f"encoding must be auto, linear or srgb, got {encoding!r}")
    check_quantization(quantization)
    if (root / FILENAMES).is_file():
        filenames = read_filenames(root / FILENAMES)
    else:
        skip = {mask.lower(), "normal_gt.png"}
        filenames = sorted((p.name for p in root.iterdir()
                            if p.suffix.lower() in IMAGE_SUFFIXES
                            and p.name.lower() not in skip and not p.name.startswith(".")),
                           key=natural_key)
        if not filenames:
            raise InputError(f"{root}: no image files (.png, .jpg, .tif, .bmp) in this folder")
    if encoding == "auto":
        jpeg = all(Path(f).suffix.lower() in (".jpg", ".jpeg") for f in filenames)
        encoding = "srgb" if jpeg else "linear"
        log.info("%s: treating images as %s (encoding=auto; set subject.encoding to override)",
                 root, encoding)
    if mask not in ("auto", "none") and mask != MASK and not (root / mask).is_file():
        raise InputError(f"{root / mask}: mask file not found (subject.mask names a file in the "
                         f"folder, or is auto or none)")
    subject = read_layout(root, filenames, mask_file=root / mask, require_mask=False,
                           require_lights=False, encoding=encoding, quantization=quantization,
                           name=name)
    if mask == "none":
        log.info("%s: subject.mask=none: the whole image is the object", root)
    elif not (root / mask).is_file():
        subject = subject.replace(mask=found_mask(subject, root, mask))
    return prepare(subject, drop=drop, crop_margin=crop_margin, downsample=downsample)


CONTRAST_WARNING = 2.0   # the object changes with the light less than this many times the
                        # background does: the mask is a guess (DiLiGenT: 5-18; noise: 0.9)


def found_mask(subject: Subject, root: Path, asked: str) -> np.ndarray:
    """The mask :func:`unps.data.automask.auto_mask` finds in the subject's images, logged."""
    found = auto_mask(subject.observed_images())
    why = "subject.mask=auto" if asked == "auto" else f"no {asked} in the folder"
    log.info("%s: %s: the object's mask was found from the images: %d of %d pixels change with "
             "the light (spread above %.3g of the 99th percentile; %.1f× the background's); it is written "
             "as mask.png in the run folder", root, why, found.mask.sum(), found.mask.size,
             found.threshold, found.contrast)
    if found.contrast < CONTRAST_WARNING:
        log.warning("%s: the automatic mask is unsure: what it calls the object changes with the "
                    "light only %.1f× as much as what it calls the background (under %.0f×), so the "
                    "background may change with the light too; check mask.png in the run folder and "
                    "give a mask.png if it is wrong", root, found.contrast, CONTRAST_WARNING)
    if found.at_edge:
        log.warning("%s: the automatic mask reaches the image's edge on %d pixels: a lit surface beside "
                    "the object (a table, a wall) may have joined it, or the object runs off the frame; "
                    "check mask.png in the run folder and give a mask.png if it is wrong (the light "
                    "network reads the object's outline)", root, found.at_edge)
    return found.mask

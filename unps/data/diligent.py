"""The DiLiGenT folder layout: reading (original 16-bit and 8-bit crops) and writing.

A folder holds ``filenames.txt`` (one image file per line), the images,
``light_directions.txt`` (n×3, unit, surface to light, x right / y up / z toward the camera),
``light_intensities.txt`` (n×3 RGB), ``mask.png`` and optionally ``Normal_gt.mat``
(key ``Normal_gt``, H×W×3, same frame). unps adds ``Depth_gt.mat`` (key ``Depth_gt``) and
``unps_subject.json`` (name, frame) when it writes a subject.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import re
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from functools import partial
from pathlib import Path

import numpy as np
import scipy.io

from unps.data.subject import (Frame, Subject, check_light_directions, check_light_intensities,
                               prepare)
from unps.errors import InputError
from unps.io.files import atomic_dir
from unps.io.images import check_quantization, read_image, read_mask, srgb_to_linear, \
    write_png8, write_png16, write_tiff32

log = logging.getLogger(__name__)

FILENAMES = "filenames.txt"
DIRECTIONS = "light_directions.txt"
INTENSITIES = "light_intensities.txt"
MASK = "mask.png"
NORMALS = "Normal_gt.mat"
DEPTH = "Depth_gt.mat"
META = "unps_subject.json"
IMAGE_FORMATS = {"png16": ".png", "tiff32": ".tiff"}


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
    root = _check_root(root)
    filenames = _read_filenames(root / FILENAMES)
    if quantization == "auto":
        quantization = _layout_quantization(root, filenames)
    check_quantization(quantization)
    subject = _read_layout(root, filenames, mask_file=root / MASK, require_mask=True,
                           require_lights=True, encoding="linear", quantization=quantization,
                           name=name)
    return prepare(subject, drop=drop, crop_margin=crop_margin, downsample=downsample)


OBJECTS = ("ball", "bear", "buddha", "cat", "cow", "goblet", "harvest", "pot1", "pot2", "reading")
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
    ``light_directions.txt`` the subject is uncalibrated. Without a mask file the whole
    image is the object.

    Args:
        encoding: ``linear`` (raw or 16-bit captures), ``srgb`` (camera JPEGs/PNGs, inverted
            to linear), or ``auto``: ``srgb`` for JPEG files, ``linear`` otherwise.
        quantization: ``round`` (cameras), or ``floor`` for images truncated from a deeper
            source (see :func:`unps.io.images.read_image`).
    """
    root = _check_root(root)
    if encoding not in ("auto", "linear", "srgb"):
        raise InputError(f"encoding must be auto, linear or srgb, got {encoding!r}")
    check_quantization(quantization)
    if (root / FILENAMES).is_file():
        filenames = _read_filenames(root / FILENAMES)
    else:
        skip = {mask.lower(), "normal_gt.png"}
        filenames = sorted((p.name for p in root.iterdir()
                            if p.suffix.lower() in (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")
                            and p.name.lower() not in skip and not p.name.startswith(".")),
                           key=_natural_key)
        if not filenames:
            raise InputError(f"{root}: no image files (.png, .jpg, .tif, .bmp) in this folder")
    if encoding == "auto":
        jpeg = all(Path(f).suffix.lower() in (".jpg", ".jpeg") for f in filenames)
        encoding = "srgb" if jpeg else "linear"
        log.info("%s: treating images as %s (encoding=auto; set subject.encoding to override)",
                 root, encoding)
    subject = _read_layout(root, filenames, mask_file=root / mask, require_mask=False,
                           require_lights=False, encoding=encoding, quantization=quantization,
                           name=name)
    return prepare(subject, drop=drop, crop_margin=crop_margin, downsample=downsample)


def write_diligent(subject: Subject, root: str | os.PathLike, image_format: str = "png16",
                   overwrite: bool = False, metadata: dict | None = None) -> Path:
    """Write a subject in the DiLiGenT layout, atomically (the folder appears complete or not at all).

    ``png16`` stores the observed images (images × intensities) as 16-bit PNGs. If they
    exceed 1, they are divided by their maximum s and the intensities too, so that
    reading back gives the same images with nothing clipped; s is recorded in
    ``unps_subject.json``. Values are rounded to the nearest of 65536 levels, so a subject
    read from 16-bit PNGs round-trips bit for bit. ``tiff32`` stores float32 TIFFs of any
    range (to float32 rounding of the intensity product).

    ``unps_subject.json`` also lists every file's SHA-256 (see :func:`verify_files`) and any
    ``metadata`` given.

    Returns:
        The folder written.
    """
    if image_format not in IMAGE_FORMATS:
        raise InputError(f"image_format must be one of {sorted(IMAGE_FORMATS)}, got "
                         f"{image_format!r}")
    suffix = IMAGE_FORMATS[image_format]
    observed = subject.observed_images()
    intensities = subject.light_intensities
    scale = 1.0
    if image_format == "png16":
        if observed.min() < 0:
            raise InputError(f"subject {subject.name!r}: images have negative values "
                             f"({observed.min():.4g}); use image_format=tiff32")
        peak = float(observed.max())
        if peak > 1 + 1e-6:
            scale = peak
            if intensities is None:
                intensities = np.ones((subject.n_images, 3), np.float32)
            intensities = (intensities / np.float32(scale)).astype(np.float32)
            observed = observed / np.float32(scale)
        observed = np.minimum(observed, 1.0)  # only float32 rounding lies above 1 here
    writer = write_png16 if image_format == "png16" else write_tiff32
    names = [f"{i + 1:03d}{suffix}" for i in range(subject.n_images)]
    with atomic_dir(root, overwrite=overwrite) as tmp:
        (tmp / FILENAMES).write_text("\n".join(names) + "\n")
        with ThreadPoolExecutor(os.cpu_count()) as pool:
            list(pool.map(lambda i: writer(tmp / names[i], observed[i]), range(subject.n_images)))
        if subject.light_directions is not None:
            np.savetxt(tmp / DIRECTIONS, subject.light_directions, fmt="%.9g")
        if intensities is not None:
            np.savetxt(tmp / INTENSITIES, intensities, fmt="%.9g")
        write_png8(tmp / MASK, np.repeat(subject.mask[..., None], 3, -1) * np.uint8(255))
        if subject.normals is not None:
            scipy.io.savemat(tmp / NORMALS, {"Normal_gt": subject.normals})
            write_png8(tmp / "Normal_gt.png",
                       np.round((subject.normals + 1) * 127.5 * subject.mask[..., None]))
        if subject.depth is not None:
            scipy.io.savemat(tmp / DEPTH, {"Depth_gt": subject.depth})
        meta = {**(metadata or {}), "name": subject.name, "frame": subject.frame.to_dict(),
                "image_format": image_format, "image_scale": scale,
                "source_filenames": list(subject.filenames),
                "files": {p.name: _sha256(p) for p in sorted(tmp.iterdir())}}
        (tmp / META).write_text(json.dumps(meta, indent=2) + "\n")
    return Path(root)


def verify_files(root: str | os.PathLike) -> dict:
    """Check a folder written by :func:`write_diligent` against its file list and checksums.

    Returns:
        Its ``unps_subject.json`` contents.

    Raises:
        InputError: the metadata is missing or unreadable, or a file is missing or altered.
    """
    root = Path(root)
    try:
        meta = json.loads((root / META).read_text())
        files = meta["files"]
    except (OSError, ValueError, KeyError) as e:
        raise InputError(f"{root / META}: missing or unreadable ({e})") from None
    for name, digest in files.items():
        if not (root / name).is_file():
            raise InputError(f"{root / name}: missing")
        if _sha256(root / name) != digest:
            raise InputError(f"{root / name}: contents differ from when it was written")
    return meta


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _check_root(root) -> Path:
    root = Path(root).expanduser()
    if not root.is_dir():
        raise InputError(f"{root}: not a folder (expected one object's folder of images)")
    return root


def _read_filenames(path: Path) -> list[str]:
    if not path.is_file():
        raise InputError(f"{path}: missing (the DiLiGenT layout lists its images there)")
    names = [line.strip() for line in path.read_text().splitlines() if line.strip()]
    if not names:
        raise InputError(f"{path}: lists no images")
    return names


def _read_matrix(path: Path, what: str) -> np.ndarray:
    try:
        return np.loadtxt(path, ndmin=2)
    except ValueError as e:
        raise InputError(f"{path}: cannot parse {what} as rows of numbers ({e})") from None


def _read_layout(root: Path, filenames: list[str], mask_file: Path, require_mask: bool,
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
        directions = check_light_directions(_read_matrix(root / DIRECTIONS, "light directions"),
                                            n, str(root / DIRECTIONS))
    elif require_lights:
        raise InputError(f"{root / DIRECTIONS}: missing")
    if (root / INTENSITIES).is_file():
        intensities = check_light_intensities(
            _read_matrix(root / INTENSITIES, "light intensities"), n, str(root / INTENSITIES))
    elif require_lights:
        raise InputError(f"{root / INTENSITIES}: missing (images must be divided by them)")
    if require_mask and not mask_file.is_file():
        raise InputError(f"{mask_file}: missing")

    with ThreadPoolExecutor(os.cpu_count()) as pool:
        images = list(pool.map(partial(read_image, quantization=quantization), paths))
    size = images[0].shape
    for p, im in zip(paths, images):
        if im.shape != size:
            raise InputError(f"{p}: image is {im.shape[1]}×{im.shape[0]}, but {paths[0].name} "
                             f"is {size[1]}×{size[0]}; all images must have one size")
        if not np.isfinite(im).all():
            row, col = np.argwhere(~np.isfinite(im))[0][:2] + 1
            raise InputError(f"{p}: contains NaN or Inf (first at row {row}, column {col}, "
                             f"counting from 1)")
    images = np.stack(images)
    if encoding == "srgb":
        images = srgb_to_linear(images)
    if intensities is not None:
        images /= intensities[:, None, None, :]

    if mask_file.is_file():
        mask = read_mask(mask_file, size[:2])
    else:
        log.warning("%s: no mask file %s; using the whole image as the object", root,
                    mask_file.name)
        mask = np.ones(size[:2], bool)

    normals = _read_mat(root / NORMALS, "Normal_gt", size[:2] + (3,))
    depth = _read_mat(root / DEPTH, "Depth_gt", size[:2])
    meta = json.loads((root / META).read_text()) if (root / META).is_file() else {}
    frame = Frame.from_dict(meta["frame"]) if "frame" in meta else None
    name = name or meta.get("name") or root.name.removesuffix("PNG")
    return Subject(name=name, images=images, mask=mask, light_directions=directions,
                   light_intensities=intensities, normals=normals, depth=depth,
                   filenames=tuple(filenames), frame=frame)


def _read_mat(path: Path, key: str, shape: tuple[int, ...]) -> np.ndarray | None:
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


def _natural_key(name: str):
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]

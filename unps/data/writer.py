"""Writing a subject in the DiLiGenT layout (:mod:`unps.data.layout`), and checking it later."""

from __future__ import annotations

import hashlib
import json
import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import scipy.io

from unps.data.layout import DEPTH, DIRECTIONS, FILENAMES, IMAGE_FORMATS, INTENSITIES, MASK, META, NORMALS
from unps.data.subject import Subject
from unps.errors import InputError
from unps.io.files import atomic_dir
from unps.io.images import write_png8, write_png16, write_tiff32


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

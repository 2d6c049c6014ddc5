"""Synthetic benchmark subjects: rendered on first use, then read from a cache.

A subject's config (``conf/subject/<Name>.yaml``) names its shape builder, material,
texture, light dome and render settings. The cache entry is a DiLiGenT-layout folder
``<cache_dir>/<Name>-<hash>``, where the hash covers every setting that changes the images;
it is written atomically with a checksum of each file, and an entry that fails its checks is
rendered again, never used.
"""

from __future__ import annotations

import hashlib
import json
import logging
import time
from collections.abc import Sequence
from pathlib import Path

from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from unps.data.diligent import read_diligent
from unps.data.writer import verify_files, write_diligent
from unps.data.prepare import prepare
from unps.data.subject import Subject
from unps.errors import InputError
from unps.synthetic.render import light_dome, render_subject

log = logging.getLogger(__name__)

RENDERER_VERSION = 2   # bump when a change to the renderer or shapes alters the images


def _plain(node):
    return OmegaConf.to_container(node, resolve=True) if isinstance(node, DictConfig) else node


def render_key(shape: dict, material: dict, texture: dict | None, lights: dict, render: dict) -> str:
    """A short hash of everything that determines the rendered images."""
    spec = {"shape": shape, "material": material, "texture": texture, "lights": lights,
            "render": render, "version": RENDERER_VERSION}
    return hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()[:12]


def cached_render(name: str, shape, material, texture, lights, render, cache_dir: str,
                  force: bool = False, progress: bool = True) -> Path:
    """Render the subject into the cache unless a valid entry exists; return the entry's folder."""
    shape, material, texture, lights, render = map(_plain, (shape, material, texture, lights, render))
    key = render_key(shape, material, texture, lights, render)
    entry = Path(cache_dir).expanduser() / f"{name}-{key}"
    if entry.exists() and not force:
        try:
            if verify_files(entry).get("render_key") == key:
                return entry
            reason = "it was made with other settings"
        except InputError as e:
            reason = str(e)
        log.warning("cache entry %s is incomplete or corrupt (%s); rendering it again", entry, reason)
    start = time.perf_counter()
    mesh = instantiate(shape)
    directions, intensities = light_dome(**lights)
    subject = render_subject(name, mesh, material, texture, directions, intensities,
                             progress=progress, **render)
    seconds = time.perf_counter() - start
    write_diligent(subject, entry, overwrite=True,
                   metadata={"render_key": key, "render_seconds": seconds,
                             "config": {"shape": shape, "material": material, "texture": texture,
                                        "lights": lights, "render": render}})
    log.info("rendered %s: %d images at %d×%d in %.0f s, cached in %s", name, len(directions),
             render["resolution"], render["resolution"], seconds, entry)
    return entry


def load_synthetic(name: str, shape, material, texture=None, lights=None, render=None,
                   cache_dir: str = "~/.cache/unps", drop: Sequence[int | str] = (),
                   crop_margin: int | None = None, downsample: int = 1, force: bool = False,
                   progress: bool = True) -> Subject:
    """A synthetic subject: rendered on first use (with a progress bar), cached after.

    Args:
        name: the subject's name (``Face``, ``Vase``, …).
        shape: a Hydra node whose ``_target_`` builds the mesh (see ``unps.synthetic.shapes``).
        material: a Mitsuba BSDF spec; texture: optional albedo texture spec.
        lights: arguments of :func:`unps.synthetic.render.light_dome`.
        render: arguments of :func:`unps.synthetic.render.render_subject`.
        cache_dir: where rendered subjects are kept.
        drop, crop_margin, downsample: reading options, as for real data.
        force: render again even if a valid cache entry exists.
    """
    if lights is None or render is None:
        raise InputError(f"synthetic subject {name!r} needs both 'lights' and 'render' settings")
    entry = cached_render(name, shape, material, texture, lights, render, cache_dir, force,
                          progress)
    return prepare(read_diligent(entry), drop=drop, crop_margin=crop_margin, downsample=downsample)

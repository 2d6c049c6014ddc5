"""``python -m unps.render subject=<Name>``: render a synthetic subject into the cache.

    python -m unps.render subject=Vase
    python -m unps.render -m subject=Vase,Golf-ball,Face,Tablet1,Tablet2,BrokenPot,Rose,Sphere
    python -m unps.render subject=Face render_force=true subject.render.resolution=256

The subject is stored in the DiLiGenT layout (16-bit PNGs, GT lights, normals, depth) under
``paths.cache_dir``; ``unps.fit`` reuses it. The run folder gets ``preview.png``.
"""

from __future__ import annotations

import logging
from pathlib import Path

import hydra
from hydra.utils import instantiate
from omegaconf import DictConfig

from unps.data.subject import Subject
from unps.cli import command_line
from unps.errors import InputError, exit_on_bad_input
from unps.io.images import write_png8
from unps.io.pictures import image_strip

log = logging.getLogger("unps.render")


def render(cfg: DictConfig) -> Subject:
    if "load_synthetic" not in str(cfg.subject.get("_target_", "")):
        raise InputError("unps.render renders synthetic subjects only: choose subject= one of "
                         "Vase, Golf-ball, Face, Tablet1, Tablet2, BrokenPot, Rose, Sphere")
    subject = instantiate(cfg.subject, _partial_=True)(force=cfg.render_force)
    write_png8(Path(cfg.paths.output_dir) / "preview.png",
               image_strip(subject.observed_images(), subject.mask, subject.normals))
    return subject


@command_line
@hydra.main(version_base="1.3", config_path="pkg://unps.conf", config_name="render")
@exit_on_bad_input
def main(cfg: DictConfig) -> None:
    render(cfg)


if __name__ == "__main__":
    main()

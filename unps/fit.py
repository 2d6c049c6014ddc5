"""``python -m unps.fit``: normals, depth and albedo of one subject.

    python -m unps.fit                                  # Face, rendered on first use; method=unps
    python -m unps.fit subject=Vase noise=0.1 light=gt preset=paper
    python -m unps.fit subject=Vase method=woodham light=gt
    python -m unps.fit subject=diligent subject.root=…/pmsData/ballPNG method=woodham
    python -m unps.fit subject=folder subject.root=~/captures/mug
    python -m unps.fit -m method=woodham,rpca subject=diligent subject.root=…

Outputs land in Hydra's run folder (``hydra.run.dir=…`` moves it); see
:func:`unps.pipeline.outputs.write_fit_outputs`.
"""

from __future__ import annotations

import logging

import hydra
from omegaconf import DictConfig

from unps.cli import command_line
from unps.errors import exit_on_bad_input
from unps.pipeline import fit

__all__ = ["fit", "main"]


@command_line
@hydra.main(version_base="1.3", config_path="pkg://unps.conf", config_name="fit")
@exit_on_bad_input
def main(cfg: DictConfig) -> None:
    import lightning.pytorch   # noqa: F401  (it sets its own logger to INFO when imported)

    logging.getLogger("lightning.pytorch").setLevel(logging.WARNING)   # no accelerator lines, no adverts
    fit(cfg)


if __name__ == "__main__":
    main()

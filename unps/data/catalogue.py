"""The subjects unps knows by name, read from its subject configs (``unps/conf/subject/``).

Adding ``unps/conf/subject/<Name>.yaml`` on ``/synthetic/base`` or ``/diligent/base`` adds the
subject to every list built from here: the studies' reports, the benchmarks and the tests.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

from omegaconf import OmegaConf

from unps.paper import PAPER_MAE

SUBJECT_CONFIGS = Path(__file__).resolve().parents[1] / "conf" / "subject"


@cache
def subjects(base: str) -> tuple[str, ...]:
    """Names of the subject configs built on ``/<base>/base`` (``synthetic`` or ``diligent``).

    Rendered subjects come in the order of the paper's Table 1, then the others by name; DiLiGenT
    objects by name.

    >>> subjects("synthetic")[:3], subjects("diligent")[:2]
    (('Vase', 'Golf-ball', 'Face'), ('ball', 'bear'))
    """
    names = [path.stem for path in SUBJECT_CONFIGS.glob("*.yaml")
             if f"/{base}/base@_here_" in OmegaConf.load(path).get("defaults", [])]
    table = list(PAPER_MAE["gt"])
    return tuple(sorted(names, key=lambda name: (table.index(name) if name in table else len(table),
                                                 name)))

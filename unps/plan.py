"""``python -m unps.plan <overrides>``: a dry run of a sweep: the jobs it would launch, where
each would write, and on which launcher, without running any.

    python -m unps.plan experiment=table1
    python -m unps.plan experiment=noise hydra/launcher=slurm hydra.launcher.partition=gpu
    python -m unps.plan subject=Vase,Face noise=0,0.1 method=woodham

The jobs are the ones ``python -m unps.fit -m <the same overrides>`` launches: Hydra's basic
sweeper takes the product of the experiment's ``hydra.sweeper.params`` and the command line's
values (the command line wins on a shared key). Every job's config is composed, so an override
that does not compose fails here, before a cluster allocation is spent on it.
"""

from __future__ import annotations

import argparse
import itertools
import logging
from collections import OrderedDict
from collections.abc import Sequence
from pathlib import Path

from hydra import compose, initialize_config_module
from hydra.core.override_parser.overrides_parser import OverridesParser
from omegaconf import DictConfig, OmegaConf

from unps.errors import InputError, exit_on_bad_input

LAUNCHER_KEYS = ("partition", "timeout_min", "nodes", "gpus_per_node", "cpus_per_task", "mem_gb",
                 "n_jobs")


def is_hydra_override(key: str) -> bool:
    return key == "hydra" or key.startswith(("hydra.", "hydra/"))


def expand(sweep_params: dict[str, str], overrides: Sequence[str]) -> list[list[str]]:
    """Each job's overrides: the product of every key's values, in Hydra's basic sweeper's order
    (the config's sweep params first; a command-line override replaces one of the same key).

    Args:
        sweep_params: ``hydra.sweeper.params``, e.g. ``{"subject": "Vase,Face"}``.
        overrides: the command line's overrides, sweeps (``a=1,2``) or not.
    """
    parser = OverridesParser.create()
    choices: OrderedDict[str, list[str]] = OrderedDict()
    for override in parser.parse_overrides([f"{k}={v}" for k, v in sweep_params.items()] + list(overrides)):
        key = override.get_key_element()
        if override.is_sweep_override():
            if not override.is_discrete_sweep():
                raise InputError(f"{override.input_line}: only lists of values (a=1,2,3) can be swept, "
                                 f"as Hydra's basic sweeper does")
            choices[key] = [f"{key}={value}" for value in override.sweep_string_iterator()]
        else:
            choices[key] = [f"{key}={override.get_value_element_as_str()}"]
    return [list(job) for job in itertools.product(*choices.values())]


def override_dirname(job: Sequence[str], exclude_keys: Sequence[str]) -> str:
    """The job's sub-folder name as Hydra's ``hydra.job.override_dirname`` writes it: its task
    overrides, sorted, without the excluded keys, joined by commas."""
    parser = OverridesParser.create()
    lines = sorted(o.input_line for o in parser.parse_overrides(list(job))
                   if o.key_or_group not in exclude_keys and not is_hydra_override(o.key_or_group))
    return ",".join(lines)


def plan(overrides: Sequence[str], config_name: str = "fit"
         ) -> tuple[DictConfig, list[tuple[list[str], Path]]]:
    """The launcher config and the (overrides, run folder) of each job of the sweep.

    Raises:
        InputError: a job's config does not compose.
    """
    parser = OverridesParser.create()
    fixed = [o.input_line for o in parser.parse_overrides(list(overrides)) if not o.is_sweep_override()]
    with initialize_config_module(config_module="unps.conf", version_base="1.3"):
        base = compose(config_name, overrides=fixed, return_hydra_config=True)
        params = base.hydra.sweeper.params
        jobs = expand(OmegaConf.to_container(params) if params else {}, overrides)
        hydra_cfg = base.hydra
        exclude = list(hydra_cfg.job.config.override_dirname.exclude_keys)
        planned = []
        for job in jobs:
            try:
                compose(config_name, overrides=job, return_hydra_config=True)
            except Exception as error:   # Hydra's own errors name the override that failed
                raise InputError(f"job {' '.join(job)} does not compose: {error}") from error
            planned.append((job, Path(hydra_cfg.sweep.dir) / override_dirname(job, exclude)))
    return hydra_cfg, planned


@exit_on_bad_input
def print_plan(overrides: Sequence[str]) -> None:
    hydra_cfg, jobs = plan(overrides)
    launcher = hydra_cfg.launcher
    settings = ", ".join(f"{k}={launcher[k]}" for k in LAUNCHER_KEYS if k in launcher)
    print(f"dry run: {len(jobs)} jobs, launcher {launcher._target_.rsplit('.', 1)[-1]}"
          + (f" ({settings})" if settings else "") + f", sweep folder {hydra_cfg.sweep.dir}")
    width = len(str(len(jobs)))
    for number, (job, folder) in enumerate(jobs):
        task = [o for o in job if not is_hydra_override(o.split("=")[0])]
        print(f"#{number:<{width}} {' '.join(task)}  →  {folder}")
    print(f"run them with: python -m unps.fit -m {' '.join(overrides)}")


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description="Dry run of a sweep of python -m unps.fit.")
    parser.add_argument("overrides", nargs="*", help="as for python -m unps.fit -m")
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    print_plan(parser.parse_args(argv).overrides)


if __name__ == "__main__":
    main()

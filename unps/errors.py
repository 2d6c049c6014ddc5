"""The one exception users see for bad input, and how the command-line entry points report it."""

import functools
import logging
import sys


class InputError(ValueError):
    """Bad input: the message names the file or value and what was expected.

    Raised before any work starts, so nothing is left half-written. The command-line
    entry points print the message without a traceback and exit with status 2.
    """


class Diverged(RuntimeError):
    """An optimisation stopped being finite. The message says where the last good state is;
    the command-line entry points print it without a traceback and exit with status 3."""


class Interrupted(KeyboardInterrupt):
    """Ctrl-C during a long stage. The message says where the run stopped and how to go on;
    :func:`unps.cli.command_line` prints it and exits with status 130."""


def exit_on_bad_input(task):
    """Wrap a ``task(cfg)`` entry point: bad input is logged in one line and exits with status 2,
    a diverged optimisation likewise with status 3. A run folder that holds nothing but what
    Hydra wrote into it before the task started (``.hydra/`` and the log) is removed on bad
    input: nothing of the run is left half-written."""
    from hydra.errors import InstantiationException
    from omegaconf.errors import MissingMandatoryValue

    @functools.wraps(task)
    def run(cfg):
        try:
            return task(cfg)
        except (InputError, MissingMandatoryValue) as e:
            logging.getLogger(task.__module__).error("%s", e)
            discard_unused_run_folder(cfg)
            sys.exit(2)
        except InstantiationException as e:         # a config node's class refused its values
            if not isinstance(e.__cause__, InputError):
                raise
            logging.getLogger(task.__module__).error("%s", e.__cause__)
            discard_unused_run_folder(cfg)
            sys.exit(2)
        except Diverged as e:
            logging.getLogger(task.__module__).error("%s", e)
            sys.exit(3)

    return run


HYDRA_FILES = {".hydra"}      # and the task's log, ``<task>.log``


def discard_unused_run_folder(cfg) -> None:
    """Remove the run folder of ``cfg`` (``paths.output_dir``) if it holds only Hydra's own
    files: the configuration in ``.hydra/`` and a ``.log`` file."""
    import shutil
    from pathlib import Path

    try:
        folder = Path(cfg.paths.output_dir)
    except (AttributeError, KeyError, TypeError, ValueError):
        return                          # not a Hydra task (plan, report), or no run folder
    if not folder.is_dir():
        return
    if all(p.name in HYDRA_FILES or (p.suffix == ".log" and p.is_file()) for p in folder.iterdir()):
        shutil.rmtree(folder, ignore_errors=True)

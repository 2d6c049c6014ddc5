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


def exit_on_bad_input(task):
    """Wrap a ``task(cfg)`` entry point: bad input is logged in one line and exits with status 2,
    a diverged optimisation likewise with status 3."""
    from omegaconf.errors import MissingMandatoryValue

    @functools.wraps(task)
    def run(cfg):
        try:
            return task(cfg)
        except (InputError, MissingMandatoryValue) as e:
            logging.getLogger(task.__module__).error("%s", e)
            sys.exit(2)
        except Diverged as e:
            logging.getLogger(task.__module__).error("%s", e)
            sys.exit(3)

    return run

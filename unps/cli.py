"""What every entry point does around Hydra: paths as users type them, one line and exit status 2
for every error in the command line, and a Ctrl-C that says how to go on.

    @command_line
    @hydra.main(version_base="1.3", config_path="pkg://unps.conf", config_name="fit")
    @exit_on_bad_input
    def main(cfg): ...
"""

from __future__ import annotations

import functools
import os
import re
import sys
from collections.abc import Callable
from pathlib import Path

INTERRUPTED = 130    # 128 + SIGINT, as shells report a command stopped by Ctrl-C

_HOME = re.compile(r"^([\w.+\-/@]+=)(~[\w.\-]*)(?=/|$)")


def expand_home(argument: str) -> str:
    """``key=~/path`` with the home folder written out: bash leaves a ``~`` after ``=`` alone, and
    Hydra's grammar does not accept it. Anything else is returned as it is.

    >>> expand_home("subject.root=~/captures/mug") == "subject.root=" + os.path.expanduser("~/captures/mug")
    True
    >>> expand_home("light=gt"), expand_home("subject.root='~/mug'")
    ('light=gt', "subject.root='~/mug'")
    """
    match = _HOME.match(argument)
    if not match:
        return argument
    return match.group(1) + os.path.expanduser(match.group(2)) + argument[match.end():]


def one_line(error: BaseException) -> str:
    r"""An exception's message on one line: Hydra's span several (the options, where it looked).

    >>> one_line(ValueError("Could not find 'preset/x'\n\nAvailable options in 'preset':\n\tfast\n"
    ...                     "\tpaper\nConfig search path:\n\tprovider=hydra"))
    "Could not find 'preset/x' Available options in 'preset': fast paper"
    """
    text = str(error).split("Config search path")[0]
    return " ".join(line.strip() for line in text.splitlines() if line.strip())


def command_line(hydra_main: Callable[[], None]) -> Callable[[], None]:
    """Wrap an entry point made by ``hydra.main`` (see the module's example).

    Before Hydra reads the command line, ``key=~/…`` is expanded (:func:`expand_home`). Errors in
    the command line (an unknown option or key, a value Hydra cannot parse) and a run folder that
    cannot be made or written print one line and exit with status 2; Ctrl-C prints where the run
    stopped and how to resume, and exits with status 130. Errors of the task itself are the
    task's own (:func:`unps.errors.exit_on_bad_input`).
    """
    from hydra.errors import HydraException, InstantiationException
    from omegaconf.errors import OmegaConfBaseException

    @functools.wraps(hydra_main)
    def run() -> None:
        sys.argv[1:] = [expand_home(argument) for argument in sys.argv[1:]]
        os.environ.setdefault("HYDRA_FULL_ERROR", "1")     # its errors reach us, not its printer
        program = f"python -m unps.{Path(sys.argv[0]).stem}"
        try:
            hydra_main()
        except InstantiationException:      # raised by the task, not the command line
            raise
        except (HydraException, OmegaConfBaseException) as e:
            culprit = f"{e.override}: " if getattr(e, "override", None) else ""   # a parse error
            _say(program, f"the command line: {culprit}{one_line(e)} (python -m {program[10:]} --help "
                          f"lists the options)")
            sys.exit(2)
        except OSError as e:                # Hydra makes the run folder and its log file first
            where = f" {e.filename}" if e.filename else ""
            _say(program, f"cannot write{where}: {e.strerror or e} (the run folder must be a folder "
                          f"you can write: choose another hydra.run.dir)")
            sys.exit(2)
        except KeyboardInterrupt as e:
            _say(program, str(e) or "interrupted; the same command starts it again (a fit resumes "
                                    "from its last checkpoint)")
            sys.exit(INTERRUPTED)

    return run


def _say(program: str, message: str) -> None:
    print(f"{program}: {message}", file=sys.stderr)

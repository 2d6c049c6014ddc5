"""The one exception users see for bad input."""


class InputError(ValueError):
    """Bad input: the message names the file or value and what was expected.

    Raised before any work starts, so nothing is left half-written. The command-line
    entry points print the message without a traceback and exit with status 2.
    """

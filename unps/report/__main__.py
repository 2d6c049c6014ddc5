"""``python -m unps.report <sweep folder> [--out DIR]``: the table and figures of a study."""

from __future__ import annotations

import argparse
import logging
from collections.abc import Sequence
from pathlib import Path

from unps.errors import exit_on_bad_input
from unps.report import report


@exit_on_bad_input


def report_and_print(args: argparse.Namespace) -> None:
    print(report(args.sweep, args.out).read_text())


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m unps.report",
                                     description="Tables and figures of one study's sweep folder.")
    parser.add_argument("sweep", type=Path, help="the sweep folder, e.g. multirun/noise")
    parser.add_argument("--out", type=Path, help="where to write (default: <sweep>/report)")
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    report_and_print(parser.parse_args(argv))


if __name__ == "__main__":
    main()

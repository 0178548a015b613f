"""The ``homocal`` command line.

Each subcommand module provides ``add_parser(subparsers)``: it adds its parser(s) and registers a handler
with ``parser.set_defaults(handler=fn)``, ``fn(args) -> int`` (the exit code). A handler raises ValueError
or OSError for bad input; ``main`` prints it as one ``homocal: error: ...`` line and exits 2. To add a
subcommand, import its module and list it in SUBCOMMANDS.
"""
from __future__ import annotations

import argparse
import sys

from homocal.correctors import commands as corrector_commands
from homocal.files import OutputFolderError
from homocal.study import cli as study_cli, report as study_report, sweep as study_sweep
from homocal.ui import cli as ui_cli

SUBCOMMANDS = (corrector_commands, study_cli, study_sweep, study_report, ui_cli)


class _Parser(argparse.ArgumentParser):
    """Usage errors as one line, like every other error of ours."""

    def error(self, message: str) -> None:
        self.exit(2, f"homocal: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="homocal", description="Homography ground-plane mapping: correct it from reference points.")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in SUBCOMMANDS:
        module.add_parser(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.handler(args)
    except (ValueError, OSError, OutputFolderError) as e:
        message = " ".join(str(e).split("\n"))
        print(f"homocal: error: {message}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

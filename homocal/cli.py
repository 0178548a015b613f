"""The ``homocal`` command line.

Each subcommand module (a ``cli.py``, or the study module the command is named after) provides
``add_parser(subparsers)``: it adds its parser(s) and registers each command's handler,
``parser.set_defaults(handler=handle_<command>)``, ``handle_<command>(args) -> int`` (the exit code).
A handler raises ValueError or OSError for bad input; ``main`` prints it as one ``homocal: error: ...``
line and exits 2. To add a subcommand, list its command name(s) and module in SUBCOMMANDS: a command line
naming one command imports only its module (``homocal apply`` does not load the study's compiled kernels).
"""
from __future__ import annotations

import argparse
import importlib
import sys

from homocal import __version__
from homocal.files import OutputFolderError, os_message

SUBCOMMANDS = {  # command -> the module whose add_parser adds it, in the order --help lists them
    "fit": "homocal.correctors.cli", "apply": "homocal.correctors.cli", "study": "homocal.study.cli",
    "sweep": "homocal.study.sweep", "report": "homocal.study.report", "advise": "homocal.study.advise",
    "ui": "homocal.ui.cli", "lens": "homocal.lens.cli", "measure": "homocal.measure.cli",
    "watch": "homocal.watch.cli", "examples": "homocal.examples_cli",
}


class _Parser(argparse.ArgumentParser):
    """Usage errors as one line, like every other error of ours."""

    def error(self, message: str) -> None:
        self.exit(2, f"homocal: error: {message} (see {self.prog} --help)\n")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of every command, or only of ``command``'s module when it names one of SUBCOMMANDS."""
    parser = _Parser(prog="homocal", description="Homography ground-plane mapping: correct it from reference points.")
    parser.add_argument("--version", action="version", version=f"homocal {__version__}")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    modules = [SUBCOMMANDS[command]] if command in SUBCOMMANDS else dict.fromkeys(SUBCOMMANDS.values())
    for module in modules:
        importlib.import_module(module).add_parser(subparsers)
    return parser


SIGNED_VALUES = ("--horizon-shift", "--camera-origin", "--lateral")  # options whose value may start with '-' (-12:16:2, -1.5,0)


def join_signed_values(argv: list[str]) -> list[str]:
    """['--horizon-shift', '-12:16:2'] -> ['--horizon-shift=-12:16:2'] for SIGNED_VALUES (argparse would take a
    value starting with '-' that is not a plain number for an option)."""
    out, i = [], 0
    while i < len(argv):
        if argv[i] in SIGNED_VALUES and i + 1 < len(argv) and argv[i + 1].startswith("-") and not argv[i + 1].startswith("--"):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out


def main(argv: list[str] | None = None) -> int:
    argv = join_signed_values(sys.argv[1:] if argv is None else list(argv))
    args = build_parser(argv[0] if argv else None).parse_args(argv)
    try:
        return args.handler(args)
    except (ValueError, OSError, OutputFolderError) as e:
        message = " ".join((os_message(e) if isinstance(e, OSError) else str(e)).split("\n"))
        print(f"homocal: error: {message}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

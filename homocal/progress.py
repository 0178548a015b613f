"""The homocal command's progress bars: tqdm on stderr when stderr is a terminal, or as --progress /
--no-progress say."""
from __future__ import annotations

import argparse
import sys


def add_progress_option(parser: argparse.ArgumentParser) -> None:
    """--progress / --no-progress on a subcommand that draws progress bars."""
    parser.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                        help="progress bars on stderr (default: only when stderr is a terminal)")


def show_progress(args: argparse.Namespace) -> bool:
    """Whether to draw progress bars: --progress / --no-progress if given, else whether stderr is a terminal."""
    return sys.stderr.isatty() if args.progress is None else args.progress

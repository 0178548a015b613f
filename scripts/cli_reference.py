"""Write docs/cli.md, the command-line reference, from the real argparse parsers of `homocal` and `simgen`.

    python scripts/cli_reference.py            # rewrite docs/cli.md from this checkout's parsers
    python scripts/cli_reference.py --check    # exit 1, naming the fix, if docs/cli.md differs from them

Every command and subcommand's `--help` as argparse prints it at WIDTH columns (argparse reads the width from
COLUMNS). argparse lays help out a little differently from one Python minor version to the next, so the page
records the version that wrote it; tests/test_docs.py runs the check under that version.
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PAGE = REPO / "docs" / "cli.md"
WIDTH = 100
PARSERS = (("homocal.cli", "build_parser"), ("simgen.cli", "_parser"))  # module, function returning its parser
PYTHON = f"{sys.version_info.major}.{sys.version_info.minor}"


def subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """The parser's subcommands by name, in the order they were added ({} for a leaf command)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def sections(parser: argparse.ArgumentParser, level: int = 2) -> list[str]:
    """A Markdown section per command, the subcommands' after their parent's."""
    text = [f"{'#' * level} {parser.prog}\n\n```text\n{parser.format_help().rstrip()}\n```\n"]
    for sub in subparsers(parser).values():
        text += sections(sub, level + 1)
    return text


def study_options() -> str:
    """The study options' table, from their one declaration (homocal.study.options)."""
    from homocal.study.inputs import StudyParams
    from homocal.study.options import options_markdown
    return ("## Study options\n\nEvery option of `homocal study` and `homocal sweep`, its values, whether it sweeps, "
            f"and its value in each preset, from the options' declarations.\n\n{options_markdown(StudyParams)}\n")


def reference() -> str:
    """The whole page, as this checkout's parsers and this Python print it."""
    sys.path.insert(0, str(REPO))
    saved = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(WIDTH)
    try:
        parsers = [getattr(importlib.import_module(module), name)() for module, name in PARSERS]
        body = [s for parser in parsers for s in sections(parser)]
        body.append(study_options())
    finally:
        sys.path.remove(str(REPO))
        if saved is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = saved
    head = ("# Command-line reference\n\n"
            "Every command's `--help`, generated from the parsers themselves by `python scripts/cli_reference.py` "
            f"(Python {PYTHON}); `tests/test_docs.py` fails when this page and the parsers differ. "
            "The guides say what the commands are for: [the camera guide](camera.md), "
            "[the dataset guide](datasets.md), [the study guide](study.md).\n")
    return "\n".join([head, *body])


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="cli_reference.py", description=__doc__.split("\n")[0])
    p.add_argument("--check", action="store_true", help="exit 1 if docs/cli.md differs from the parsers; write nothing")
    args = p.parse_args(argv)
    page = reference()
    if args.check:
        if PAGE.read_text(encoding="utf-8") != page:
            print("cli_reference.py: error: docs/cli.md differs from the parsers: run python scripts/cli_reference.py",
                  file=sys.stderr)
            return 1
        return 0
    PAGE.write_text(page, encoding="utf-8")
    print(f"cli_reference.py: wrote {PAGE.relative_to(REPO)} (Python {PYTHON})")
    return 0


if __name__ == "__main__":
    sys.exit(main())

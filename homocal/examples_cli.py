"""``homocal examples DIR``: copy the example files the README's first quick start uses (package data, so that
they come with ``pip install``) into a new or empty folder."""
from __future__ import annotations

import argparse
import shutil
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parent / "examples"  # in a checkout, a link to the top-level examples/


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Register ``examples``."""
    p = subparsers.add_parser("examples", help="copy the example files (examples/street/...) into a folder",
                              description="Copy the example files of the README's first quick start into DIR "
                                          "(new or empty): street/trapezoid.json, street/reference_points.csv, "
                                          "street/feet.csv and compare_corrections.py.")
    p.add_argument("dir", type=Path, metavar="DIR", help="folder to copy into (new or empty)")
    p.set_defaults(handler=handle_examples)


def handle_examples(args: argparse.Namespace) -> int:
    out: Path = args.dir
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise ValueError(f"DIR {out}: exists and is not an empty folder")
    shutil.copytree(EXAMPLES, out, dirs_exist_ok=True, ignore=shutil.ignore_patterns("__pycache__"))
    files = sorted(str(f.relative_to(out)) for f in out.rglob("*") if f.is_file())
    print(f"homocal examples: {len(files)} files copied into {out}: {', '.join(files)}")
    return 0

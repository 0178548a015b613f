"""data_schema.md's tables, read as the tests that hold a dataset's files to them need them."""
from __future__ import annotations

from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def schema_names(section: str) -> list[str]:
    """The key or column names data_schema.md's table under '## SECTION' lists, in order, each name of a row's first
    cell ('x1, y1, x2, y2' is four)."""
    text = (REPO / "data_schema.md").read_text(encoding="utf-8").split(f"\n## {section}\n", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in text.splitlines() if line.startswith("| ") and not line.startswith(("| key ", "| column "))]
    return [name.strip() for row in rows for name in row.split("|")[1].split(",")]

"""Atomic file writes: a file that exists is whole (DESIGN principle 6). Shared by homocal and simgen."""
from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path


def write_atomic(path: str | Path, write: Callable[[Path], object]) -> None:
    """Call write(tmp) on a temporary path beside ``path`` (same extension: tools pick formats by it), then
    rename it to ``path``; on any failure the temporary file is removed and nothing is left behind."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.stem}.tmp{os.getpid()}{path.suffix}")
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_text_atomic(path: str | Path, text: str) -> None:
    """Write text (UTF-8, newlines as given) atomically."""
    write_atomic(path, lambda tmp: tmp.write_text(text, encoding="utf-8", newline=""))


def write_json_atomic(path: str | Path, obj: object) -> None:
    """Write obj as indented JSON with a final newline, atomically."""
    write_text_atomic(path, json.dumps(obj, indent=2) + "\n")

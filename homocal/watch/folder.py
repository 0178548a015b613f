"""A homocal watch folder's stretches: which correction applies at a time (``homocal apply DIR --at S``)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from homocal.correctors.base import load_corrector
from homocal.files import read_json

TOOL = "homocal-watch"
MARKER = "watch.json"  # the folder's marker (homocal.files.output_folder)
REFUSED = "homocal-watch-refused"  # the format of corrections/<start_s>.json for a stretch whose correction is refused


def watch_corrections(folder: Path) -> list[tuple[float, Path]]:
    """The stretches of a homocal watch folder: [(start_s, correction path)] by start; ValueError naming the
    folder when it is not one or holds no correction."""
    if read_json(folder / MARKER).get("format") != TOOL:
        raise ValueError(f"{folder}: not a homocal watch folder (no {MARKER} with format {TOOL!r})")
    found = []
    for path in (folder / "corrections").glob("*.json"):
        try:
            found.append((float(path.stem), path))
        except ValueError:
            continue
    if not found:
        raise ValueError(f"{folder}: no correction yet (a stretch needs 3 people)")
    return sorted(found)


def correction_at(stretches: list[tuple[float, Path]], t_s: np.ndarray) -> np.ndarray:
    """The index (N,) into stretches of the stretch each time t_s (N,) seconds falls in: the last one starting at
    or before it (the first for a time before every start)."""
    starts = np.array([s for s, _ in stretches])
    return np.clip(np.searchsorted(starts, t_s, side="right") - 1, 0, len(starts) - 1)


def load_stretches(folder: Path) -> list:
    """The correctors of a watch folder's stretches, in watch_corrections' order; for a stretch whose correction was
    refused (homocal watch's REFUSED file: its people's outliers) why, as text."""
    loaded = []
    for _, path in watch_corrections(folder):
        document = read_json(path)
        if document.get("format") != REFUSED:
            loaded.append(load_corrector(path))
        elif isinstance(document.get("refused"), str):
            loaded.append(document["refused"])
        else:
            raise ValueError(f"{path}: field refused: expected text (why the stretch's correction was refused)")
    return loaded

"""JSON files of fitted corrections: the format's identity and tolerant reads.

A correction file is one JSON object (see ``Corrector.to_dict``)::

    {"format": "homocal.correction", "format_version": 1, "method": "regression" | "descent" | "hybrid",
     "params": {...constructor arguments...},
     "transformer": {"source": 4x2 image px (TL, TR, BR, BL), "target": 4x2 ground units},
     "camera_origin": [x, y], "error_before": e, "error_after": e, "calibration_improvement": pct | null,
     "fitted": {...the method's fitted parameters...}}
"""
from __future__ import annotations

import json
import math
from pathlib import Path

FORMAT = "homocal.correction"
FORMAT_VERSION = 1


def read_json(path: str | Path) -> dict:
    """Read a JSON object from path; ValueError (naming the file) if it is missing, unreadable or not an object."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"{path}: not a JSON file ({e})") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a JSON object, got {type(data).__name__}")
    return data


def float_or_none(x: float) -> float | None:
    """NaN as JSON null (strict JSON has no NaN)."""
    return None if math.isnan(x) else float(x)


def none_to_nan(x: float | None) -> float:
    return math.nan if x is None else float(x)

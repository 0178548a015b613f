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


def number(value, field: str, minimum: float | None = None) -> float:
    """A loaded field that must be a finite JSON number (>= minimum if given); ValueError naming the field."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"field {field}: expected a number, got {value!r}")
    if not math.isfinite(value):
        raise ValueError(f"field {field}: expected a finite number, got {value!r}")
    if minimum is not None and value < minimum:
        raise ValueError(f"field {field}: must be >= {minimum:g}, got {value!r}")
    return float(value)


def integer(value, field: str, minimum: int, maximum: int) -> int:
    """A loaded field that must be a JSON integer in [minimum, maximum]; ValueError naming the field."""
    if isinstance(value, bool) or not isinstance(value, int) or not minimum <= value <= maximum:
        raise ValueError(f"field {field}: expected an integer in [{minimum}, {maximum}], got {value!r}")
    return value


def boolean(value, field: str) -> bool:
    """A loaded field that must be JSON true or false; ValueError naming the field."""
    if not isinstance(value, bool):
        raise ValueError(f"field {field}: expected true or false, got {value!r}")
    return value


def float_or_none(x: float) -> float | None:
    """NaN as JSON null (strict JSON has no NaN)."""
    return None if math.isnan(x) else float(x)

"""JSON files of fitted corrections: the format's identity and tolerant reads.

A correction file is one JSON object (see ``Corrector.to_dict``)::

    {"format": "homocal.correction", "format_version": 1,
     "method": "regression" | "horizon" | "descent" | "hybrid" | "least-change",
     "params": {...constructor arguments...},
     "transformer": {"source": 4x2 image px (TL, TR, BR, BL), "target": 4x2 ground units},
     "camera_origin": [x, y], "error_before": e, "error_after": e, "calibration_improvement": pct | null,
     "fitted": {...the method's fitted parameters...},
     "lens": {"K": 3x3, "distortion": [k1, k2, p1, p2, k3], "image_size": [W, H]}}   optional: the camera's
                                   lens (its undistorted pixels are the ones mapped); absent: a pinhole's

Every field is checked on load against what fit could have produced (``Corrector._from_fields``); a bad one
is one ValueError naming the file and the field ("field fitted.a: must be >= 0 ...").
"""
from __future__ import annotations

import math

FORMAT = "homocal.correction"
FORMAT_VERSION = 1


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

"""Site-map units: a top-down map image with a scale and an origin ("after homography projection
and scaling", paper Section 4.1).

Convention (data_schema.md): map pixels px right, py down; world metres x right, y forward (map up):
    px = ox + s x,   py = oy - s y,   s = scale_px_per_m, (ox, oy) = origin_px (the world origin on the map).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from homocal.files import read_json
from homocal.geometry.homography import as_points


@dataclass(frozen=True)
class SiteMap:
    """Scale (px per metre, > 0) and origin (map pixel of the world origin) of a site-map image."""

    scale_px_per_m: float
    origin_px: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.scale_px_per_m) and self.scale_px_per_m > 0):
            raise ValueError(f"site map: scale_px_per_m must be a positive number, got {self.scale_px_per_m}")
        if len(self.origin_px) != 2 or not np.all(np.isfinite(self.origin_px)):
            raise ValueError(f"site map: origin_px must be two finite numbers, got {self.origin_px}")

    @property
    def to_metres_matrix(self) -> np.ndarray:
        """(3, 3) affine map from map pixels to world metres, for composing with a homography."""
        s, (ox, oy) = self.scale_px_per_m, self.origin_px
        return np.array([[1 / s, 0.0, -ox / s], [0.0, -1 / s, oy / s], [0.0, 0.0, 1.0]])

    def to_metres(self, points_px: np.ndarray) -> np.ndarray:
        """Map pixels (N, 2) to world metres (N, 2)."""
        p = as_points(points_px, "map points")
        ox, oy = self.origin_px
        return np.column_stack([(p[:, 0] - ox), (oy - p[:, 1])]) / self.scale_px_per_m

    def to_pixels(self, points_m: np.ndarray) -> np.ndarray:
        """World metres (N, 2) to map pixels (N, 2)."""
        p = as_points(points_m, "ground points")
        ox, oy = self.origin_px
        return np.column_stack([ox + p[:, 0] * self.scale_px_per_m, oy - p[:, 1] * self.scale_px_per_m])

    @classmethod
    def from_dict(cls, d: dict, where: str = "site map") -> "SiteMap":
        """From {"scale_px_per_m": s, "origin_px": [ox, oy], ...} (JSON numbers: true, false and "10" are not);
        ValueError naming ``where`` if malformed."""
        try:
            scale, origin = d["scale_px_per_m"], d["origin_px"]
            ox, oy = origin
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"{where}: site map needs scale_px_per_m and origin_px [ox, oy] ({e})") from None
        for name, value in (("scale_px_per_m", scale), ("origin_px", ox), ("origin_px", oy)):
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f"{where}: site map {name} must be numbers, got {value!r}")
        try:
            return cls(float(scale), (float(ox), float(oy)))
        except ValueError as e:
            raise ValueError(f"{where}: {e}") from None

    @classmethod
    def from_json(cls, path: str | Path) -> "SiteMap":
        """Read a dataset's site_map.json; ValueError naming the file if it is missing or not a JSON object."""
        return cls.from_dict(read_json(path), str(path))

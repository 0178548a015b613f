"""Geometry: the pinhole camera model, homographies from trapezoids, site-map units."""
from homocal.geometry.camera import PinholeCamera
from homocal.geometry.homography import (
    ViewTransformer,
    apply_homography,
    as_points,
    homography_from_quads,
    validate_quad,
)
from homocal.geometry.sitemap import SiteMap

__all__ = [
    "PinholeCamera",
    "SiteMap",
    "ViewTransformer",
    "apply_homography",
    "as_points",
    "homography_from_quads",
    "validate_quad",
]

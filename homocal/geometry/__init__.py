"""Geometry: the pinhole camera model, homographies from trapezoids, site-map units."""
from homocal.geometry.camera import PinholeCamera
from homocal.geometry.homography import (
    ViewTransformer,
    apply_homography,
    as_points,
    check_magnitude,
    check_orientation,
    homography_from_quads,
    signed_area,
    validate_quad,
)
from homocal.geometry.sitemap import SiteMap

__all__ = [
    "PinholeCamera",
    "SiteMap",
    "ViewTransformer",
    "apply_homography",
    "as_points",
    "check_magnitude",
    "check_orientation",
    "homography_from_quads",
    "signed_area",
    "validate_quad",
]

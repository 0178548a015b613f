"""Geometry: the pinhole camera model, the lens (distortion), homographies from trapezoids, site-map units, box foot points."""
from homocal.geometry.boxes import BOX_CONVENTIONS, box_bottom_points
from homocal.geometry.camera import PinholeCamera
from homocal.geometry.homography import (
    MAX_COORDINATE,
    ViewTransformer,
    apply_homography,
    as_points,
    check_magnitude,
    check_orientation,
    homography_from_quads,
    signed_area,
    validate_quad,
)
from homocal.geometry.lens import Lens
from homocal.geometry.sitemap import SiteMap
from homocal.geometry.trapezoid_file import read_trapezoid_file

__all__ = [
    "BOX_CONVENTIONS",
    "Lens",
    "MAX_COORDINATE",
    "PinholeCamera",
    "SiteMap",
    "ViewTransformer",
    "apply_homography",
    "as_points",
    "box_bottom_points",
    "check_magnitude",
    "check_orientation",
    "homography_from_quads",
    "signed_area",
    "read_trapezoid_file",
    "validate_quad",
]

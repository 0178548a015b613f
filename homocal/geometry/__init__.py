"""Geometry: the pinhole camera model, homographies from trapezoids, site-map units."""
from homocal.geometry.camera import PinholeCamera

__all__ = ["PinholeCamera"]

"""A lens on a pinhole renderer: MuJoCo renders a pinhole view wide enough to hold every ray of the distorted frame,
and each frame pixel takes its value from where its undistorted ray lands there (cv2.remap: bilinear for RGB,
nearest for ids). The maps are computed once per camera (``lens_warp`` is cached).

The wide view shares the camera's pose and focal length; it is the camera's undistorted image grown by a margin
on each side, so its principal point is the camera's plus the margin (MuJoCo puts it at the view's centre).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from homocal.geometry.camera import PinholeCamera

MARGIN_PX = 2  # beyond the outermost undistorted ray, so that bilinear interpolation stays inside the render


@dataclass(frozen=True, eq=False)
class LensWarp:
    """The wide pinhole render of a distorted camera and its maps to the camera's frame.

    Attributes:
        width, height: the pinhole render's size, px.
        fovy_deg: its vertical field of view (MuJoCo's ``fovy``), degrees.
        linear: cv2's fixed-point maps (``convertMaps``, CV_16SC2 and CV_16UC1) for bilinear remapping.
        nearest: (H, W) int64 flat index (row * width + column) of the render pixel nearest to each frame pixel's
            undistorted ray.
    """

    width: int
    height: int
    fovy_deg: float
    linear: tuple[np.ndarray, np.ndarray]
    nearest: np.ndarray

    def rgb(self, image: np.ndarray) -> np.ndarray:
        """(height, width, 3) uint8 render -> the camera's (H, W, 3) frame, bilinear."""
        return cv2.remap(image, *self.linear, cv2.INTER_LINEAR)

    def ids(self, image: np.ndarray) -> np.ndarray:
        """(height, width) ids of the render -> the camera's (H, W) ids, nearest (ids are never blended)."""
        return np.take(image.ravel(), self.nearest)


@functools.cache
def lens_warp(camera: PinholeCamera) -> LensWarp | None:
    """The warp of ``camera`` (None without distortion: MuJoCo renders its frame directly).

    ValueError when the lens folds inside the frame (a frame pixel with no undistorted ray)."""
    if not any(camera.distortion):
        return None
    w, h = camera.width, camera.height
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    und = camera.lens.check_folds().undistort_points(np.column_stack([u.ravel(), v.ravel()]))
    if not np.isfinite(und).all():
        raise ValueError(f"camera: distortion {list(camera.distortion)} leaves frame pixels without an undistorted ray")
    low, high = und.min(axis=0), und.max(axis=0) - [w - 1, h - 1]
    mx, my = (max(0, math.ceil(max(-lo, hi))) + MARGIN_PX for lo, hi in zip(low, high))
    src = (und + [mx, my]).reshape(h, w, 2).astype(np.float32)
    linear = cv2.convertMaps(src[..., 0], src[..., 1], cv2.CV_16SC2)
    fovy = math.degrees(2.0 * math.atan((h / 2.0 + my) / camera.focal_px))
    nearest = np.rint(src[..., 1]).astype(np.int64) * (w + 2 * mx) + np.rint(src[..., 0]).astype(np.int64)
    return LensWarp(w + 2 * mx, h + 2 * my, fovy, linear, nearest)


def render_view(camera: PinholeCamera) -> tuple[int, int, float]:
    """(width px, height px, fovy degrees) of the pinhole view MuJoCo renders for ``camera``: its own without a lens."""
    warp = lens_warp(camera)
    return (camera.width, camera.height, camera.vfov_deg) if warp is None else (warp.width, warp.height, warp.fovy_deg)

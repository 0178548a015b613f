"""Error bars: 1-sigma ellipses of ground positions and the trustworthy range, from the library's
``ground_uncertainty`` and ``max_trustworthy_range``."""
from __future__ import annotations

import numpy as np

import homocal
from homocal.geometry import ViewTransformer
from homocal.ui import overlay
from homocal.ui.session import Session

ELLIPSE_VERTICES = 32


def error_bars(session: Session, transformer: ViewTransformer, image_points: np.ndarray, camera_origin: np.ndarray,
               tolerance_m: float, click_sigma_px: float, point_sigma_px: float, map_sigma_px: float) -> dict:
    """Ground covariances of image points (K, 2) px as 1-sigma ellipses, and the trustworthy range.

    Returns {"points": (K, 2) ground m, "image_points": the image points, "sigma": [[major, minor] m, ...], "image": ellipses as image polylines,
    "map": ellipses in map px, "trustworthy_range_m": range or None, "trustworthy_image": that ring in the
    image (polylines)}.
    """
    sigmas = {"click_sigma_px": click_sigma_px, "point_sigma_px": point_sigma_px, "map_sigma_px": map_sigma_px}
    if not hasattr(homocal, "ground_uncertainty"):
        return None
    cov = homocal.ground_uncertainty(transformer, image_points, **sigmas)
    trustworthy = float(homocal.max_trustworthy_range(transformer, tolerance_m, **sigmas))
    trustworthy = trustworthy if np.isfinite(trustworthy) else None
    centres = transformer.transform_points(image_points)
    eigval, eigvec = np.linalg.eigh(cov)  # ascending: minor, major
    angle = np.linspace(0, 2 * np.pi, ELLIPSE_VERTICES)
    unit = np.stack([np.cos(angle), np.sin(angle)])  # (2, V)
    ground = centres[:, :, None] + eigvec @ (np.sqrt(np.maximum(eigval, 0))[:, :, None] * unit)  # (K, 2, V)
    ground = ground.transpose(0, 2, 1)
    return {
        "points": centres.tolist(),
        "image_points": image_points.tolist(),
        "sigma": np.sqrt(np.maximum(eigval[:, ::-1], 0)).tolist(),
        "image": [np.round(transformer.inverse_transform_points(e), 2).tolist() for e in ground],
        "map": [np.round(session.site_map.to_pixels(e), 2).tolist() for e in ground],
        "trustworthy_range_m": trustworthy,
        "trustworthy_image": [] if trustworthy is None else overlay.ring_in_image(
            transformer, camera_origin, trustworthy, *session.frame_size),
    }

"""Error bars: 1-sigma ellipses of ground positions and the trustworthy range, from the library's
``ground_uncertainty`` and ``max_trustworthy_range`` (homocal/uncertainty.py)."""
from __future__ import annotations

import functools
from typing import Callable

import numpy as np

from homocal.geometry import ViewTransformer
from homocal.ui import overlay
from homocal.ui.session import Session, to_frame
from homocal.uncertainty import ground_uncertainty, max_trustworthy_range

ELLIPSE_VERTICES = 32


def error_bars(session: Session, transformer: ViewTransformer, image_points: np.ndarray, camera_origin: np.ndarray,
               tolerance_m: float | None, click_sigma_px: float, point_sigma_px: float, map_sigma_px: float,
               uncertainty: Callable[..., np.ndarray] | None = None,
               transform: Callable[[np.ndarray], np.ndarray] | None = None) -> dict:
    """1-sigma error ellipses of the ground positions of image points (K, 2) px (the transformer's: undistorted
    with the session's lens; what it returns as image polylines is in the frame's pixels), and the trustworthy range.

    The error model is ``uncertainty`` (a fitted correction's own ``Corrector.ground_uncertainty``, whose
    mapping is transformer), or ``ground_uncertainty`` of transformer and the session's lens if None. The sigmas are theirs: image
    clicks and the point itself in image px, the map clicks in site-map px (converted here to the
    transformer's metres). The ellipses are centred on ``transform`` of the points (a fitted correction's
    transform_points), or on transformer's mapping of them if None. Points whose covariance is NaN (at the
    horizon) are left out. Returns {"image_points": (K', 2) px, "points": (K', 2) ground m, "sigma": [[major,
    minor] m, ...], "image": ellipses as image polylines, "map": ellipses in map px, "trustworthy_range_m":
    the straight-ahead range whose 1-sigma radius is <= tolerance_m (None if unbounded or tolerance_m is None),
    "trustworthy_image": that range's ring as image polylines, "beyond": how many points were left out because
    they lie beyond that range (their ellipses are not trustworthy: long spikes towards the horizon)}.
    """
    sigmas = {"click_sigma_px": click_sigma_px, "point_sigma_px": point_sigma_px,
              "map_sigma_px": map_sigma_px / session.site_map.scale_px_per_m}
    if uncertainty is None:  # the clicks are on the frame: through the session's lens (None without one)
        uncertainty = functools.partial(ground_uncertainty, transformer, lens=session.lens)
    cov = uncertainty(image_points, **sigmas)
    valid = np.isfinite(cov).all(axis=(1, 2))
    image_points, cov = image_points[valid], cov[valid]
    trustworthy, beyond = None, 0
    centres = (transformer.transform_points if transform is None else transform)(image_points)
    if tolerance_m is not None:
        trustworthy = float(max_trustworthy_range(transformer, tolerance_m, camera_origin=camera_origin,
                                                 uncertainty=uncertainty, **sigmas))
        within = np.hypot(*(centres - camera_origin).T) <= trustworthy
        beyond = int(np.count_nonzero(~within))
        image_points, centres, cov = image_points[within], centres[within], cov[within]
        trustworthy = trustworthy if np.isfinite(trustworthy) else None
    eigval, eigvec = np.linalg.eigh(cov)  # ascending: minor, major; columns of eigvec are the axes
    angle = np.linspace(0, 2 * np.pi, ELLIPSE_VERTICES)
    unit = np.stack([np.cos(angle), np.sin(angle)])  # (2, V)
    axes = eigvec * np.sqrt(np.maximum(eigval, 0))[:, None, :]  # (K, 2, 2): each axis scaled by its sigma
    ellipses = (centres[:, :, None] + axes @ unit).transpose(0, 2, 1)  # (K, V, 2) ground m
    return {
        "image_points": to_frame(session, image_points).tolist(),
        "points": centres.tolist(),
        "sigma": np.sqrt(np.maximum(eigval[:, ::-1], 0)).tolist(),
        "image": [np.round(to_frame(session, transformer.inverse_transform_points(e)), 2).tolist() for e in ellipses],
        "map": [np.round(session.site_map.to_pixels(e), 2).tolist() for e in ellipses],
        "trustworthy_range_m": trustworthy,
        "beyond": beyond,
        "trustworthy_image": [] if trustworthy is None else [overlay.through_lens(line, session.lens) for line in
                                                             overlay.ring_in_image(transformer, camera_origin,
                                                                                   trustworthy, *session.frame_size)],
    }

"""Error bars on mapped ground points: the first-order covariance (the paper's eq. (1), Section 2) of a
trapezoid homography's output under clicking noise on the trapezoid and detection noise on the point, and the
farthest range a tolerance allows.

The "1-sigma radius" of a (2, 2) covariance is, everywhere in homocal, sqrt of its largest eigenvalue: the
semi-major axis of the 1-sigma error ellipse, the standard deviation along the worst direction (for a
homography that is almost exactly the range direction, the error the paper studies).
"""
from __future__ import annotations

import functools
import math
from typing import Callable

import numpy as np

from homocal.geometry import ViewTransformer, apply_homography, as_points, homography_from_quads
from homocal.geometry.lens import Lens

STEP = 1e-3  # central-difference step on an image coordinate, pixels (map coordinates: 1e-6 of the map's size)


def _check_sigma(name: str, value: float) -> float:
    value = float(value)
    if not (math.isfinite(value) and value >= 0):
        raise ValueError(f"{name} must be a finite number >= 0, got {value}")
    return value


def _quad_jacobian(source: np.ndarray, target: np.ndarray, points: np.ndarray, which: int, h: float) -> np.ndarray:
    """(N, 2, 8) derivative of the mapped points (N, 2) with respect to the 8 coordinates of the source (which=0)
    or target (which=1) quad, by central differences of homography_from_quads."""
    J = np.empty((len(points), 2, 8))
    for k in range(8):
        mapped = []
        for sign in (1.0, -1.0):
            quads = [source.copy(), target.copy()]
            quads[which].reshape(-1)[k] += sign * h
            mapped.append(apply_homography(homography_from_quads(*quads), points))
        J[:, :, k] = (mapped[0] - mapped[1]) / (2 * h)
    return J


def click_jacobian(transformer: ViewTransformer, image_points: np.ndarray, lens: Lens | None = None) -> np.ndarray:
    """J_s (N, 2, 8) of ``ground_uncertainty``: the derivative of the mapped points (N, 2) px -> target units
    with respect to the 8 clicked image coordinates of the transformer's trapezoid (with ``lens``: clicked on the
    distorted frame, each corner's derivative times the undistortion's local Jacobian inv(lens.distort_jacobian))."""
    Js = _quad_jacobian(transformer.source, transformer.target, as_points(image_points, "image_points"), 0, STEP)
    if lens is None or lens.is_identity:
        return Js
    corners = np.linalg.inv(lens.distort_jacobian(transformer.source))  # (4, 2, 2) d(undistorted) / d(clicked)
    return np.einsum("nikj,kjl->nikl", Js.reshape(len(Js), 2, 4, 2), corners).reshape(len(Js), 2, 8)


def point_jacobian(transformer: ViewTransformer, image_points: np.ndarray, lens: Lens | None = None) -> np.ndarray:
    """J_q (N, 2, 2) of ``ground_uncertainty``: the derivative of the mapped points, target units, with respect to
    the image points (N, 2) px, analytic: the derivative of (H q)_xy / (H q)_w; with ``lens`` with respect to the
    point on the distorted frame, where it is detected: J_q times inv(lens.distort_jacobian) at the undistorted
    point. A point's covariance S (2, 2) px^2 on that frame maps to J_q S J_q^T. NaN on or above the horizon."""
    q = as_points(image_points, "image_points")
    H = transformer.m
    w = (np.column_stack([q, np.ones(len(q))]) @ H[2])[:, None, None]
    Jq = (H[None, :2, :2] - apply_homography(H, q)[:, :, None] * H[None, 2:3, :2]) / w
    if lens is not None and not lens.is_identity:
        Jq = Jq @ np.linalg.inv(lens.distort_jacobian(q))
    return Jq


def ground_uncertainty(
    transformer: ViewTransformer,
    image_points: np.ndarray,
    click_sigma_px: float = 1.5,
    point_sigma_px: float = 1.0,
    map_sigma_px: float = 0.0,
    lens: Lens | None = None,
) -> np.ndarray:
    """First-order covariance (N, 2, 2) of the mapped image points (N, 2) px, in the transformer's target units
    (metres for homocal fit's files).

    Sigma = click_sigma^2 J_s J_s^T + map_sigma^2 J_t J_t^T + point_sigma^2 J_q J_q^T (the paper's eq. (1)), with
    independent Gaussian errors of standard deviation click_sigma_px on each of the 8 clicked image coordinates
    of the trapezoid (J_s (2, 8)), map_sigma_px on each of the 8 map coordinates (J_t (2, 8); in the
    transformer's TARGET units: site-map pixels if it was built on site-map pixels, metres if on metres, so for
    homocal fit's files, which hold metres, divide a map clicking error in pixels by scale_px_per_m) and
    point_sigma_px on each image coordinate of the point itself (J_q (2, 2), ``point_jacobian``). J_s and J_t are
    central differences (step 1e-3 px; 1e-6 of the map's extent) of the closed-form 4-point homography: the closed
    form is the one home of the homography, its analytic derivative through the projective basis would be a second,
    longer one, and the differences are exact to ~1e-9 relative (truncation ~ (step / distance to the horizon)^2,
    rounding ~1e-16 / step), far below the first-order approximation's own error.

    lens: the camera's Lens when the trapezoid was clicked and the point detected on its distorted frame (the
    transformer's source and image_points are then undistorted pixels, as homocal fit --camera-json makes them):
    click_sigma_px and point_sigma_px are on the frame's pixels, where the clicks and detections err, so each
    undistorted corner and point gets the covariance sigma^2 A A^T, A = inv(lens.distort_jacobian) there (the
    undistortion's local Jacobian: it stretches a wide lens's frame up to 2.1 times, docs/real-camera.md), i.e. J_s
    and J_q times A.

    Points on or above the horizon (and those whose differences cross it): NaN covariance. Checked against Monte
    Carlo in tests/homocal/test_uncertainty.py (1-sigma radii within 10 % out to 50 m on the paper's camera).
    """
    if not isinstance(transformer, ViewTransformer):
        raise TypeError(f"transformer: expected a homocal.ViewTransformer, got {type(transformer).__name__}")
    q = as_points(image_points, "image_points")
    sc = _check_sigma("click_sigma_px", click_sigma_px)
    sp = _check_sigma("point_sigma_px", point_sigma_px)
    sm = _check_sigma("map_sigma_px", map_sigma_px)
    source, target = transformer.source, transformer.target
    mapped = apply_homography(transformer.m, q)
    Jq = point_jacobian(transformer, q, lens)
    cov = sp**2 * Jq @ Jq.transpose(0, 2, 1)
    if sc > 0:
        Js = click_jacobian(transformer, q, lens)
        cov += sc**2 * Js @ Js.transpose(0, 2, 1)
    if sm > 0:
        Jt = _quad_jacobian(source, target, q, 1, 1e-6 * max(float(np.ptp(target, axis=0).max()), 1e-300))
        cov += sm**2 * Jt @ Jt.transpose(0, 2, 1)
    cov[np.isnan(mapped).any(axis=1)] = np.nan
    return cov


def sigma_radius(cov: np.ndarray) -> np.ndarray:
    """1-sigma radius of covariances (..., 2, 2): sqrt of the largest eigenvalue (the error ellipse's semi-major
    axis), same units as the coordinates; NaN stays NaN."""
    cov = np.asarray(cov, dtype=np.float64)
    a, b, c = cov[..., 0, 0], 0.5 * (cov[..., 0, 1] + cov[..., 1, 0]), cov[..., 1, 1]
    return np.sqrt(0.5 * (a + c) + np.sqrt((0.5 * (a - c)) ** 2 + b**2))


def straight_ahead_column(transformer: ViewTransformer) -> float:
    """Image column u (px) of "straight ahead": where the ground lines of constant x (parallel to the target's
    y axis, the forward direction) meet, the vanishing point m_inv (0, 1, 0). For a camera without yaw or roll
    whose ground frame has y along the optical axis (homocal's world frame), the principal column."""
    vp = transformer.m_inv @ np.array([0.0, 1.0, 0.0])
    if abs(vp[2]) <= 1e-12 * np.linalg.norm(vp):
        raise ValueError("the target's y axis is parallel to the image plane: no straight-ahead column")
    return float(vp[0] / vp[2])


def max_trustworthy_range(
    transformer: ViewTransformer,
    tolerance_m: float,
    columns: np.ndarray | None = None,
    click_sigma_px: float = 1.5,
    point_sigma_px: float = 1.0,
    camera_origin=(0.0, 0.0),
    map_sigma_px: float = 0.0,
    uncertainty: Callable[..., np.ndarray] | None = None,
) -> float | np.ndarray:
    """The farthest range (target units, metres) along image column(s) u at which the 1-sigma radius
    (``sigma_radius`` of ``ground_uncertainty``, or of ``uncertainty``) stays at or under tolerance_m.

    Along a column the search starts at the row of the trapezoid's lowest vertex and walks towards the horizon
    (rows v_h + D 2^(-k/16), D = start row - v_h, down to 1e-3 px from it; then 40 bisections in log(v - v_h) at
    the first row over the tolerance); range = ||mapped point - camera_origin||. 0.0 if the tolerance is
    exceeded at the start row already, inf if it never is (all sigmas 0).

    Args:
        columns: image columns u, pixels; None: the straight-ahead column (``straight_ahead_column``).
        camera_origin: (2,) ground point under the camera, target units.
        uncertainty: the error model, called as uncertainty(image_points (N, 2), click_sigma_px=,
            point_sigma_px=, map_sigma_px=) -> covariances (N, 2, 2): a fitted correction's own
            (``Corrector.ground_uncertainty``, whose ``mapping`` is transformer); None: ground_uncertainty of
            transformer.
    Returns a float if columns is None, else an array of the columns' shape.
    """
    tol = float(tolerance_m)
    if not (math.isfinite(tol) and tol > 0):
        raise ValueError(f"tolerance_m must be a finite number > 0, got {tolerance_m}")
    origin = np.asarray(camera_origin, dtype=np.float64)
    if origin.shape != (2,) or not np.isfinite(origin).all():
        raise ValueError(f"camera_origin must be 2 finite numbers, got {camera_origin!r}")
    u_all = np.atleast_1d(np.asarray(straight_ahead_column(transformer) if columns is None else columns, float))
    if not np.isfinite(u_all).all():
        raise ValueError(f"columns must be finite numbers, got {u_all.tolist()}")
    v_start = float(transformer.source[:, 1].max())
    kw = dict(click_sigma_px=click_sigma_px, point_sigma_px=point_sigma_px, map_sigma_px=map_sigma_px)
    if uncertainty is None:
        uncertainty = functools.partial(ground_uncertainty, transformer)

    def radius(u: float, log_dv: np.ndarray) -> np.ndarray:
        q = np.column_stack([np.full(len(log_dv), u), transformer.horizon_row(u) + np.exp(log_dv)])
        return sigma_radius(uncertainty(q, **kw))

    out = np.empty(len(u_all))
    for n, u in enumerate(u_all):
        D = v_start - float(transformer.horizon_row(u))
        if not D > 0:
            raise ValueError(f"column {u}: the trapezoid's lowest vertex (row {v_start}) is not below the horizon")
        log_dv = np.log(D) - np.log(2.0) / 16 * np.arange(int(16 * math.log2(D / 1e-3)) + 1)
        over = np.flatnonzero(~(radius(u, log_dv) <= tol))
        if over.size == 0:
            out[n] = math.inf
            continue
        if over[0] == 0:
            out[n] = 0.0
            continue
        ok, bad = log_dv[over[0] - 1], log_dv[over[0]]
        for _ in range(40):
            mid = 0.5 * (ok + bad)
            ok, bad = (mid, bad) if radius(u, np.array([mid]))[0] <= tol else (ok, mid)
        point = transformer.transform_points([[u, transformer.horizon_row(u) + math.exp(ok)]])[0]
        out[n] = float(np.linalg.norm(point - origin))
    return float(out[0]) if columns is None else out.reshape(np.shape(columns))

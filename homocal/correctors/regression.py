"""Method 1 of the paper (Section 4.1, eqs. (18)-(24)): fit the quadratic error law e(d) = a d^2 + b d to
the calibration errors and move every mapped point radially by the predicted error; and beyond the paper,
the signed law with an intercept, e(d) = a d^2 + b d + c (the constant of Section 3's first-order expansion,
``homocal.first_order_error``)."""
from __future__ import annotations

import numpy as np

from homocal.correctors.base import Corrector
from homocal.correctors.serialization import boolean, number


def fit_quadratic_error(d: np.ndarray, e: np.ndarray) -> tuple[float, float, bool]:
    """Least-squares a, b of e = a d^2 + b d (eq. (19)) over N pairs, by the normal equations (eqs. (20)-(22)).

    With S_k = sum d_i^k and T_k = sum d_i^k e_i, det = S4 S2 - S3^2:
      det <= 1e-12 S4 S2 (degenerate, distances nearly equal): a = 0, b = T1 / S2 (linear-only fit e = b d);
      else a = (T2 S2 - T1 S3) / det, b = (S4 T1 - S3 T2) / det (eq. (22)).
    No clamping here. Args d, e: (N,). Returns (a, b, degenerate).
    """
    S2, S3, S4 = np.sum(d**2), np.sum(d**3), np.sum(d**4)
    T1, T2 = np.sum(d * e), np.sum(d**2 * e)
    if not S2 > 0:
        raise ValueError("all calibration points map onto the camera origin: no distance to fit the error law to")
    det = S4 * S2 - S3**2
    if det <= 1e-12 * S4 * S2:
        return 0.0, float(T1 / S2), True
    return float((T2 * S2 - T1 * S3) / det), float((S4 * T1 - S3 * T2) / det), False


def fit_quadratic_intercept(d: np.ndarray, e: np.ndarray) -> tuple[float, float, float, bool]:
    """Least-squares a, b, c of e = a d^2 + b d + c over N >= 3 pairs (exact through three distinct distances).

    For conditioning the fit is made in t = (d - m) / s, m = mean(d), s = max |d - m| (t in [-1, 1]):
    e = alpha t^2 + beta t + gamma by the normal equations, with S_k = sum t_i^k, T_k = sum t_i^k e_i,
        | S4 S3 S2 | |alpha|   |T2|
        | S3 S2 S1 | |beta | = |T1|,   solved by Cramer's rule,
        | S2 S1 S0 | |gamma|   |T0|
    then a = alpha / s^2, b = beta / s - 2 alpha m / s^2, c = alpha m^2 / s^2 - beta m / s + gamma.
    Degenerate (det <= 1e-12 S4 S2 S0: fewer than three distinct distances, nearly): alpha = 0 and the line
    e = beta t + gamma by least squares; if that is degenerate too (det2 = S2 S0 - S1^2 <= 1e-12 S2 S0, or all
    distances equal): beta = 0, gamma = mean(e). No clamping. Args d, e: (N,). Returns (a, b, c, degenerate).
    """
    m = np.sum(d) / len(d)
    s = np.max(np.abs(d - m))
    if not s > 0:
        return 0.0, 0.0, float(np.sum(e) / len(e)), True
    t = (d - m) / s
    S0, S1, S2, S3, S4 = float(len(t)), np.sum(t), np.sum(t**2), np.sum(t**3), np.sum(t**4)
    T0, T1, T2 = np.sum(e), np.sum(t * e), np.sum(t**2 * e)
    alpha, beta, gamma, degenerate = solve_normal3(S0, S1, S2, S3, S4, T0, T1, T2)
    return alpha / s**2, beta / s - 2 * alpha * m / s**2, alpha * m**2 / s**2 - beta * m / s + gamma, degenerate


def solve_normal3(S0, S1, S2, S3, S4, T0, T1, T2) -> tuple[float, float, float, bool]:
    """(alpha, beta, gamma, degenerate) of fit_quadratic_intercept's normal equations (Cramer's rule, with its
    fallbacks); scalar code, which the compiled study kernel calls too."""
    det = S4 * (S2 * S0 - S1 * S1) - S3 * (S3 * S0 - S1 * S2) + S2 * (S3 * S1 - S2 * S2)
    if det > 1e-12 * S4 * S2 * S0:
        alpha = (T2 * (S2 * S0 - S1 * S1) - S3 * (T1 * S0 - S1 * T0) + S2 * (T1 * S1 - S2 * T0)) / det
        beta = (S4 * (T1 * S0 - S1 * T0) - T2 * (S3 * S0 - S1 * S2) + S2 * (S3 * T0 - T1 * S2)) / det
        gamma = (S4 * (S2 * T0 - T1 * S1) - S3 * (S3 * T0 - T1 * S2) + T2 * (S3 * S1 - S2 * S2)) / det
        return float(alpha), float(beta), float(gamma), False
    det2 = S2 * S0 - S1 * S1
    if det2 > 1e-12 * S2 * S0:
        return 0.0, float((T1 * S0 - S1 * T0) / det2), float((S2 * T0 - S1 * T1) / det2), True
    return 0.0, 0.0, float(T0 / S0), True


def radial_correction(points: np.ndarray, origin: np.ndarray, a: float, b: float, c: float = 0.0) -> np.ndarray:
    """Eqs. (23)-(24): p_corr = p - dhat c(d) with d = ||p - o||, c(d) = a d^2 + b d + c (the paper: c = 0),
    dhat = (o - p) / ||o - p||.

    A positive c moves p away from the camera origin o, a negative c towards it; the bearing from o is kept.
    Args: points (N, 2) mapped ground positions (NaN rows stay NaN), origin (2,), same units. A point at o
    is left where it is. Returns (N, 2) float64.
    """
    towards_camera = origin - points
    d = np.linalg.norm(towards_camera, axis=1)
    shift = a * d**2 + b * d + c
    out = points.copy()
    moved = d > 0
    dhat = towards_camera[moved] / d[moved, None]
    out[moved] = points[moved] - dhat * shift[moved, None]
    return out


class RegressionCorrector(Corrector):
    """Method 1, regression on the quadratic error law (paper eqs. (18)-(24)).

    With p_i the mapped calibration points, g_i their true positions and o the camera origin:
      d_i = ||p_i - o||;
      signed=False (paper-faithful): e_i = ||p_i - g_i|| (eq. (18)), a and b from eq. (22)
        (``fit_quadratic_error``, with its linear-only fallback), then clamped a = max(a, 0), b = max(b, 0)
        independently, as the paper writes. With a, b >= 0 the correction (eq. (24)) can only move points
        AWAY from the camera: a mapping that overestimates range is made worse, not better.
      signed=True: e_i = ||g_i - o|| - ||p_i - o|| (the signed range error), no clamping, so a mapping
        that overestimates range is pulled back towards the camera.
      signed=True, intercept=True (beyond the paper; CLI ``regression-intercept``): the signed error fitted
        as e(d) = a d^2 + b d + c (``fit_quadratic_intercept``: exact through three points, least squares
        for more), no clamping. The constant is Section 3's dOffset (``first_order_error``): a trapezoid
        error moves the near field too, which a law through e(0) = 0 cannot follow.
    Every mapped point p is then corrected by ``radial_correction`` (eqs. (23)-(24)) with
    c(d) = a d^2 + b d + c (c = 0 without the intercept).

    Attributes after fit: a_, b_, c_ (metres^-1, dimensionless and metres for metre units; c_ = 0 without
    the intercept), degenerate_ (a fallback of lower order was used), plus those of ``Corrector``.
    """

    method = "regression"
    param_names = ("signed", "intercept")

    def __init__(self, signed: bool = False, intercept: bool = False) -> None:
        for name, value in (("signed", signed), ("intercept", intercept)):
            if not isinstance(value, (bool, np.bool_)):
                raise ValueError(f"{name} must be true or false, got {value!r}")
        if intercept and not signed:
            raise ValueError("intercept=True needs signed=True: an intercept fitted to unsigned errors would move "
                             "every point, even one at the camera, away from it")
        self.signed = bool(signed)
        self.intercept = bool(intercept)

    def _fit(self, q: np.ndarray, p: np.ndarray, g: np.ndarray) -> None:
        o = self.camera_origin_
        d = np.linalg.norm(p - o, axis=1)
        if self.signed:
            e = np.linalg.norm(g - o, axis=1) - d
        else:
            e = np.linalg.norm(p - g, axis=1)  # eq. (18)
        if self.intercept:
            self.a_, self.b_, self.c_, self.degenerate_ = fit_quadratic_intercept(d, e)
            return
        a, b, self.degenerate_ = fit_quadratic_error(d, e)
        if not self.signed:
            a, b = max(a, 0.0), max(b, 0.0)
        self.a_, self.b_, self.c_ = a, b, 0.0

    def _transform(self, q: np.ndarray) -> np.ndarray:
        return radial_correction(self.base_transformer_.transform_points(q), self.camera_origin_, self.a_, self.b_,
                                 self.c_)

    def _fitted_state(self) -> dict:
        return {"a": self.a_, "b": self.b_, "c": self.c_, "degenerate": self.degenerate_}

    def _set_fitted_state(self, state: dict) -> None:
        """Check what fit could have produced: finite a, b, c; faithful: a, b >= 0 (clamped); no intercept: c = 0
        (files written before the intercept have no c); degenerate: a = 0 (the fallbacks have no d^2 term)."""
        floor = None if self.signed else 0.0
        self.a_ = number(state["a"], "fitted.a", minimum=floor)
        self.b_ = number(state["b"], "fitted.b", minimum=floor)
        self.c_ = number(state.get("c", 0.0), "fitted.c")
        self.degenerate_ = boolean(state["degenerate"], "fitted.degenerate")
        if not self.intercept and self.c_ != 0:
            raise ValueError(f"field fitted.c: must be 0 without the intercept (params.intercept false), got {self.c_}")
        if self.degenerate_ and self.a_ != 0:
            raise ValueError(f"field fitted.a: must be 0 for a degenerate fit (fitted.degenerate true), got {self.a_}")

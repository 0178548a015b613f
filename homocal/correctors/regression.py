"""Method 1 of the paper (Section 4.1, eqs. (18)-(24)): fit the quadratic error law e(d) = a d^2 + b d to
the calibration errors and move every mapped point radially by the predicted error."""
from __future__ import annotations

import numpy as np

from homocal.correctors.base import Corrector


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


def radial_correction(points: np.ndarray, origin: np.ndarray, a: float, b: float) -> np.ndarray:
    """Eqs. (23)-(24): p_corr = p - dhat c with d = ||p - o||, c = a d^2 + b d, dhat = (o - p) / ||o - p||.

    A positive c moves p away from the camera origin o, a negative c towards it; the bearing from o is kept.
    Args: points (N, 2) mapped ground positions (NaN rows stay NaN), origin (2,), same units. A point at o
    is left where it is. Returns (N, 2) float64.
    """
    towards_camera = origin - points
    d = np.linalg.norm(towards_camera, axis=1)
    c = a * d**2 + b * d
    out = points.copy()
    moved = d > 0
    dhat = towards_camera[moved] / d[moved, None]
    out[moved] = points[moved] - dhat * c[moved, None]
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
    Every mapped point p is then corrected by ``radial_correction`` (eqs. (23)-(24)).

    Attributes after fit: a_, b_ (metres^-1 and dimensionless for metre units), degenerate_ (the linear
    fallback was used), plus those of ``Corrector``.
    """

    method = "regression"
    param_names = ("signed",)

    def __init__(self, signed: bool = False) -> None:
        if not isinstance(signed, (bool, np.bool_)):
            raise ValueError(f"signed must be True or False, got {signed!r}")
        self.signed = bool(signed)

    def _fit(self, q: np.ndarray, p: np.ndarray, g: np.ndarray) -> None:
        o = self.camera_origin_
        d = np.linalg.norm(p - o, axis=1)
        if self.signed:
            e = np.linalg.norm(g - o, axis=1) - d
        else:
            e = np.linalg.norm(p - g, axis=1)  # eq. (18)
        a, b, self.degenerate_ = fit_quadratic_error(d, e)
        if not self.signed:
            a, b = max(a, 0.0), max(b, 0.0)
        self.a_, self.b_ = a, b

    def _transform(self, q: np.ndarray) -> np.ndarray:
        return radial_correction(self.base_transformer_.transform_points(q), self.camera_origin_, self.a_, self.b_)

    def _fitted_state(self) -> dict:
        return {"a": self.a_, "b": self.b_, "degenerate": self.degenerate_}

    def _set_fitted_state(self, state: dict) -> None:
        self.a_, self.b_, self.degenerate_ = float(state["a"]), float(state["b"]), bool(state["degenerate"])

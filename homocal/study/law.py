"""The quadratic law of paper Section 3, measured: how the range error along the calibration line grows with
range for a horizon-shift error (eq. (17) predicts an exponent of 2) and for the study's random corner
perturbations, and how well eq. (17) and its full first-order form (error_model.first_order_error) predict each.

Everything is measured against the dataset's exact trapezoid (trapezoids.json "exact"), so the errors are the
named error alone; ranges Y are true ranges of ground points straight ahead of the camera (x = o_x).
"""
from __future__ import annotations

import numpy as np

from homocal.error_model import column_model, first_order_error, quadratic_error
from homocal.geometry import ViewTransformer
from homocal.study.perturb import draw_variant, perturbed_quads, tilt_shift

RANGES = np.linspace(10.0, 44.0, 35)  # metres along the calibration line (the paper's calibration span)


def exponent(Y: np.ndarray, error: np.ndarray) -> float:
    """The least-squares slope of log|error| against log Y, (N,) arrays: the power of range the error grows with
    (points where the error is exactly 0 are left out; NaN if fewer than 2 remain)."""
    keep = np.abs(error) > 0
    return float(np.polyfit(np.log(Y[keep]), np.log(np.abs(error[keep])), 1)[0]) if keep.sum() >= 2 else float("nan")


def line_errors(exact: ViewTransformer, other: ViewTransformer, origin: np.ndarray, Y: np.ndarray = RANGES):
    """(q (N, 2) px, signed range error (N,) m) of `other` at the true ground points (o_x, o_y + Y) straight
    ahead: q are their exact image points, the error is ||other(q) - o|| - Y (positive: too far)."""
    ground = origin + np.column_stack([np.zeros_like(Y), Y])
    q = exact.inverse_transform_points(ground)
    return q, np.linalg.norm(other.transform_points(q) - origin, axis=1) - Y


def horizon_shift_law(exact: ViewTransformer, K: np.ndarray, origin: np.ndarray, shifts=(1.0, 4.0, 8.0, -8.0)) -> list[dict]:
    """Per horizon shift s (px, perturb.tilt_shift of the exact image quad): the exponent of |error| against Y
    and against Y - Offset (eq. (17)'s Y is measured from where the column model's Offset vanishes), and the
    error at the farthest range: exact, first order (first_order_error) and eq. (17) alone."""
    u = K[0, 2]
    model = column_model(exact.m, u)
    rows = []
    for s in shifts:
        shifted = ViewTransformer(tilt_shift(exact.source, K, float(exact.horizon_row(u)), s), exact.target)
        _, err = line_errors(exact, shifted, origin)
        eps = float(shifted.horizon_row(u) - exact.horizon_row(u))
        rows.append({
            "shift_px": s, "exponent_Y": exponent(RANGES, err), "exponent_Y_offset": exponent(RANGES - model.offset, err),
            "error_far_m": float(err[-1]),
            "first_order_far_m": float(first_order_error(exact.m, shifted.m, u, RANGES[-1])),
            "eq17_far_m": float(quadratic_error(eps, model.K, RANGES[-1] - model.offset)),
        })
    return rows


def perturbation_law(exact: ViewTransformer, map_quad: np.ndarray, site_map, origin: np.ndarray, u: float,
                     seed: int, scene: str, n_variants: int = 200, reading: str = "coordinate") -> dict:
    """Over the study's random corner perturbations (variants 1..n_variants, perturb.draw_variant as `reading`
    reads the paper's perturbation) of the exact trapezoid alone: the median exponent of |error| against Y,
    the share of variants whose signed error changes sign between 10 and 44 m (no a Y^2 + b Y without a
    constant fits those well), and the median relative RMS residual of first_order_error and of eq. (17)
    against the exact error."""
    model = column_model(exact.m, u)
    exps, sign_changes, res_first, res_17 = [], 0, [], []
    for v in range(1, n_variants + 1):
        image, mp = perturbed_quads(exact.source, map_quad, draw_variant(seed, scene, v, reading)[0])
        try:
            other = ViewTransformer(image, site_map.to_metres(mp))
        except ValueError:
            continue
        _, err = line_errors(exact, other, origin)
        if not np.isfinite(err).all() or not np.abs(err).max() > 0:
            continue
        exps.append(exponent(RANGES, err))
        sign_changes += bool((np.sign(err) != np.sign(err[0])).any())
        rms = np.sqrt(np.mean(err**2))
        res_first.append(np.sqrt(np.mean((first_order_error(exact.m, other.m, u, RANGES) - err) ** 2)) / rms)
        eps = float(other.horizon_row(u) - exact.horizon_row(u))
        res_17.append(np.sqrt(np.mean((quadratic_error(eps, model.K, RANGES - model.offset) - err) ** 2)) / rms)
    n = len(exps)
    return {"variants": n, "median_exponent": float(np.median(exps)), "sign_change_share": sign_changes / n,
            "median_residual_first_order": float(np.median(res_first)), "median_residual_eq17": float(np.median(res_17))}

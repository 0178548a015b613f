"""Compiled kernels of the two correctors beyond the paper, for the study's per-sample loop: regression with an
intercept (homocal.correctors.regression.fit_quadratic_intercept) and the horizon correction
(homocal.correctors.horizon.fit_horizon_shift). Plain scalar functions of one calibration triple, the same
algorithm, iteration counts and tolerances as the readable correctors; tests/homocal/test_method_kernels.py
checks that their results agree to 1e-9 (rounding-level ties aside, every decision is the same; where one is
not, both still converge to the same minimum). Conventions as homocal.study.kernels: cal table rows d, rx, ry, ux, uy,
e_faithful, e_signed; test-point lengths in units of 1/FIXED m (jit.FIXED).

Use in a per-sample loop (i, j, k the triple, H0 the variant's homography, q (M, 2) image and g (M, 2) ground
calibration points)::

    a, b, c, _ = fit_quadratic_intercept3(cal[0, i], cal[0, j], cal[0, k], cal[6, i], cal[6, j], cal[6, k])
    cal_after = (radial_error_intercept(cal, i, a, b, c) + ... j ... + ... k ...) / 3
    path_after = regression_path_intercept(test, a, b, c)
    eps, delta = fit_horizon_shift3(H0, q[i, 0], q[i, 1], g[i, 0], g[i, 1], ... j ..., ... k ...)
    cal_after = horizon_mean_error3(H0, eps, q[i, 0], q[i, 1], g[i, 0], g[i, 1], ... j ..., ... k ...)
    horizon_homography_into(H0, eps, Hh)        # then dH = Hh - H0 into kernels.descent_path, as descent's
(eps is NaN if the variant's mapping has h32 <= 0 or a calibration point beyond its horizon.)
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from homocal.correctors.horizon import FLAT, GRID_INTERVALS, NEWTON_STEPS, newton_step
from homocal.correctors.regression import solve_normal3
from homocal.study.jit import FIXED, JIT, PATH_JIT, to_fixed

_newton_step = nb.njit(inline="always", **JIT)(newton_step)  # the readable correctors' scalar steps, compiled
_solve_normal3 = nb.njit(inline="always", **JIT)(solve_normal3)


@nb.njit(**JIT)
def fit_quadratic_intercept3(d0, d1, d2, e0, e1, e2):
    """(a, b, c, degenerate) of e = a d^2 + b d + c through three (d, e), as fit_quadratic_intercept: in
    t = (d - m) / s (m the mean, s = max |d - m|), Cramer's rule on the normal equations, det <= 1e-12 S4 S2 S0
    falls back to a line, det2 <= 1e-12 S2 S0 (or s = 0) to the mean."""
    m = (d0 + d1 + d2) / 3.0
    s = max(abs(d0 - m), max(abs(d1 - m), abs(d2 - m)))
    if not s > 0:
        return 0.0, 0.0, (e0 + e1 + e2) / 3.0, True
    t0, t1, t2 = (d0 - m) / s, (d1 - m) / s, (d2 - m) / s
    S0, S1, S2 = 3.0, t0 + t1 + t2, t0 * t0 + t1 * t1 + t2 * t2
    S3, S4 = t0**3 + t1**3 + t2**3, t0**4 + t1**4 + t2**4
    T0, T1, T2 = e0 + e1 + e2, t0 * e0 + t1 * e1 + t2 * e2, t0 * t0 * e0 + t1 * t1 * e1 + t2 * t2 * e2
    alpha, beta, gamma, degenerate = _solve_normal3(S0, S1, S2, S3, S4, T0, T1, T2)
    return alpha / s**2, beta / s - 2 * alpha * m / s**2, alpha * m**2 / s**2 - beta * m / s + gamma, degenerate


@nb.njit(**JIT)
def radial_error_intercept(cal, i, a, b, c):
    """||p + u c(d) - g|| (eq. (24)) of calibration candidate i, c(d) = a d^2 + b d + c."""
    d = cal[0, i]
    shift = a * d * d + b * d + c
    return math.hypot(cal[1, i] + cal[3, i] * shift, cal[2, i] + cal[4, i] * shift)


@nb.njit(**PATH_JIT)
def regression_path_intercept(test, a, b, c):
    """Mean test-point error (m) after the intercept regression, as kernels.regression_paths (float32, units of
    1/FIXED m, fixed-point sum): |r + u c|^2 = |r|^2 + c (2 r.u + c), c = a d^2 + b d + c0."""
    n = test.shape[1]
    af, bf, cf = np.float32(a / FIXED), np.float32(b), np.float32(c * FIXED)
    total = np.int64(0)
    for t in range(n):
        d, rr, ru2 = test[0, t], test[1, t], test[2, t]
        shift = d * (af * d + bf) + cf
        qq = rr + shift * (ru2 + shift)
        total += to_fixed(math.sqrt(qq if qq > 0 else np.float32(0.0)))
    return total / FIXED / n


@nb.njit(inline="always", **JIT)
def _sq(x, y, w, gx, gy, hx, hy, hw, eps):
    """||H_eps(q) - g||^2 of one point from n = (x, y, w) = H (q, 1) and h = H[:, 1] (horizon_loss's terms)."""
    inv = 1.0 / (w + eps * hw)
    rx, ry = (x + eps * hx) * inv - gx, (y + eps * hy) * inv - gy
    return rx * rx + ry * ry


@nb.njit(**JIT)
def horizon_loss3(x0, y0, w0, gx0, gy0, x1, y1, w1, gx1, gy1, x2, y2, w2, gx2, gy2, hx, hy, hw, eps):
    """horizon_loss of homocal.correctors.horizon for three points: (x, y, w) = H (q_i, 1), g_i, h = H[:, 1];
    +inf if a point is on or beyond the horizon of H_eps."""
    if not (w0 + eps * hw > 0 and w1 + eps * hw > 0 and w2 + eps * hw > 0):
        return math.inf
    return (_sq(x0, y0, w0, gx0, gy0, hx, hy, hw, eps) + _sq(x1, y1, w1, gx1, gy1, hx, hy, hw, eps)
            + _sq(x2, y2, w2, gx2, gy2, hx, hy, hw, eps))


@nb.njit(inline="always", **JIT)
def _newton_terms(x, y, w, gx, gy, hx, hy, hw, eps):
    """(r.r', r'.r' + r.r'') of one point (horizon_loss_derivatives' terms)."""
    inv = 1.0 / (w + eps * hw)
    rx, ry = (x + eps * hx) * inv - gx, (y + eps * hy) * inv - gy
    r1x, r1y = (hx * w - x * hw) * (inv * inv), (hy * w - y * hw) * (inv * inv)
    r2x, r2y = -2.0 * hw * r1x * inv, -2.0 * hw * r1y * inv
    return rx * r1x + ry * r1y, (r1x * r1x + rx * r2x) + (r1y * r1y + ry * r2y)


@nb.njit(**JIT)
def fit_horizon_shift3(H, u0, v0, gx0, gy0, u1, v1, gx1, gy1, u2, v2, gx2, gy2):
    """(epsilon, delta) of fit_horizon_shift for three image points (u, v) px and their ground truth (gx, gy):
    the grid of GRID_INTERVALS over (-delta, delta] (first least), NEWTON_STEPS safeguarded Newton steps in the
    bracket around it, the result kept unless its loss is above the grid's best by FLAT. H (3, 3) the variant's
    image-to-ground homography (H[2, 1] > 0, every point below its horizon: NaN otherwise)."""
    hx, hy, hw = H[0, 1], H[1, 1], H[2, 1]
    x0, y0, w0 = H[0, 0] * u0 + hx * v0 + H[0, 2], H[1, 0] * u0 + hy * v0 + H[1, 2], H[2, 0] * u0 + hw * v0 + H[2, 2]
    x1, y1, w1 = H[0, 0] * u1 + hx * v1 + H[0, 2], H[1, 0] * u1 + hy * v1 + H[1, 2], H[2, 0] * u1 + hw * v1 + H[2, 2]
    x2, y2, w2 = H[0, 0] * u2 + hx * v2 + H[0, 2], H[1, 0] * u2 + hy * v2 + H[1, 2], H[2, 0] * u2 + hw * v2 + H[2, 2]
    P = (x0, y0, w0, gx0, gy0, x1, y1, w1, gx1, gy1, x2, y2, w2, gx2, gy2, hx, hy, hw)
    if not hw > 0:
        return math.nan, math.nan
    delta = min(w0, min(w1, w2)) / hw
    if not delta > 0:
        return math.nan, math.nan
    best, kbest = math.inf, 0
    for k in range(GRID_INTERVALS):
        f = horizon_loss3(*P, -delta + 2.0 * delta * (k + 1) / GRID_INTERVALS)
        if f < best:
            best, kbest = f, k
    a = -delta + 2.0 * delta * kbest / GRID_INTERVALS if kbest > 0 else -delta
    b = -delta + 2.0 * delta * (min(kbest + 1, GRID_INTERVALS - 1) + 1) / GRID_INTERVALS
    start = -delta + 2.0 * delta * (kbest + 1) / GRID_INTERVALS
    x = start
    for _ in range(NEWTON_STEPS):
        p0, q0 = _newton_terms(x0, y0, w0, gx0, gy0, hx, hy, hw, x)
        p1, q1 = _newton_terms(x1, y1, w1, gx1, gy1, hx, hy, hw, x)
        p2, q2 = _newton_terms(x2, y2, w2, gx2, gy2, hx, hy, hw, x)
        a, b, x, converged = _newton_step(a, b, x, 2.0 * (p0 + p1 + p2), 2.0 * (q0 + q1 + q2))
        if converged:
            break
    return (x if horizon_loss3(*P, x) <= (1.0 + FLAT) * best else start), delta


@nb.njit(**JIT)
def horizon_mean_error3(H, eps, u0, v0, gx0, gy0, u1, v1, gx1, gy1, u2, v2, gx2, gy2):
    """Mean Euclidean calibration error (eq. (25)'s L) of the horizon-corrected mapping H . row_shift(eps) on
    three points: HorizonCorrector.error_after_."""
    total = 0.0
    for u, v, gx, gy in ((u0, v0, gx0, gy0), (u1, v1, gx1, gy1), (u2, v2, gx2, gy2)):
        x = H[0, 0] * u + H[0, 1] * (v + eps) + H[0, 2]
        y = H[1, 0] * u + H[1, 1] * (v + eps) + H[1, 2]
        w = H[2, 0] * u + H[2, 1] * (v + eps) + H[2, 2]
        total += math.hypot(x / w - gx, y / w - gy)
    return total / 3.0


@nb.njit(**JIT)
def horizon_homography_into(H, eps, out):
    """Write into out (3, 3) the corrected homography H . row_shift(eps), unit Frobenius norm (HorizonCorrector.m,
    there formed from the trapezoid moved eps px up): column 2 becomes H[:, 1] eps + H[:, 2]."""
    ss = 0.0
    for r in range(3):
        out[r, 0], out[r, 1], out[r, 2] = H[r, 0], H[r, 1], H[r, 1] * eps + H[r, 2]
        ss += out[r, 0] ** 2 + out[r, 1] ** 2 + out[r, 2] ** 2
    norm = math.sqrt(ss)
    for r in range(3):
        for m in range(3):
            out[r, m] /= norm

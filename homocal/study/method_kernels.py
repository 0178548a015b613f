"""Compiled kernels of the two correctors beyond the paper, for the study's per-sample loop: regression with an
intercept (homocal.correctors.regression.fit_quadratic_intercept) and the horizon correction
(homocal.correctors.horizon.fit_horizon_shift). Plain scalar functions of one calibration triple, the same
algorithm, iteration counts and tolerances as the readable correctors (tests/homocal/test_method_kernels.py
checks them decision for decision). Conventions as homocal.study.kernels: cal table rows d, rx, ry, ux, uy,
e_faithful, e_signed; test-point lengths in units of 2^-26 m (kernels.FIXED).

Use in a per-sample loop (i, j, k the triple, H0 the variant's homography, q (M, 2) image and g (M, 2) ground
calibration points)::

    a, b, c, _ = fit_quadratic_intercept3(cal[0, i], cal[0, j], cal[0, k], cal[6, i], cal[6, j], cal[6, k])
    cal_after = (radial_error_intercept(cal, i, a, b, c) + ... j ... + ... k ...) / 3
    path_after = regression_path_intercept(test, a, b, c)
    eps, delta = fit_horizon_shift3(H0, q[i, 0], q[i, 1], g[i, 0], g[i, 1], ... j ..., ... k ...)
    horizon_homography_into(H0, eps, Hh)        # then dH = Hh - H0 into kernels.descent_path, as descent's
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from homocal.correctors.horizon import FLAT, GOLDEN_ITERATIONS, GRID_INTERVALS, INV_PHI, NEWTON_STEPS
from homocal.study.kernels import FIXED, JIT, PATH_JIT, _fixed


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
    det = S4 * (S2 * S0 - S1 * S1) - S3 * (S3 * S0 - S1 * S2) + S2 * (S3 * S1 - S2 * S2)
    degenerate = not det > 1e-12 * S4 * S2 * S0
    if not degenerate:
        alpha = (T2 * (S2 * S0 - S1 * S1) - S3 * (T1 * S0 - S1 * T0) + S2 * (T1 * S1 - S2 * T0)) / det
        beta = (S4 * (T1 * S0 - S1 * T0) - T2 * (S3 * S0 - S1 * S2) + S2 * (S3 * T0 - T1 * S2)) / det
        gamma = (S4 * (S2 * T0 - T1 * S1) - S3 * (S3 * T0 - T1 * S2) + T2 * (S3 * S1 - S2 * S2)) / det
    else:
        alpha = 0.0
        det2 = S2 * S0 - S1 * S1
        if det2 > 1e-12 * S2 * S0:
            beta, gamma = (T1 * S0 - S1 * T0) / det2, (S2 * T0 - S1 * T1) / det2
        else:
            beta, gamma = 0.0, T0 / S0
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
    2^-26 m, fixed-point sum): |r + u c|^2 = |r|^2 + c (2 r.u + c), c = a d^2 + b d + c0."""
    n = test.shape[1]
    af, bf, cf = np.float32(a / FIXED), np.float32(b), np.float32(c * FIXED)
    total = np.int64(0)
    for t in range(n):
        d, rr, ru2 = test[0, t], test[1, t], test[2, t]
        shift = d * (af * d + bf) + cf
        qq = rr + shift * (ru2 + shift)
        total += _fixed(math.sqrt(qq if qq > 0 else np.float32(0.0)))
    return total / FIXED / n


@nb.njit(inline="always", **JIT)
def _point_sq(H, m2, eps, u, v, gx, gy):
    """||H_eps(u, v) - g||^2 with M = H . row_shift(eps) (m2 = ||M[2]||), +inf on or beyond the horizon by
    apply_homography's rule (w <= 1e-12 (|u| + |v| + 1) ||M[2]||)."""
    x = H[0, 0] * u + H[0, 1] * v + (H[0, 1] * eps + H[0, 2])
    y = H[1, 0] * u + H[1, 1] * v + (H[1, 1] * eps + H[1, 2])
    w = H[2, 0] * u + H[2, 1] * v + (H[2, 1] * eps + H[2, 2])
    if not w > 1e-12 * (abs(u) + abs(v) + 1.0) * m2:
        return math.inf
    rx, ry = x / w - gx, y / w - gy
    return rx * rx + ry * ry


@nb.njit(**JIT)
def horizon_loss3(H, eps, u0, v0, gx0, gy0, u1, v1, gx1, gy1, u2, v2, gx2, gy2):
    """horizon_loss of homocal.correctors.horizon for three points: sum ||H_eps(q_i) - g_i||^2, +inf beyond."""
    m2 = math.sqrt(H[2, 0] ** 2 + H[2, 1] ** 2 + (H[2, 1] * eps + H[2, 2]) ** 2)
    return (_point_sq(H, m2, eps, u0, v0, gx0, gy0) + _point_sq(H, m2, eps, u1, v1, gx1, gy1)
            + _point_sq(H, m2, eps, u2, v2, gx2, gy2))


@nb.njit(inline="always", **JIT)
def _gauss_newton_terms(H, eps, u, v, gx, gy):
    """(r.J, J.J) of one point: r = H_eps(q) - g, J = dr/deps = (h_xy w - n h_w) / w^2, h = H[:, 1]."""
    x = H[0, 0] * u + H[0, 1] * v + (H[0, 1] * eps + H[0, 2])
    y = H[1, 0] * u + H[1, 1] * v + (H[1, 1] * eps + H[1, 2])
    w = H[2, 0] * u + H[2, 1] * v + (H[2, 1] * eps + H[2, 2])
    jx = (H[0, 1] * w - x * H[2, 1]) / (w * w)
    jy = (H[1, 1] * w - y * H[2, 1]) / (w * w)
    return (x / w - gx) * jx + (y / w - gy) * jy, jx * jx + jy * jy


@nb.njit(**JIT)
def fit_horizon_shift3(H, u0, v0, gx0, gy0, u1, v1, gx1, gy1, u2, v2, gx2, gy2):
    """(epsilon, delta) of fit_horizon_shift for three image points (u, v) px and their ground truth (gx, gy):
    the grid of GRID_INTERVALS over (-delta, delta] (first least), GOLDEN_ITERATIONS of golden section on the
    bracket around it, NEWTON_STEPS Gauss-Newton steps kept if inside the range and not higher by FLAT. H (3, 3) the
    variant's image-to-ground homography (H[2, 1] > 0, every point below its horizon: NaN otherwise)."""
    if not H[2, 1] > 0:
        return math.nan, math.nan
    w0 = H[2, 0] * u0 + H[2, 1] * v0 + H[2, 2]
    w1 = H[2, 0] * u1 + H[2, 1] * v1 + H[2, 2]
    w2 = H[2, 0] * u2 + H[2, 1] * v2 + H[2, 2]
    delta = min(w0, min(w1, w2)) / H[2, 1]
    if not delta > 0:
        return math.nan, math.nan
    eps, best, kbest = -delta + 2.0 * delta / GRID_INTERVALS, math.inf, 0
    for k in range(GRID_INTERVALS):
        e = -delta + 2.0 * delta * (k + 1) / GRID_INTERVALS
        f = horizon_loss3(H, e, u0, v0, gx0, gy0, u1, v1, gx1, gy1, u2, v2, gx2, gy2)
        if f < best:
            eps, best, kbest = e, f, k
    a = -delta + 2.0 * delta * kbest / GRID_INTERVALS if kbest > 0 else -delta
    b = -delta + 2.0 * delta * (min(kbest + 1, GRID_INTERVALS - 1) + 1) / GRID_INTERVALS
    c, d = b - INV_PHI * (b - a), a + INV_PHI * (b - a)
    fc = horizon_loss3(H, c, u0, v0, gx0, gy0, u1, v1, gx1, gy1, u2, v2, gx2, gy2)
    fd = horizon_loss3(H, d, u0, v0, gx0, gy0, u1, v1, gx1, gy1, u2, v2, gx2, gy2)
    for _ in range(GOLDEN_ITERATIONS):
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - INV_PHI * (b - a)
            fc = horizon_loss3(H, c, u0, v0, gx0, gy0, u1, v1, gx1, gy1, u2, v2, gx2, gy2)
        else:
            a, c, fc = c, d, fd
            d = a + INV_PHI * (b - a)
            fd = horizon_loss3(H, d, u0, v0, gx0, gy0, u1, v1, gx1, gy1, u2, v2, gx2, gy2)
    golden, f_golden = (c, fc) if fc <= fd else (d, fd)
    if f_golden < best:
        eps, best = golden, f_golden
    for _ in range(NEWTON_STEPS):
        rj0, jj0 = _gauss_newton_terms(H, eps, u0, v0, gx0, gy0)
        rj1, jj1 = _gauss_newton_terms(H, eps, u1, v1, gx1, gy1)
        rj2, jj2 = _gauss_newton_terms(H, eps, u2, v2, gx2, gy2)
        jj = jj0 + jj1 + jj2
        if not jj > 0:
            break
        cand = eps - (rj0 + rj1 + rj2) / jj
        f_cand = math.inf
        if -delta < cand <= delta:
            f_cand = horizon_loss3(H, cand, u0, v0, gx0, gy0, u1, v1, gx1, gy1, u2, v2, gx2, gy2)
        if f_cand <= (1.0 + FLAT) * best:
            eps, best = cand, f_cand
    return eps, delta


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

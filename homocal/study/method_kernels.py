"""Compiled kernels of the three correctors beyond the paper, for the study's per-sample loop: regression with an
intercept (homocal.correctors.regression.fit_quadratic_intercept), the horizon correction
(homocal.correctors.horizon.fit_horizon_shift) and least change (LeastChangeCorrector, least_change3). Plain
functions of one calibration triple, the same algorithm, iteration counts and tolerances as the readable
correctors; tests/study/test_method_kernels.py checks that their results agree to 1e-9 (rounding-level ties
aside, every decision is the same; where one is not, both still converge to the same minimum). Least change
stops on a relative decrease of its objective far above rounding, so both take the same steps and their quads
agree to 1e-6 px. Conventions as homocal.study.kernels: the cal and test tables' rows named in homocal.study.rows;
test-point lengths in units of 1/FIXED m (jit.FIXED).

Use in a per-sample loop (i, j, k the triple, H0 the variant's homography, q (M, 2) image and g (M, 2) ground
calibration points)::

    a, b, c, _ = fit_quadratic_intercept3(cal[CAL_D, i], ... j ..., ... k ..., cal[CAL_E_SIGNED, i], ... j ..., ... k ...)
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
from homocal.correctors.least_change import MAX_HALVINGS, OBJECTIVE_TOLERANCE
from homocal.correctors.regression import solve_normal3
from homocal.study.frame import quad_frame
from homocal.study.jit import FIXED, JIT, PATH_JIT, fixed_point_mean
from homocal.study.rows import CAL_D, CAL_RX, CAL_RY, CAL_UX, CAL_UY, TEST_D, TEST_RR, TEST_RU2

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
    d = cal[CAL_D, i]
    shift = a * d * d + b * d + c
    return math.hypot(cal[CAL_RX, i] + cal[CAL_UX, i] * shift, cal[CAL_RY, i] + cal[CAL_UY, i] * shift)


@nb.njit(inline="always", **PATH_JIT)
def _radial_intercept32(test, t, abc):
    """kernels._radial32 with an intercept: c(d) = a d^2 + b d + c, (a, b, c) = abc."""
    a, b, c = abc
    d = test[TEST_D, t]
    shift = d * (a * d + b) + c
    q = test[TEST_RR, t] + shift * (test[TEST_RU2, t] + shift)
    return math.sqrt(np.float32(0.0) if q < 0 else q), True


@nb.njit(**PATH_JIT)
def regression_path_intercept(test, a, b, c):
    """Mean test-point error (m) after the intercept regression, as kernels.regression_path (float32, units of
    1/FIXED m, jit.fixed_point_mean: exact at any size, NaN if a point error is not finite): |r + u c|^2 =
    |r|^2 + c (2 r.u + c), c = a d^2 + b d + c0."""
    return fixed_point_mean(_radial_intercept32, test, (np.float32(a / FIXED), np.float32(b), np.float32(c * FIXED)))


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


# ---- least change (homocal.correctors.least_change): the MAP correction of both clicked trapezoids

@nb.njit(**JIT)
def _basis_into(z, o, out):
    """The projective basis B = P diag(lam) of the quad z[o:o + 8] (x, y of TL, TR, BR, BL) into out (13,): the rows
    n_k of N at 0-8 (P^-1 = N / det, P = [p0 p1 p2] homogeneous vertices as columns), lam = N p3 / det at 9-11
    (P lam = p3), det at 12 (quad_frame). Returns validate_quad's test."""
    a0, a1, a2, b0, b1, b2, e0, e1, e2, d0, d1, d2, det, valid = quad_frame(
        z[o], z[o + 1], z[o + 2], z[o + 3], z[o + 4], z[o + 5], z[o + 6], z[o + 7])
    out[0], out[1], out[2], out[3], out[4], out[5], out[6], out[7], out[8] = a0, a1, a2, b0, b1, b2, e0, e1, e2
    out[9], out[10], out[11], out[12] = d0 / det, d1 / det, d2 / det, det
    return valid


@nb.njit(**JIT)
def _usable(z, bs, bt, sign_s, sign_t):
    """Fill the bases bs, bt (13,) of the image quad z[:8] and the map quad z[8:]; True if both pass validate_quad's
    test and keep the orientation (sign of det) of the clicked quads, sign_s and sign_t (predicted_points' checks)."""
    return _basis_into(z, 0, bs) and _basis_into(z, 8, bt) and bs[12] * sign_s > 0 and bt[12] * sign_t > 0


@nb.njit(inline="always", **JIT)
def _map_point(z, bs, bt, u, v, y, X):
    """y = B_s^-1 (u, v, 1) (3,) and X = B_t y (3,), unnormalised homogeneous (w = 1 at the fourth vertex; the point
    is in front of the horizon iff X[2] > 0, the kernels' rule, see kernels' docstring)."""
    for k in range(3):
        y[k] = (bs[3 * k] * u + bs[3 * k + 1] * v + bs[3 * k + 2]) / (bs[9 + k] * bs[12])
    X[0] = X[1] = X[2] = 0.0
    for k in range(3):
        c = bt[9 + k] * y[k]
        X[0] += c * z[8 + 2 * k]
        X[1] += c * z[9 + 2 * k]
        X[2] += c


@nb.njit(**JIT)
def _phi(x, z, bs, bt, q, g, point_sigma, y, X):
    """Phi(x) = ||x||^2 + sum_i ||g_i - f_i||^2 / point_sigma^2 (least_change.objective) for quads z with bases bs,
    bt; +inf if a point q_i (3, 2) maps on or beyond the horizon."""
    total = 0.0
    for i in range(3):
        _map_point(z, bs, bt, q[i, 0], q[i, 1], y, X)
        if not X[2] > 0.0:
            return math.inf
        rx, ry = g[i, 0] - X[0] / X[2], g[i, 1] - X[1] / X[2]
        total += rx * rx + ry * ry
    prior = 0.0
    for c in range(16):
        prior += x[c] * x[c]
    return prior + total / (point_sigma * point_sigma)


@nb.njit(**JIT)
def _jacobian_into(z, bs, bt, q, g, sigma, J, r, y, X, H, dB):
    """J (6, 16) = df/dx at quads z (least_change.mapped_jacobian times sigma), rows 2 i + (x, y) of point i, and the
    residuals r (6,) = g - f. With y = B_s^-1 (q, 1) and W_k = P Pinv[:, k] o y (each quad's P, Pinv = N / det),
    a quad's dB y for its vertex j, coordinate k is lam_j (y_j e_k - W_k) (j < 3) or W_k (j = 3); a map
    coordinate moves X = B_t y by dB_t y, an image one by -H dB_s y (H = B_t B_s^-1); df = (dX_xy - f dX_w) / X_w.
    H (3, 3) and dB (16, 3): scratch."""
    for a in range(3):
        for c in range(3):
            s = 0.0
            for k in range(3):
                pk = z[8 + 2 * k + a] if a < 2 else 1.0
                s += pk * bt[9 + k] * bs[3 * k + c] / (bs[9 + k] * bs[12])
            H[a, c] = s
    for i in range(3):
        _map_point(z, bs, bt, q[i, 0], q[i, 1], y, X)
        fx, fy = X[0] / X[2], X[1] / X[2]
        r[2 * i], r[2 * i + 1] = g[i, 0] - fx, g[i, 1] - fy
        for quad in range(2):
            b, o = (bs, 0) if quad == 0 else (bt, 8)
            for k in range(2):
                W0 = W1 = W2 = 0.0
                for m in range(3):
                    c = b[3 * m + k] / b[12] * y[m]
                    W0 += z[o + 2 * m] * c
                    W1 += z[o + 2 * m + 1] * c
                    W2 += c
                for j in range(3):
                    lj = b[9 + j]
                    dB[o + 2 * j + k, 0] = lj * ((y[j] if k == 0 else 0.0) - W0)
                    dB[o + 2 * j + k, 1] = lj * ((y[j] if k == 1 else 0.0) - W1)
                    dB[o + 2 * j + k, 2] = -lj * W2
                dB[o + 6 + k, 0], dB[o + 6 + k, 1], dB[o + 6 + k, 2] = W0, W1, W2
        for c in range(16):
            if c < 8:
                d0 = -(H[0, 0] * dB[c, 0] + H[0, 1] * dB[c, 1] + H[0, 2] * dB[c, 2])
                d1 = -(H[1, 0] * dB[c, 0] + H[1, 1] * dB[c, 1] + H[1, 2] * dB[c, 2])
                d2 = -(H[2, 0] * dB[c, 0] + H[2, 1] * dB[c, 1] + H[2, 2] * dB[c, 2])
            else:
                d0, d1, d2 = dB[c, 0], dB[c, 1], dB[c, 2]
            J[2 * i, c] = (d0 - fx * d2) / X[2] * sigma[c]
            J[2 * i + 1, c] = (d1 - fy * d2) / X[2] * sigma[c]


@nb.njit(**JIT)
def _gauss_newton_into(x, J, r, point_sigma, A, b, out):
    """out (16,) = J^T (J J^T + point_sigma^2 I)^-1 (r + J x) (least_change.gauss_newton_step), the 6 x 6 system
    solved by Cholesky (symmetric positive definite) in the lower triangle of the scratch A (6, 6), b (6,) (plain
    loops: numba's matmul on arrays this small costs more in calls and allocations than in arithmetic)."""
    for i in range(6):
        s = r[i]
        for c in range(16):
            s += J[i, c] * x[c]
        b[i] = s
        for j in range(i + 1):
            s = 0.0
            for c in range(16):
                s += J[i, c] * J[j, c]
            A[i, j] = s
        A[i, i] += point_sigma * point_sigma
    for i in range(6):  # A = L L^T in place (lower triangle)
        for j in range(i + 1):
            s = A[i, j]
            for k in range(j):
                s -= A[i, k] * A[j, k]
            A[i, j] = math.sqrt(s) if i == j else s / A[j, j]
    for i in range(6):  # L w = b
        s = b[i]
        for k in range(i):
            s -= A[i, k] * b[k]
        b[i] = s / A[i, i]
    for i in range(5, -1, -1):  # L^T u = w
        s = b[i]
        for k in range(i + 1, 6):
            s -= A[k, i] * b[k]
        b[i] = s / A[i, i]
    for c in range(16):
        s = 0.0
        for i in range(6):
            s += J[i, c] * b[i]
        out[c] = s


@nb.njit(**JIT)
def least_change3(z0, q, g, click_sigma, map_sigma, point_sigma, iterations, z, Bt):
    """LeastChangeCorrector.fit on three points: from the clicked quads z0 (16,) (image quad px then map quad m, x, y
    of TL, TR, BR, BL), image points q (3, 2) px and ground points g (3, 2) m, write the corrected quads into
    z (16,) and the corrected map quad's basis into Bt (3, 3) (kernels.target_basis of it, for homography_into);
    return (Gauss-Newton steps accepted, Phi at the end). The same iteration as the readable corrector:
    at most ``iterations`` steps; each tried at full length, then halved up to MAX_HALVINGS times until both quads
    are usable (_usable, every point in front) and Phi does not rise; taken only if it lowers Phi by more than
    OBJECTIVE_TOLERANCE of it, else the fit stops. z0's quads must be usable (the variant's)."""
    sigma = np.empty(16)
    sigma[:8], sigma[8:] = click_sigma, map_sigma
    bs, bt, y, X = np.empty(13), np.empty(13), np.empty(3), np.empty(3)
    J, r, step, x, xc = np.empty((6, 16)), np.empty(6), np.empty(16), np.zeros(16), np.empty(16)
    H, dB, A, b = np.empty((3, 3)), np.empty((16, 3)), np.empty((6, 6)), np.empty(6)
    _basis_into(z0, 0, bs)
    _basis_into(z0, 8, bt)
    sign_s, sign_t = bs[12], bt[12]
    z[:] = z0
    phi = _phi(x, z, bs, bt, q, g, point_sigma, y, X)
    steps = 0
    for _ in range(iterations):  # bs, bt hold the bases of z, the accepted iterate (its _usable call filled them)
        _jacobian_into(z, bs, bt, q, g, sigma, J, r, y, X, H, dB)
        _gauss_newton_into(x, J, r, point_sigma, A, b, step)
        step -= x
        accepted, value = False, math.inf
        for h in range(MAX_HALVINGS + 1):
            scale = 0.5**h  # a power of two: step * scale == step / 2**h exactly
            for c in range(16):
                xc[c] = x[c] + step[c] * scale
                z[c] = z0[c] + sigma[c] * xc[c]
            value = _phi(xc, z, bs, bt, q, g, point_sigma, y, X) if _usable(z, bs, bt, sign_s, sign_t) else math.inf
            if value <= phi:
                accepted = True
                break
        if not accepted or phi - value <= OBJECTIVE_TOLERANCE * phi:
            for c in range(16):
                z[c] = z0[c] + sigma[c] * x[c]
            break
        x[:] = xc
        phi = value
        steps += 1
    _basis_into(z, 8, bt)
    for k in range(3):
        Bt[0, k], Bt[1, k], Bt[2, k] = z[8 + 2 * k] * bt[9 + k], z[9 + 2 * k] * bt[9 + k], bt[9 + k]
    return steps, phi


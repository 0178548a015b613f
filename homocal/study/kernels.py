"""The study's compiled kernels: a second implementation of the correctors' maths (homocal.correctors),
per trapezoid variant, over every calibration triple, in parallel.

Closed-form homography (the projective-basis construction of homocal.geometry): for an image quad
p0..p3 (homogeneous, w = 1) let n_k = p_{k+1} x p_{k+2} (indices mod 3) and d_k = n_k . p3. Then
B_s^-1 = diag(1 / d) N (N rows n_k) and, multiplying by D = d0 d1 d2,
    H' = B_t diag(c) N,   c = (d1 d2, d0 d2, d0 d1),   H = H' / D,
so H' needs no division and has the sign of D: a point q maps beyond the horizon iff (H' q)_w D <= 0.
The quad passes validate_quad iff det[p0 p1 p2], d0, -d1, d2 (its four consecutive-vertex triangles)
have one sign and each exceeds 1e-9 scale^2 (scale = largest side of its bounding box).
Errors against a ground point g use F = [B_t0 - g_x B_t2; B_t1 - g_y B_t2; B_t2] (3, 3):
    (X, Y, W) = F diag(c) N q,   ||H(q) - g|| = sqrt(X^2 + Y^2) / |W|.

Differences from the readable correctors, all below any decision: the loss is summed in another order
(1e-15 relative), and the horizon test is on the sign only (apply_homography also rejects w within
1e-12 relative of zero). Path errors over the test points are float32 in residual form (about 1e-7 m).
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from homocal.keyed_rng import shuffled_order, splitmix64

JIT = dict(cache=True, error_model="numpy")
# float sums over test points may be reordered (vectorised); everything else keeps IEEE order
JIT_SUM = dict(cache=True, error_model="numpy", fastmath={"reassoc", "nsz", "contract"})

METHODS = ("regression", "regression_signed", "descent", "hybrid")


@nb.njit(inline="always", **JIT)
def _max(a, b):
    return a if a > b else b


@nb.njit(inline="always", **JIT)
def _min(a, b):
    return a if a < b else b


@nb.njit(inline="always", **JIT)
def frame(x0, y0, x1, y1, x2, y2, x3, y3):
    """Projective frame of an image quad: (n0, n1, n2 as 9 scalars, c0, c1, c2, D, valid)."""
    a0, a1, a2 = y1 - y2, x2 - x1, x1 * y2 - x2 * y1  # n0 = p1 x p2
    b0, b1, b2 = y2 - y0, x0 - x2, x2 * y0 - x0 * y2  # n1 = p2 x p0
    e0, e1, e2 = y0 - y1, x1 - x0, x0 * y1 - x1 * y0  # n2 = p0 x p1
    d0 = a0 * x3 + a1 * y3 + a2  # det[p1 p2 p3]
    d1 = b0 * x3 + b1 * y3 + b2  # det[p2 p0 p3] = -det[p2 p3 p0]
    d2 = e0 * x3 + e1 * y3 + e2  # det[p0 p1 p3] = det[p3 p0 p1]
    det = a0 * x0 + a1 * y0 + a2  # det[p0 p1 p2]
    sx = _max(_max(x0, x1), _max(x2, x3)) - _min(_min(x0, x1), _min(x2, x3))
    sy = _max(_max(y0, y1), _max(y2, y3)) - _min(_min(y0, y1), _min(y2, y3))
    scale = _max(sx, sy)
    tol = 1e-9 * (scale * scale)
    pos = det > 0
    valid = ((_min(_min(abs(det), abs(d0)), _min(abs(d1), abs(d2))) > tol) & (pos == (d0 > 0)) & (pos == (d1 < 0))
             & (pos == (d2 > 0)))
    return a0, a1, a2, b0, b1, b2, e0, e1, e2, d1 * d2, d0 * d2, d0 * d1, d0 * d1 * d2, valid


@nb.njit(inline="always", **JIT)
def point_error(a0, a1, a2, b0, b1, b2, e0, e1, e2, c0, c1, c2, D, f0, f1, f2, f3, f4, f5, f6, f7, f8, u, v):
    """||H(q) - g|| for image point q = (u, v) and the F (9 scalars) of its ground point g; +inf beyond the horizon."""
    l0 = c0 * (a0 * u + a1 * v + a2)
    l1 = c1 * (b0 * u + b1 * v + b2)
    l2 = c2 * (e0 * u + e1 * v + e2)
    X = f0 * l0 + f1 * l1 + f2 * l2
    Y = f3 * l0 + f4 * l1 + f5 * l2
    W = f6 * l0 + f7 * l1 + f8 * l2
    e = math.sqrt(X * X + Y * Y) / abs(W)
    return e if W * D > 0.0 else math.inf


@nb.njit(**JIT)
def homography(v, Bt):
    """(3, 3) image-to-target homography of image quad v (8,) and target basis Bt (3, 3), unit Frobenius
    norm, w > 0 on the quad (as homocal.geometry.homography_from_quads)."""
    a0, a1, a2, b0, b1, b2, e0, e1, e2, c0, c1, c2, D, valid = frame(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7])
    N = np.array([[a0, a1, a2], [b0, b1, b2], [e0, e1, e2]])
    c = np.array([c0, c1, c2])
    H = Bt @ (c[:, None] * N)
    H *= math.copysign(1.0, D) / math.sqrt(np.sum(H * H))
    return H


@nb.njit(**JIT)
def target_basis(T):
    """(3, 3) B_t mapping e1, e2, e3, (1, 1, 1) to the target quad T (4, 2) (homogeneous, w = 1 at T3)."""
    P = np.ones((3, 3))
    P[:2, :] = T[:3].T
    lam = np.linalg.solve(P, np.array([T[3, 0], T[3, 1], 1.0]))
    return P * lam[None, :]


@nb.njit(**JIT)
def ground_frames(Bt, ground):
    """F (M, 9) per ground point (M, 2): rows B_t0 - g_x B_t2, B_t1 - g_y B_t2, B_t2, flattened."""
    F = np.empty((ground.shape[0], 9))
    for i in range(ground.shape[0]):
        for m in range(3):
            F[i, m] = Bt[0, m] - ground[i, 0] * Bt[2, m]
            F[i, 3 + m] = Bt[1, m] - ground[i, 1] * Bt[2, m]
            F[i, 6 + m] = Bt[2, m]
    return F


@nb.njit(**JIT)
def grid_table(v0, grid, F, q):
    """Phase-1 table (M, G^4): error of calibration candidate i under the grid trapezoid of cell g, v0 + offsets
    on coordinates 0, 1, 4, 5 in itertools.product(grid, repeat=4) order; +inf if invalid (eq. (25) terms)."""
    G = grid.shape[0]
    M = q.shape[0]
    table = np.empty((M, G**4))
    for g in range(G**4):
        x0 = v0[0] + grid[g // G**3]
        y0 = v0[1] + grid[(g // G**2) % G]
        x2 = v0[4] + grid[(g // G) % G]
        y2 = v0[5] + grid[g % G]
        a0, a1, a2, b0, b1, b2, e0, e1, e2, c0, c1, c2, D, valid = frame(x0, y0, v0[2], v0[3], x2, y2, v0[6], v0[7])
        for i in range(M):
            e = point_error(a0, a1, a2, b0, b1, b2, e0, e1, e2, c0, c1, c2, D, F[i, 0], F[i, 1], F[i, 2], F[i, 3],
                            F[i, 4], F[i, 5], F[i, 6], F[i, 7], F[i, 8], q[i, 0], q[i, 1])
            table[i, g] = e if valid else math.inf
    return table


@nb.njit(**JIT)
def eval_batch(X, n, F3, q3, out):
    """Eq. (25) losses of n candidate quads X[:, m] (8, >= n); F3 (3, 9), q3 (3, 2) of the triple.
    Straight-line per candidate (scalars, selects) so the loop vectorises over candidates."""
    f00, f01, f02, f03, f04, f05, f06, f07, f08 = F3[0, 0], F3[0, 1], F3[0, 2], F3[0, 3], F3[0, 4], F3[0, 5], F3[0, 6], F3[0, 7], F3[0, 8]
    f10, f11, f12, f13, f14, f15, f16, f17, f18 = F3[1, 0], F3[1, 1], F3[1, 2], F3[1, 3], F3[1, 4], F3[1, 5], F3[1, 6], F3[1, 7], F3[1, 8]
    f20, f21, f22, f23, f24, f25, f26, f27, f28 = F3[2, 0], F3[2, 1], F3[2, 2], F3[2, 3], F3[2, 4], F3[2, 5], F3[2, 6], F3[2, 7], F3[2, 8]
    u0, v0, u1, v1, u2, v2 = q3[0, 0], q3[0, 1], q3[1, 0], q3[1, 1], q3[2, 0], q3[2, 1]
    for m in range(n):
        a0, a1, a2, b0, b1, b2, e0, e1, e2, c0, c1, c2, D, valid = frame(
            X[0, m], X[1, m], X[2, m], X[3, m], X[4, m], X[5, m], X[6, m], X[7, m])
        s = (point_error(a0, a1, a2, b0, b1, b2, e0, e1, e2, c0, c1, c2, D, f00, f01, f02, f03, f04, f05, f06, f07, f08, u0, v0)
             + point_error(a0, a1, a2, b0, b1, b2, e0, e1, e2, c0, c1, c2, D, f10, f11, f12, f13, f14, f15, f16, f17, f18, u1, v1)
             + point_error(a0, a1, a2, b0, b1, b2, e0, e1, e2, c0, c1, c2, D, f20, f21, f22, f23, f24, f25, f26, f27, f28, u2, v2))
        out[m] = s / 3.0 if valid else math.inf


@nb.njit(**JIT)
def descend(v0, v, L, F3, q3, seed, step, min_step, delta_max, max_evals, order, kc, dl, X, lc):
    """Phase 2 of DescentCorrector from v (8,) (modified in place) with loss L; returns (L, evals).

    Each pass shuffles the coordinates with shuffled_order(seed, pass); the candidates left in the pass
    (relative to the current v) are evaluated together, then scanned in the corrector's order: skipped if
    beyond delta_max of v0, stop when evals == max_evals, accept the first that lowers L.
    """
    pass_index = 0
    evals = 0
    while True:
        shuffled_order(seed, pass_index, order)
        improved = False
        t = 0
        while t < 8:
            n = 0
            for tt in range(t, 8):
                for sgn in range(2):
                    kc[n] = order[tt]
                    dl[n] = step if sgn == 0 else -step
                    for c in range(8):
                        X[c, n] = v[c]
                    X[kc[n], n] += dl[n]
                    n += 1
            eval_batch(X, n, F3, q3, lc)
            accepted = -1
            for m in range(n):
                k = kc[m]
                if abs((v[k] + dl[m]) - v0[k]) > delta_max:
                    continue
                if evals == max_evals:
                    return L, evals
                evals += 1
                if lc[m] < L:
                    accepted = m
                    break
            if accepted < 0:
                break
            v[kc[accepted]] += dl[accepted]
            L = lc[accepted]
            improved = True
            t += accepted // 2 + 1
        pass_index += 1
        if not improved:
            step /= 2
            if step < min_step:
                return L, evals


@nb.njit(**JIT)
def fit_quadratic(d0, d1, d2, e0, e1, e2, faithful):
    """(a, b, degenerate) of eqs. (20)-(22) for three (d, e); faithful clamps a, b >= 0 independently."""
    S2 = d0 * d0 + d1 * d1 + d2 * d2
    S3 = d0**3 + d1**3 + d2**3
    S4 = d0**4 + d1**4 + d2**4
    T1 = d0 * e0 + d1 * e1 + d2 * e2
    T2 = d0 * d0 * e0 + d1 * d1 * e1 + d2 * d2 * e2
    det = S4 * S2 - S3 * S3
    degenerate = det <= 1e-12 * S4 * S2
    if degenerate:
        a, b = 0.0, T1 / S2
    else:
        a, b = (T2 * S2 - T1 * S3) / det, (S4 * T1 - S3 * T2) / det
    if faithful:
        a, b = max(a, 0.0), max(b, 0.0)
    return a, b, degenerate


@nb.njit(**JIT)
def radial_error(cal, i, a, b):
    """||p + u c - g|| (eq. (24)) of calibration candidate i, c = a d^2 + b d; cal rows d, rx, ry, ux, uy, ..."""
    d = cal[0, i]
    c = a * d * d + b * d
    return math.hypot(cal[1, i] + cal[3, i] * c, cal[2, i] + cal[4, i] * c)


@nb.njit(**JIT_SUM)
def regression_paths(test, af, bf, as_, bs):
    """Mean test-point error after both regressions, float32: |r + u c|^2 = |r|^2 + c (2 r.u + c).
    test rows 0-2: d, |r|^2, 2 r.u (N,)."""
    n = test.shape[1]
    af, bf, as_, bs = np.float32(af), np.float32(bf), np.float32(as_), np.float32(bs)
    sf = np.float32(0.0)
    ss = np.float32(0.0)
    for t in range(n):
        d, rr, ru2 = test[0, t], test[1, t], test[2, t]
        cf = d * (af * d + bf)
        cs = d * (as_ * d + bs)
        sf += math.sqrt(rr + cf * (ru2 + cf))
        ss += math.sqrt(rr + cs * (ru2 + cs))
    return sf / n, ss / n


@nb.njit(**JIT_SUM)
def descent_path(test, dH):
    """Mean test-point error of H0 + dH, float32, residual form: with s = t/w0 (H0 s = (p0, 1)) and r = p0 - g,
    H(t) - g = (r + dH01 s - g dH2 s) / (1 + dH2 s). test rows 3-9: s0, s1, s2, rx, ry, gx, gy; dH (9,)
    float32. NaN if a point crosses the horizon."""
    n = test.shape[1]
    total = np.float32(0.0)
    for t in range(n):
        s0, s1, s2 = test[3, t], test[4, t], test[5, t]
        dx = dH[0] * s0 + dH[1] * s1 + dH[2] * s2
        dy = dH[3] * s0 + dH[4] * s1 + dH[5] * s2
        dw = dH[6] * s0 + dH[7] * s1 + dH[8] * s2
        nx = test[6, t] + dx - test[8, t] * dw
        ny = test[7, t] + dy - test[9, t] * dw
        w = np.float32(1.0) + dw
        e = math.sqrt(nx * nx + ny * ny) / w
        total += e if w > 0 else np.float32(np.nan)
    return total / n


@nb.njit(**JIT)
def sample_seed_kernel(base, i, j, k):
    """seed_from_key(run_seed, scene, variant, i, j, k) from base = seed_from_key(run_seed, scene, variant)."""
    s = splitmix64(base ^ np.uint64(i))
    s = splitmix64(s ^ np.uint64(j))
    return splitmix64(s ^ np.uint64(k))


@nb.njit(**JIT)
def _improvement(before, after):
    return math.nan if before == 0.0 else 100.0 * (before - after) / before


@nb.njit(parallel=True, **JIT)
def run_variant(v0, Bt, H0, F, q, cal, test, path_before, I, J, K, base, grid, delta_max, initial_step, min_step,
                max_evals, threshold, out, ab, vfinal):
    """Every method on every triple (I, J, K) (S,) of one trapezoid variant.

    v0 (8,) image quad, Bt (3, 3) target basis, H0 (3, 3) = homography(v0, Bt); F (M, 9), q (M, 2) image
    calibration points; cal (7, M) of the mapped candidates p: d = |p - o|, r = p - g (2), u = (p - o)/d (2),
    faithful e = |p - g| (eq. (18)), signed e = |g - o| - |p - o|; test (10, N) float32 (see
    regression_paths, descent_path); path_before: mean test error (metres).
    Writes out (S, 10) float64: cal_before (m), then (cal, path) improvement (%) of each of the 4 METHODS,
    then 1.0 if hybrid chose regression; ab (S, 4): a, b faithful, a, b signed;
    vfinal (S, 9): descent's final trapezoid and its phase-2 evaluations.
    """
    table = grid_table(v0, grid, F, q)
    G4 = table.shape[1]
    S = I.shape[0]
    chunk = 64
    for c in nb.prange((S + chunk - 1) // chunk):
        order = np.empty(8, np.int64)
        kc = np.empty(16, np.int64)
        dl = np.empty(16)
        lc = np.empty(16)
        X = np.empty((8, 16))
        F3 = np.empty((3, 9))
        q3 = np.empty((3, 2))
        v = np.empty(8)
        dH = np.empty(9, np.float32)
        for s in range(c * chunk, min(S, (c + 1) * chunk)):
            i, j, k = I[s], J[s], K[s]
            # ---- regression, faithful and signed (eqs. (18)-(24))
            e_before = (cal[5, i] + cal[5, j] + cal[5, k]) / 3.0
            di, dj, dk = cal[0, i], cal[0, j], cal[0, k]
            af, bf, _ = fit_quadratic(di, dj, dk, cal[5, i], cal[5, j], cal[5, k], True)
            as_, bs, _ = fit_quadratic(di, dj, dk, cal[6, i], cal[6, j], cal[6, k], False)
            cal_f = _improvement(e_before, (radial_error(cal, i, af, bf) + radial_error(cal, j, af, bf)
                                            + radial_error(cal, k, af, bf)) / 3.0)
            cal_s = _improvement(e_before, (radial_error(cal, i, as_, bs) + radial_error(cal, j, as_, bs)
                                            + radial_error(cal, k, as_, bs)) / 3.0)
            path_f, path_s = regression_paths(test, af, bf, as_, bs)
            # ---- descent phase 1: the grid cell of least mean loss, first on ties
            best, gbest = math.inf, 0
            for g in range(G4):
                Lg = (table[i, g] + table[j, g] + table[k, g]) / 3.0
                if Lg < best:
                    best, gbest = Lg, g
            G = grid.shape[0]
            v[:] = v0
            v[0] += grid[gbest // G**3]
            v[1] += grid[(gbest // G**2) % G]
            v[4] += grid[(gbest // G) % G]
            v[5] += grid[gbest % G]
            # ---- descent phase 2
            F3[0] = F[i]
            F3[1] = F[j]
            F3[2] = F[k]
            q3[0] = q[i]
            q3[1] = q[j]
            q3[2] = q[k]
            seed = sample_seed_kernel(base, i, j, k)
            L, evals = descend(v0, v, best, F3, q3, seed, initial_step, min_step, delta_max, max_evals, order, kc, dl, X, lc)
            cal_d = _improvement(e_before, L)
            Hd = homography(v, Bt)
            for m in range(9):
                dH[m] = np.float32(Hd.flat[m] - H0.flat[m])
            path_d = descent_path(test, dH)
            # ---- outputs
            hyb = cal_f >= threshold
            out[s, 0] = e_before
            out[s, 1], out[s, 2] = cal_f, _improvement(path_before, path_f)
            out[s, 3], out[s, 4] = cal_s, _improvement(path_before, path_s)
            out[s, 5], out[s, 6] = cal_d, _improvement(path_before, path_d)
            out[s, 7] = cal_f if hyb else cal_d
            out[s, 8] = out[s, 2] if hyb else out[s, 6]
            out[s, 9] = 1.0 if hyb else 0.0
            ab[s, 0], ab[s, 1], ab[s, 2], ab[s, 3] = af, bf, as_, bs
            vfinal[s, :8] = v
            vfinal[s, 8] = evals

"""The study's compiled kernels: a second implementation of the correctors' maths (homocal.correctors),
per trapezoid variant, over every calibration triple (one call per variant, GIL released: the engine runs
variants side by side on all cores).

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
(1e-15 relative), and the horizon test is on the sign of w only (point_error, descent_path), where
homocal.geometry.apply_homography rejects w <= 1e-12 (|x| + |y| + 1) |H[2]|. The two differ only for a point
within 1e-12 relative of the horizon, which the kernels map ~1e12 scene sizes away instead of rejecting: such
a candidate's loss is far above the current one (at most the loss of v0, which is a scene-sized distance:
a variant whose calibration points do not map inside the horizon is degenerate and never run), so it is
rejected either way and no decision changes; matching the rule exactly would cost |H[2]| per candidate (a
3-vector and a norm, an estimated ~15 % of an evaluation). Path errors over the test points are float32 in
residual form (about 1e-7 m), their multiply-adds fused (fastmath "contract": FMA where the CPU has it, 10-20 %
faster; no decision depends on them), summed exactly in fixed point (the same bits in every
compilation on one machine, whatever the vectorisation).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from homocal.correctors.catalogue import STUDY_COLUMNS
from homocal.correctors.descent import within_reach
from homocal.keyed_rng import packed_order, splitmix64
from homocal.study import method_kernels as mk
from homocal.study.frame import frame, min2
from homocal.study.jit import FIXED, JIT, PATH_JIT, fixed_point_mean
from homocal.study.rows import (CAL_D, CAL_E_FAITHFUL, CAL_E_SIGNED, CAL_RX, CAL_RY, CAL_UX, CAL_UY, TEST_D, TEST_DG, TEST_GOX,
                                TEST_GOY, TEST_GX, TEST_GY, TEST_RR, TEST_RU2, TEST_RX, TEST_RY, TEST_S0, TEST_S1, TEST_S2)


METHODS = STUDY_COLUMNS  # the study's methods, in their shard column order: the catalogue's (homocal.correctors.catalogue)
# run_variant's output columns, in order (the shard schema is derived from them): method m's calibration and
# path improvements are columns 1 + 2 m and 2 + 2 m
OUT_COLUMNS = ("cal_before", *(f"{kind}_{m}" for m in METHODS for kind in ("cal", "path")), "hybrid_regression")
CAL = {m: OUT_COLUMNS.index(f"cal_{m}") for m in METHODS}  # method m's calibration column (its path column: the next)
CHOSE = len(OUT_COLUMNS) - 1
BEFORE = OUT_COLUMNS.index("cal_before")


class Variant(NamedTuple):
    """One trapezoid variant, as run_variant reads it (shards.prepare_variant makes it): v0 (8,) its image quad
    (px), t0 (8,) its map quad (m), Bt (3, 3) the map quad's basis (target_basis), H0 (3, 3) = homography(v0, Bt);
    F (M, 9) (ground_frames), q (M, 2) image (px) and g (M, 2) ground (m) calibration points; origin (2,) the
    camera's ground point o; cal (len(rows.CAL_ROWS), M) and test (len(rows.TEST_ROWS), N) float32, the tables of
    homocal.study.rows; path_before the mean test-point error before correction (m)."""

    v0: np.ndarray
    t0: np.ndarray
    Bt: np.ndarray
    H0: np.ndarray
    F: np.ndarray
    q: np.ndarray
    g: np.ndarray
    origin: np.ndarray
    cal: np.ndarray
    test: np.ndarray
    path_before: float


class Samples(NamedTuple):
    """The calibration triples (I, J, K) (S,) int64 of one variant and base = seed_from_key(run seed, scene,
    variant) (uint64), the key of their descent orders (sample_seed_kernel)."""

    I: np.ndarray
    J: np.ndarray
    K: np.ndarray
    base: np.uint64


class DescentSettings(NamedTuple):
    """DescentCorrector's settings: grid (G,) phase-1 offsets, px; delta_max, initial_step, min_step px; max_evals."""

    grid: np.ndarray
    delta_max: float
    initial_step: float
    min_step: float
    max_evals: int


class LeastChangeSettings(NamedTuple):
    """LeastChangeCorrector's settings: click_sigma (px), map_sigma (m), point_sigma (m), iterations."""

    click_sigma: float
    map_sigma: float
    point_sigma: float
    iterations: int


class Settings(NamedTuple):
    """The methods' settings: descent, least_change, the hybrid's threshold (%), in_range (the range metric)."""

    descent: DescentSettings
    least_change: LeastChangeSettings
    threshold: float
    in_range: bool


class Results(NamedTuple):
    """run_variant's outputs for S samples (see there)."""

    out: np.ndarray
    faithful_ab: np.ndarray
    signed_ab: np.ndarray
    quads: np.ndarray
    evaluations: np.ndarray

    @classmethod
    def empty(cls, S: int) -> "Results":
        return cls(np.empty((S, len(OUT_COLUMNS))), np.empty((S, 2)), np.empty((S, 2)), np.empty((S, 8)),
                   np.empty(S, np.int64))


@nb.njit(inline="always", **JIT)
def point_error(a0, a1, a2, b0, b1, b2, e0, e1, e2, c0, c1, c2, D, f0, f1, f2, f3, f4, f5, f6, f7, f8, u, v):
    """||H(q) - g|| for image point q = (u, v) and the F (9 scalars) of its ground point g; +inf beyond the horizon,
    decided on the sign of w alone (apply_homography's 1e-12 relative band is not applied: see the module
    docstring for why no decision depends on it)."""
    l0 = c0 * (a0 * u + a1 * v + a2)
    l1 = c1 * (b0 * u + b1 * v + b2)
    l2 = c2 * (e0 * u + e1 * v + e2)
    X = f0 * l0 + f1 * l1 + f2 * l2
    Y = f3 * l0 + f4 * l1 + f5 * l2
    W = f6 * l0 + f7 * l1 + f8 * l2
    e = math.sqrt(X * X + Y * Y) / abs(W)
    return e if W * D > 0.0 else math.inf


@nb.njit(**JIT)
def homography_into(v, Bt, H):
    """Write into H (3, 3) the image-to-target homography of image quad v (8,) and target basis Bt (3, 3):
    B_t diag(c) N, scaled to unit Frobenius norm with w > 0 on the quad (as homography_from_quads)."""
    a0, a1, a2, b0, b1, b2, e0, e1, e2, c0, c1, c2, D, valid = frame(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7])
    ss = 0.0
    for r in range(3):
        x, y, z = Bt[r, 0] * c0, Bt[r, 1] * c1, Bt[r, 2] * c2
        H[r, 0] = x * a0 + y * b0 + z * e0
        H[r, 1] = x * a1 + y * b1 + z * e1
        H[r, 2] = x * a2 + y * b2 + z * e2
        ss += H[r, 0] * H[r, 0] + H[r, 1] * H[r, 1] + H[r, 2] * H[r, 2]
    scale = math.copysign(1.0, D) / math.sqrt(ss)
    for r in range(3):
        for m in range(3):
            H[r, m] *= scale


@nb.njit(**JIT)
def homography(v, Bt):
    """(3, 3) homography_into a new array."""
    H = np.empty((3, 3))
    homography_into(v, Bt, H)
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


_within_reach = nb.njit(inline="always", **JIT)(within_reach)  # the readable corrector's reach rule, compiled
LANES = 32  # phase-2 samples run side by side, each evaluating one coordinate's +step and -step at once


@nb.njit(**JIT)
def grid_best(table, i, j, k, sums):
    """Phase 1 for triple (i, j, k): (least mean loss, first cell reaching it, as np.argmin) over the grid
    table (M, G^4); sums (G^4,) scratch. The cells are ranked by their loss sums, divided by 3 once for the
    best (the same bits as its mean; a sum and a mean rank alike except where two sums 1 ulp apart round to
    one mean, below the kernels' other differences from the correctors). Losses are >= 0 or +inf, so the
    sums order as their int64 bit patterns: the minimum and the search for its first cell are integer loops,
    which vectorise (a float minimum does not)."""
    n = table.shape[1]
    for g in range(n):
        sums[g] = table[i, g] + table[j, g] + table[k, g]
    bits = sums.view(np.int64)
    least = bits[0]
    for g in range(n):
        least = min2(least, bits[g])
    first = n
    for g in range(n):
        first = min2(first, g if bits[g] == least else n)
    return sums[first] / 3.0, first


@nb.njit(**JIT)
def eval_lanes(X, kc, dl, Fl, Ql, out):
    """Eq. (25) loss of each slot's candidate: quad X[:, m] (8, n) with coordinate kc[m] moved by dl[m], for its
    triple: Fl (27, n) the F of its 3 calibration points, Ql (6, n) their image points. Straight-line,
    vectorised over slots."""
    for m in range(X.shape[1]):
        k, d = kc[m], dl[m]
        a0, a1, a2, b0, b1, b2, e0, e1, e2, c0, c1, c2, D, valid = frame(
            X[0, m] + (d if k == 0 else 0.0), X[1, m] + (d if k == 1 else 0.0), X[2, m] + (d if k == 2 else 0.0),
            X[3, m] + (d if k == 3 else 0.0), X[4, m] + (d if k == 4 else 0.0), X[5, m] + (d if k == 5 else 0.0),
            X[6, m] + (d if k == 6 else 0.0), X[7, m] + (d if k == 7 else 0.0))
        s = 0.0
        for t in range(3):
            s += point_error(a0, a1, a2, b0, b1, b2, e0, e1, e2, c0, c1, c2, D, Fl[9 * t, m], Fl[9 * t + 1, m],
                             Fl[9 * t + 2, m], Fl[9 * t + 3, m], Fl[9 * t + 4, m], Fl[9 * t + 5, m], Fl[9 * t + 6, m],
                             Fl[9 * t + 7, m], Fl[9 * t + 8, m], Ql[2 * t, m], Ql[2 * t + 1, m])
        out[m] = s / 3.0 if valid else math.inf


@nb.njit(**JIT)
def descend_lanes(lo, hi, variant, samples, descent, seeds, quads, evaluations, Lfinal):
    """Phase 2 of DescentCorrector (settings descent: DescentSettings) for samples lo..hi-1 of variant (Variant),
    samples (Samples), seeds (S,) their keys, LANES at a time: each lane l holds one sample and resolves one
    coordinate per round, its +step and -step candidates evaluated together in slots l and LANES + l; a finished
    lane takes the next sample. quads[s] (8,) holds the phase-1 trapezoid and Lfinal[s] its loss on entry, the
    final ones on return, evaluations[s] the evaluations.

    Per lane, as DescentCorrector: each pass visits the coordinates in shuffled_order(seed, pass); a move
    beyond reach of v0 (correctors.descent.within_reach) is skipped unevaluated; +step is taken if it lowers L, else -step; the descent
    stops when evals == max_evals before an evaluation, or when step < min_step after a pass without
    improvement.

    Each round is a straight-line loop over the lanes (vectorised): accept or reject, write the moved
    coordinate into X, select the next coordinate of the pass and test its bounds. A lane that needs more
    (end of pass: step halving and a new shuffle; a coordinate skipped at the delta_max bound; budget
    exhausted; end of sample: its results out and the next sample in; idle) is flagged in event and
    finished by a scalar pass. (Written without helper calls: array arguments of inlined helpers cost
    reference counting in the hot loop.)

    Per-lane state (LANES,): the sample (-1 idle), its pass, evals, position in the pass, improved (0/1),
    the pass order packed 4 bits a position (perm, keyed_rng.packed_order), step, loss Ls, and for the
    coordinate in evaluation (kc[l]) its value xk and whether +step, -step are within delta_max (pok, mok, 0/1).
    """
    v0, F, q, I, J, K = variant.v0, variant.F, variant.q, samples.I, samples.J, samples.K
    initial_step, min_step, delta_max, max_evals = descent.initial_step, descent.min_step, descent.delta_max, descent.max_evals
    n = LANES
    # all lane state in two flat arrays at constant offsets (named views for the scalar code): the vectorised
    # loop indexes them directly, so it needs no runtime alias checks between a dozen arrays (with them,
    # LLVM does not vectorise it)
    OUT, DL, LS, STEP, XK = 16 * n, 18 * n, 20 * n, 21 * n, 22 * n  # in fs, after X (8, 2n)
    KC, SAMPLE, PAS, EVALS, POS = 0, 2 * n, 3 * n, 4 * n, 5 * n  # in ist
    IMPROVED, PERM, POK, MOK, EVENT = 6 * n, 7 * n, 8 * n, 9 * n, 10 * n
    fs, ist = np.zeros(23 * n), np.zeros(11 * n, np.int64)
    X, out, dl = fs[:OUT].reshape(8, 2 * n), fs[OUT:DL], fs[DL:LS]
    Ls, step, xk = fs[LS:STEP], fs[STEP:XK], fs[XK:]
    kc, sample, pas, evals = ist[KC:SAMPLE], ist[SAMPLE:PAS], ist[PAS:EVALS], ist[EVALS:POS]
    pos, improved, perm = ist[POS:IMPROVED], ist[IMPROVED:PERM], ist[PERM:POK]
    pok, mok, event = ist[POK:MOK], ist[MOK:EVENT], ist[EVENT:]
    sample[:] = -1
    event[:] = 1
    Fl, Ql = np.zeros((27, 2 * n)), np.zeros((6, 2 * n))
    nxt, active = lo, 0
    while True:
        for l in range(n):  # events of the previous round, and the initial loads (every lane flagged)
            if event[l] == 0:
                continue
            ready = sample[l] >= 0 and event[l] < 2  # event >= 2: the budget ran out before -step
            while True:
                if ready:  # find the lane's next coordinate to evaluate
                    while True:
                        if pos[l] == 8:
                            pas[l] += 1
                            if improved[l] == 0:
                                step[l] /= 2
                                if step[l] < min_step:
                                    ready = False
                                    break
                            improved[l] = 0
                            pos[l] = 0
                            perm[l] = packed_order(seeds[sample[l]], pas[l])
                        k = (perm[l] >> (4 * pos[l])) & 7
                        pok[l] = _within_reach((X[k, l] + step[l]) - v0[k], delta_max)
                        mok[l] = _within_reach((X[k, l] - step[l]) - v0[k], delta_max)
                        if pok[l] or mok[l]:
                            ready = evals[l] < max_evals
                            break
                        pos[l] += 1
                if ready:
                    kc[l] = kc[n + l] = k
                    xk[l] = X[k, l]
                    dl[l], dl[n + l] = step[l], -step[l]
                    break
                s = sample[l]
                if s >= 0:  # the lane's descent ended
                    for c in range(8):
                        quads[s, c] = X[c, l]
                    evaluations[s] = evals[l]
                    Lfinal[s] = Ls[l]
                    sample[l] = -1
                    pok[l] = mok[l] = 0
                    active -= 1
                if nxt == hi:
                    break
                s = nxt  # the lane takes the next sample
                nxt += 1
                active += 1
                sample[l], pas[l], evals[l], pos[l], improved[l] = s, 0, 0, 0, 0
                for c in range(8):
                    X[c, l] = X[c, n + l] = quads[s, c]
                Ls[l], step[l] = Lfinal[s], initial_step
                for t in range(3):
                    i = I[s] if t == 0 else (J[s] if t == 1 else K[s])
                    for c in range(9):
                        Fl[9 * t + c, l] = Fl[9 * t + c, n + l] = F[i, c]
                    Ql[2 * t, l] = Ql[2 * t, n + l] = q[i, 0]
                    Ql[2 * t + 1, l] = Ql[2 * t + 1, n + l] = q[i, 1]
                perm[l] = packed_order(seeds[s], 0)
                ready = True
        if active == 0:
            return
        eval_lanes(X, kc, dl, Fl, Ql, out)
        for l in range(n):  # resolve every lane's coordinate and pick its next one (idle lanes: pok = mok = 0)
            k, sp, L, e, x = ist[KC + l], fs[STEP + l], fs[LS + l], ist[EVALS + l], fs[XK + l]
            op, om, p_ok, m_ok = fs[OUT + l], fs[OUT + n + l], ist[POK + l], ist[MOK + l]
            take_p = (p_ok != 0) & (op < L)
            e += p_ok
            try_m = (m_ok != 0) & (not take_p)
            budget = try_m & (e == max_evals)  # no evaluation left for -step: the descent ends
            eval_m = try_m & (e != max_evals)
            take_m = eval_m & (om < L)
            e += eval_m
            x = x + sp if take_p else (x - sp if take_m else x)
            fs[LS + l] = op if take_p else (om if take_m else L)
            ist[EVALS + l] = e
            ist[IMPROVED + l] |= take_p | take_m
            p = ist[POS + l] + 1
            ist[POS + l] = p
            k2 = (ist[PERM + l] >> (4 * p)) & 7  # (p == 8: an event, k2 unused)
            xn, vn = 0.0, 0.0
            for c in range(8):  # selects, not branches or indexing by k: X[k, l] = x, xn = X[k2, l], vn = v0[k2]
                old = fs[2 * n * c + l]
                col = x if c == k else old
                fs[2 * n * c + l] = fs[2 * n * c + n + l] = col
                xn = col if c == k2 else xn
                vn = v0[c] if c == k2 else vn
            pn = _within_reach((xn + sp) - vn, delta_max)
            mn = _within_reach((xn - sp) - vn, delta_max)
            ist[KC + l] = ist[KC + n + l] = k2
            fs[XK + l], ist[POK + l], ist[MOK + l] = xn, pn, mn
            # event: 0 none; 1 end of pass, k2 out of bounds both ways, budget spent, or idle; 2 or 3 budget hit
            ist[EVENT + l] = 2 * budget + ((ist[SAMPLE + l] < 0) | (p == 8) | (not (pn | mn)) | (e >= max_evals))


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
def radial_error(cal, i, a, b, in_range):
    """Error of calibration candidate i after the radial correction (eq. (24)), c = a d^2 + b d: ||p + u c - g||,
    or in_range the range error | ||g - o|| - |d + c| |; cal (rows.CAL_ROWS, M)."""
    d = cal[CAL_D, i]
    c = a * d * d + b * d
    if in_range:
        return abs(cal[CAL_E_SIGNED, i] + d - abs(d + c))
    return math.hypot(cal[CAL_RX, i] + cal[CAL_UX, i] * c, cal[CAL_RY, i] + cal[CAL_UY, i] * c)


@nb.njit(inline="always", **PATH_JIT)
def _radial32(test, t, ab):
    """(e, True): the float32 error of test point t after the radial correction (eq. (24)), c = a d^2 + b d,
    (a, b) = ab (a in FIXED/m): |r + u c| = sqrt(|r|^2 + c (2 r.u + c)), units of 1/FIXED m (NaN stays NaN)."""
    a, b = ab
    d = test[TEST_D, t]
    c = d * (a * d + b)
    q = test[TEST_RR, t] + c * (test[TEST_RU2, t] + c)
    return math.sqrt(np.float32(0.0) if q < 0 else q), True


@nb.njit(inline="always", **PATH_JIT)
def _range32(test, t, ab):
    """(e, True): the float32 range error | ||g - o|| - |d + c| | of test point t after the radial correction
    c = a d^2 + b d (the corrected point p + u c lies at range |d + c|), units of 1/FIXED m."""
    a, b = ab
    d = test[TEST_D, t]
    return abs(test[TEST_DG, t] - abs(d + d * (a * d + b))), True


@nb.njit(**PATH_JIT)
def regression_path(test, a, b, in_range):
    """Mean test-point error (m) after a regression's radial correction (a, b) (_radial32; in_range its range error,
    _range32), in float32 and units of 1/FIXED m, summed exactly (jit.fixed_point_mean: NaN if a point error is not
    finite); test (rows.TEST_ROWS, N), its rows d, rr, ru2 (in_range: d, dg) read."""
    ab = (np.float32(a / FIXED), np.float32(b))
    return fixed_point_mean(_range32, test, ab) if in_range else fixed_point_mean(_radial32, test, ab)


@nb.njit(inline="always", **PATH_JIT)
def _residual(test, dH, t):
    """(nx, ny, w) of test point t under H0 + dH (see descent_path): H(t) - g = (nx, ny) / w, float32."""
    s0, s1, s2 = test[TEST_S0, t], test[TEST_S1, t], test[TEST_S2, t]
    dw = dH[6] * s0 + dH[7] * s1 + dH[8] * s2
    nx = test[TEST_RX, t] + (dH[0] * s0 + dH[1] * s1 + dH[2] * s2) - test[TEST_GX, t] * dw
    ny = test[TEST_RY, t] + (dH[3] * s0 + dH[4] * s1 + dH[5] * s2) - test[TEST_GY, t] * dw
    return nx, ny, np.float32(1.0) + dw


@nb.njit(inline="always", **PATH_JIT)
def _homography32(test, t, args):
    """(e, ok): the float32 error ||H(t) - g|| of test point t under H0 + dH, dH = args[0], units of 1/FIXED m,
    and whether t is in front of the horizon (w > 0; e is meaningless if not)."""
    nx, ny, w = _residual(test, args[0], t)
    ok = w > 0
    return math.sqrt(nx * nx + ny * ny) / (w if ok else np.float32(1.0)), ok


@nb.njit(**PATH_JIT)
def descent_path(test, dH):
    """Mean test-point error (m) of H0 + dH, float32, residual form: with s = t/w0 (H0 s = (p0, 1)) and
    r = p0 - g, H(t) - g = (r + dH01 s - g dH2 s) / (1 + dH2 s). test rows s0, s1, s2, rx, ry, gx, gy read;
    dH (9,) float32, rows 0-1 in units of 1/FIXED m. Summed as regression_path; NaN if a point crosses the
    horizon."""
    return fixed_point_mean(_homography32, test, (dH,))


@nb.njit(inline="always", **PATH_JIT)
def _homography_range32(test, t, args):
    """(e, ok): the float32 range error | ||g - o|| - ||H(t) - o|| | of test point t under H0 + dH (args[0]),
    H(t) - o = (H(t) - g) + (g - o), units of 1/FIXED m, and ok as _homography32."""
    nx, ny, w = _residual(test, args[0], t)
    ok = w > 0
    wi = np.float32(1.0) / (w if ok else np.float32(1.0))
    px = nx * wi + test[TEST_GOX, t]
    py = ny * wi + test[TEST_GOY, t]
    return abs(test[TEST_DG, t] - math.sqrt(px * px + py * py)), ok


@nb.njit(**PATH_JIT)
def descent_path_range(test, dH):
    """As descent_path, with the range error (_homography_range32); test rows gox, goy (g - o) and dg (||g - o||)
    read too."""
    return fixed_point_mean(_homography_range32, test, (dH,))


@nb.njit(inline="always", **PATH_JIT)
def _range_intercept32(test, t, abc):
    """_range32 for the radial correction with an intercept, c(d) = a d^2 + b d + c, (a, b, c) = abc."""
    a, b, c = abc
    d = test[TEST_D, t]
    return abs(test[TEST_DG, t] - abs(d + d * (a * d + b) + c)), True


@nb.njit(**PATH_JIT)
def regression_path_range(test, a, b, c):
    """As regression_path (in_range) for one regression with an intercept, c(d) = a d^2 + b d + c (m)."""
    return fixed_point_mean(_range_intercept32, test, (np.float32(a / FIXED), np.float32(b), np.float32(c * FIXED)))


@nb.njit(**JIT)
def mapped_error(H, q, g, i, origin, in_range):
    """Error of image point q[i] (M, 2) mapped by H (3, 3) against its ground point g[i] (M, 2): ||H(q) - g||, or
    in_range | ||g - o|| - ||H(q) - o|| | (origin o (2,)); +inf on or beyond the horizon (w <= 0)."""
    u, v = q[i, 0], q[i, 1]
    w = H[2, 0] * u + H[2, 1] * v + H[2, 2]
    if not w > 0.0:
        return math.inf
    x = (H[0, 0] * u + H[0, 1] * v + H[0, 2]) / w
    y = (H[1, 0] * u + H[1, 1] * v + H[1, 2]) / w
    if in_range:
        return abs(math.hypot(g[i, 0] - origin[0], g[i, 1] - origin[1]) - math.hypot(x - origin[0], y - origin[1]))
    return math.hypot(x - g[i, 0], y - g[i, 1])


@nb.njit(**JIT)
def homography_paths(test, H, H0, dH, in_range):
    """Mean test-point error (m) of the mapping H (3, 3), through descent_path (or its range form) with dH (9,)
    float32 scratch = H - H0 (rows 0-1 in units of 1/FIXED m)."""
    for m in range(9):
        dH[m] = np.float32((H[m // 3, m % 3] - H0[m // 3, m % 3]) * (FIXED if m < 6 else 1.0))
    return descent_path_range(test, dH) if in_range else descent_path(test, dH)


@nb.njit(**JIT)
def sample_seed_kernel(base, i, j, k):
    """seed_from_key(run_seed, scene, variant, i, j, k) from base = seed_from_key(run_seed, scene, variant)."""
    s = splitmix64(base ^ np.uint64(i))
    s = splitmix64(s ^ np.uint64(j))
    return splitmix64(s ^ np.uint64(k))


@nb.njit(**JIT)
def _improvement(before, after):
    return math.nan if before == 0.0 else 100.0 * (before - after) / before


@nb.njit(**JIT)
def _mean3(a, b, c):
    return (a + b + c) / 3.0


@nb.njit(**JIT)
def _calibration_error(H, q, g, i, j, k, origin, in_range):
    """Mean mapped_error of calibration points i, j, k under H (3, 3), metres."""
    return _mean3(mapped_error(H, q, g, i, origin, in_range), mapped_error(H, q, g, j, origin, in_range),
                  mapped_error(H, q, g, k, origin, in_range))


def column_kernel(column, after=()):
    """Declare the compiled study kernel of the catalogue's study column ``column`` (catalogue.STUDY_COLUMNS):
    kernel(variant, samples, settings, results, cal, after) writes, for every sample s, results.out[s, cal] and
    [s, cal + 1], the method's calibration and path improvements (%), and may read the columns out[:, c] of
    the methods named in ``after`` (their calibration columns, in that order), which run_variant runs first."""
    def declare(kernel):
        KERNELS[column] = (nb.njit(nogil=True, **JIT)(kernel), after)
        return KERNELS[column][0]
    return declare


KERNELS = {}  # study column -> (its compiled kernel, the columns it reads), declared by column_kernel


@nb.njit(nogil=True, **JIT)
def calibration_before(variant, samples, settings, results):
    """out[s, BEFORE]: the mean calibration error (m) of triple s before correction, in the study's metric."""
    cal, I, J, K, out = variant.cal, samples.I, samples.J, samples.K, results.out
    for s in range(I.shape[0]):
        i, j, k = I[s], J[s], K[s]
        if settings.in_range:
            out[s, BEFORE] = _mean3(abs(cal[CAL_E_SIGNED, i]), abs(cal[CAL_E_SIGNED, j]), abs(cal[CAL_E_SIGNED, k]))
        else:
            out[s, BEFORE] = _mean3(cal[CAL_E_FAITHFUL, i], cal[CAL_E_FAITHFUL, j], cal[CAL_E_FAITHFUL, k])


@nb.njit(inline="always", **JIT)
def _regression(variant, samples, in_range, out, col, ab, signed):
    """The radial regression (eqs. (18)-(24)), faithful or signed, of every sample: its improvements in out[:, col],
    out[:, col + 1] and its (a, b) in ab (S, 2)."""
    cal, test, I, J, K = variant.cal, variant.test, samples.I, samples.J, samples.K
    e = CAL_E_SIGNED if signed else CAL_E_FAITHFUL
    for s in range(I.shape[0]):
        i, j, k = I[s], J[s], K[s]
        a, b, _ = fit_quadratic(cal[CAL_D, i], cal[CAL_D, j], cal[CAL_D, k], cal[e, i], cal[e, j], cal[e, k], not signed)
        out[s, col] = _improvement(out[s, BEFORE], _mean3(radial_error(cal, i, a, b, in_range), radial_error(cal, j, a, b, in_range),
                                                           radial_error(cal, k, a, b, in_range)))
        out[s, col + 1] = _improvement(variant.path_before, regression_path(test, a, b, in_range))
        ab[s, 0], ab[s, 1] = a, b


@column_kernel("regression")
def regression(variant, samples, settings, results, col, after):
    """The paper's regression of unsigned errors, clamped (results.faithful_ab)."""
    _regression(variant, samples, settings.in_range, results.out, col, results.faithful_ab, False)


@column_kernel("regression_signed")
def regression_signed(variant, samples, settings, results, col, after):
    """The regression of signed range errors (results.signed_ab)."""
    _regression(variant, samples, settings.in_range, results.out, col, results.signed_ab, True)


@column_kernel("regression_intercept")
def regression_intercept(variant, samples, settings, results, col, after):
    """The signed regression with an intercept, e = a d^2 + b d + c, exact through the three points."""
    cal, test, I, J, K, out = variant.cal, variant.test, samples.I, samples.J, samples.K, results.out
    for s in range(I.shape[0]):
        i, j, k = I[s], J[s], K[s]
        di, dj, dk = cal[CAL_D, i], cal[CAL_D, j], cal[CAL_D, k]
        ei, ej, ek = cal[CAL_E_SIGNED, i], cal[CAL_E_SIGNED, j], cal[CAL_E_SIGNED, k]
        ai, bi, ci, _ = mk.fit_quadratic_intercept3(di, dj, dk, ei, ej, ek)
        if settings.in_range:
            cal_i = _mean3(abs(ei + di - abs(di + ai * di * di + bi * di + ci)),
                           abs(ej + dj - abs(dj + ai * dj * dj + bi * dj + ci)),
                           abs(ek + dk - abs(dk + ai * dk * dk + bi * dk + ci)))
            path_i = regression_path_range(test, ai, bi, ci)
        else:
            cal_i = _mean3(mk.radial_error_intercept(cal, i, ai, bi, ci), mk.radial_error_intercept(cal, j, ai, bi, ci),
                           mk.radial_error_intercept(cal, k, ai, bi, ci))
            path_i = mk.regression_path_intercept(test, ai, bi, ci)
        out[s, col], out[s, col + 1] = _improvement(out[s, BEFORE], cal_i), _improvement(variant.path_before, path_i)


@column_kernel("horizon")
def horizon(variant, samples, settings, results, col, after):
    """The horizon correction: the least-squares horizon shift (eq. (9)) as a homography."""
    H0, q, g, test, I, J, K, out = variant.H0, variant.q, variant.g, variant.test, samples.I, samples.J, samples.K, results.out
    dH, Hd = np.empty(9, np.float32), np.empty((3, 3))
    for s in range(I.shape[0]):
        i, j, k = I[s], J[s], K[s]
        eps, _ = mk.fit_horizon_shift3(H0, q[i, 0], q[i, 1], g[i, 0], g[i, 1], q[j, 0], q[j, 1], g[j, 0], g[j, 1],
                                       q[k, 0], q[k, 1], g[k, 0], g[k, 1])
        mk.horizon_homography_into(H0, eps, Hd)
        cal_h = _calibration_error(Hd, q, g, i, j, k, variant.origin, settings.in_range)
        out[s, col] = _improvement(out[s, BEFORE], cal_h)
        out[s, col + 1] = _improvement(variant.path_before, homography_paths(test, Hd, H0, dH, settings.in_range))


@column_kernel("least_change")
def least_change(variant, samples, settings, results, col, after):
    """Least change: the smallest move of both clicked quads that explains the three points (MAP)."""
    H0, q, g, test, I, J, K, out = variant.H0, variant.q, variant.g, variant.test, samples.I, samples.J, samples.K, results.out
    lc, in_range = settings.least_change, settings.in_range
    dH, Hd = np.empty(9, np.float32), np.empty((3, 3))
    z0, zl, Bl = np.concatenate((variant.v0, variant.t0)), np.empty(16), np.empty((3, 3))
    q3, g3 = np.empty((3, 2)), np.empty((3, 2))
    for s in range(I.shape[0]):
        i, j, k = I[s], J[s], K[s]
        for t in range(3):
            c = i if t == 0 else (j if t == 1 else k)
            q3[t, 0], q3[t, 1], g3[t, 0], g3[t, 1] = q[c, 0], q[c, 1], g[c, 0], g[c, 1]
        mk.least_change3(z0, q3, g3, lc.click_sigma, lc.map_sigma, lc.point_sigma, lc.iterations, zl, Bl)
        homography_into(zl[:8], Bl, Hd)
        cal_l = _calibration_error(Hd, q, g, i, j, k, variant.origin, in_range)
        out[s, col] = _improvement(out[s, BEFORE], cal_l)
        out[s, col + 1] = _improvement(variant.path_before, homography_paths(test, Hd, H0, dH, in_range))


@column_kernel("descent")
def descent(variant, samples, settings, results, col, after):
    """DescentCorrector: phase 1, the grid cell of least mean loss (first on ties), then phase 2 with LANES samples
    side by side over the whole variant (descend_lanes: lanes idle only at its end); results.quads and
    results.evaluations its final trapezoids and phase-2 evaluations."""
    v0, Bt, H0, F, q, g, test = variant.v0, variant.Bt, variant.H0, variant.F, variant.q, variant.g, variant.test
    I, J, K, out, quads, grid = samples.I, samples.J, samples.K, results.out, results.quads, settings.descent.grid
    table = grid_table(v0, grid, F, q)
    G, S = grid.shape[0], I.shape[0]
    Lfinal, seeds, sums = np.empty(S), np.empty(S, np.uint64), np.empty(table.shape[1])
    dH, Hd = np.empty(9, np.float32), np.empty((3, 3))
    for s in range(S):
        i, j, k = I[s], J[s], K[s]
        best, gbest = grid_best(table, i, j, k, sums)
        quads[s] = v0
        quads[s, 0] += grid[gbest // G**3]
        quads[s, 1] += grid[(gbest // G**2) % G]
        quads[s, 4] += grid[(gbest // G) % G]
        quads[s, 5] += grid[gbest % G]
        Lfinal[s] = best
        seeds[s] = sample_seed_kernel(samples.base, i, j, k)
    descend_lanes(0, S, variant, samples, settings.descent, seeds, quads, results.evaluations, Lfinal)
    for s in range(S):
        homography_into(quads[s], Bt, Hd)
        cal_d = _calibration_error(Hd, q, g, I[s], J[s], K[s], variant.origin, True) if settings.in_range else Lfinal[s]
        out[s, col] = _improvement(out[s, BEFORE], cal_d)
        out[s, col + 1] = _improvement(variant.path_before, homography_paths(test, Hd, H0, dH, settings.in_range))


@column_kernel("hybrid", after=("regression", "descent"))
def hybrid(variant, samples, settings, results, col, after):
    """The hybrid: regression if its calibration improvement reaches the threshold (Section 7), else descent;
    out[s, CHOSE] 1.0 if it chose regression."""
    reg, des = after
    out = results.out
    for s in range(out.shape[0]):
        chose = out[s, reg] >= settings.threshold
        out[s, col] = out[s, reg] if chose else out[s, des]
        out[s, col + 1] = out[s, reg + 1] if chose else out[s, des + 1]
        out[s, CHOSE] = 1.0 if chose else 0.0


def _run_order():
    """(kernel, calibration column, the columns it reads) of each METHODS column, in its order; ImportError if a
    column has no kernel or reads a column not run before it."""
    missing = [m for m in METHODS if m not in KERNELS]
    if missing:
        raise ImportError(f"study columns without a kernel (homocal.study.kernels.column_kernel): {', '.join(missing)}")
    order = []
    for n, m in enumerate(METHODS):
        kernel, after = KERNELS[m]
        if not set(after) <= set(METHODS[:n]):
            raise ImportError(f"the study kernel of {m} reads {', '.join(after)}: each must be a study column before it")
        order.append((kernel, CAL[m], tuple(CAL[a] for a in after)))
    return tuple(order)


RUN_ORDER = _run_order()


def run_variant(variant, samples, settings, results):
    """Every method on every triple of samples (Samples) of one trapezoid variant (Variant), with settings
    (Settings); writes results (Results): out (S, len(OUT_COLUMNS)) in OUT_COLUMNS order, cal_before (m), then
    (cal, path) improvement (%) of each of the METHODS, then 1.0 if hybrid chose regression; faithful_ab and
    signed_ab (S, 2): the two regressions' a, b; quads (S, 8) and evaluations (S,): descent's final trapezoid and
    its phase-2 evaluations. Each kernel releases the GIL (the engine runs variants side by side).

    With settings.in_range, errors are range errors | ||g - o|| - ||p - o|| | instead of ||p - g|| (the study's
    metric; the methods themselves do not change, the hybrid's threshold applies to the metric's improvement).
    """
    calibration_before(variant, samples, settings, results)
    for kernel, cal, after in RUN_ORDER:
        kernel(variant, samples, settings, results, cal, after)

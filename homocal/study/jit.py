"""What every compiled kernel of the study shares: numba's settings and the fixed-point unit of test-point
lengths (homocal.study.kernels, homocal.study.method_kernels)."""
from __future__ import annotations

import math

import numba as nb
import numpy as np

JIT = dict(cache=True, error_model="numpy")
PATH_JIT = dict(JIT, fastmath={"contract"})  # the test-point loops (no decision depends on them)

# test-point lengths are in units of 2^-18 m (3.8 um: float32's resolution at 32-64 m, the operating range), so a
# point error below 8 km fits an int32 (shards.prepare_variant scales them). A loop sums to_fixed of its errors and
# counts those at or beyond CLIP (8 km, inf or NaN) and the failures (a point beyond the horizon) with over_clip; if
# any, the loop sums again with fixed_parts, in which every error below LIMIT (2^62 units, 1.76e13 m) keeps its true
# value and a failure or a larger error makes the mean NaN (exact_mean), a failed correction. Corrected errors beyond 8 km do occur (regression with an intercept
# extrapolates its parabola beyond the calibration points), so the second sum is no dead branch.
FIXED = 2.0**18
CLIP = np.float32(2.0**31 - 2.0**7)
SPLIT = np.float32(2.0**31)
LIMIT = np.float32(2.0**62)


@nb.njit(inline="always", **JIT)
def to_fixed(e):
    """A float32 point error below CLIP in units of 2^-18 m, rounded to an int32 and widened to int64 (clipped at
    CLIP: see over_clip): integer sums are exact, so they give the same bits in every order (a float reduction
    vectorises differently in different compilations); the float32-to-int32 conversion vectorises on AVX2 (to int64
    it does not): about 1.25x faster."""
    return np.int64(np.int32(np.float32(0.5) + (e if e < CLIP else CLIP)))


@nb.njit(inline="always", **JIT)
def over_clip(e, ok):
    """1 (int64) if e is a failure (not ok) or to_fixed clipped it (e >= CLIP, inf or NaN), else 0."""
    return np.int64(not (ok and e < CLIP))


@nb.njit(inline="always", **JIT)
def fixed_parts(e, ok):
    """(hi, lo, over) int64 of a float32 point error e >= 0 in units of 2^-18 m, exactly e = hi 2^31 + lo, lo rounded
    to the unit (hi = floor(e 2^-31) is exact, and so is e - hi 2^31, a multiple of e's ulp below e); over = 1 and
    hi = lo = 0 if e is a failure (not ok) or not below LIMIT (inf, NaN)."""
    ok = ok and e < LIMIT
    x = e if ok else np.float32(0.0)
    hi = np.int32(x / SPLIT)
    lo = np.int32(np.float32(0.5) + (x - np.float32(hi) * SPLIT))
    return np.int64(hi), np.int64(lo), np.int64(not ok)


@nb.njit(inline="always", **JIT)
def exact_mean(hi, lo, over, n):
    """The mean (m) of n point errors from the sums of their fixed_parts; NaN if one was over LIMIT."""
    return (hi * 2147483648.0 + lo) / FIXED / n if over == 0 else math.nan


@nb.njit(inline="always", **PATH_JIT)
def fixed_point_mean(point_error, test, args):
    """The mean (m) of point_error(test, t, args) -> (e, ok) over the test points t (test (rows, N), e a float32
    error in units of 2^-18 m, ok False for a failure): summed with to_fixed, and again with fixed_parts if one
    was a failure or at least 8 km (NaN if a failure or beyond LIMIT)."""
    n = test.shape[1]
    total = over = np.int64(0)
    for t in range(n):
        e, ok = point_error(test, t, args)
        total += to_fixed(e)
        over += over_clip(e, ok)
    if over == 0:
        return total / FIXED / n
    hi = lo = over = np.int64(0)
    for t in range(n):
        e, ok = point_error(test, t, args)
        h, low, o = fixed_parts(e, ok)
        hi, lo, over = hi + h, lo + low, over + o
    return exact_mean(hi, lo, over, n)

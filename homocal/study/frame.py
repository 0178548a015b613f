"""The closed-form projective frame of a quad that the study's compiled kernels share (homocal.study.kernels,
homocal.study.method_kernels): see kernels' module docstring for the construction."""
from __future__ import annotations

import numba as nb

from homocal.study.jit import JIT


@nb.njit(inline="always", **JIT)
def max2(a, b):
    return a if a > b else b


@nb.njit(inline="always", **JIT)
def min2(a, b):
    return a if a < b else b


@nb.njit(inline="always", **JIT)
def quad_frame(x0, y0, x1, y1, x2, y2, x3, y3):
    """Projective frame of a quad p0..p3 (homogeneous, w = 1): (n0, n1, n2 as 9 scalars, d0, d1, d2, det, valid),
    n_k = p_{k+1} x p_{k+2} (so [p0 p1 p2]^-1 has rows n_k / det), d_k = n_k . p3, det = det[p0 p1 p2];
    valid: validate_quad's test (det, d0, -d1, d2 of one sign, each beyond 1e-9 scale^2)."""
    a0, a1, a2 = y1 - y2, x2 - x1, x1 * y2 - x2 * y1  # n0 = p1 x p2
    b0, b1, b2 = y2 - y0, x0 - x2, x2 * y0 - x0 * y2  # n1 = p2 x p0
    e0, e1, e2 = y0 - y1, x1 - x0, x0 * y1 - x1 * y0  # n2 = p0 x p1
    d0 = a0 * x3 + a1 * y3 + a2  # det[p1 p2 p3]
    d1 = b0 * x3 + b1 * y3 + b2  # det[p2 p0 p3] = -det[p2 p3 p0]
    d2 = e0 * x3 + e1 * y3 + e2  # det[p0 p1 p3] = det[p3 p0 p1]
    det = a0 * x0 + a1 * y0 + a2  # det[p0 p1 p2]
    sx = max2(max2(x0, x1), max2(x2, x3)) - min2(min2(x0, x1), min2(x2, x3))
    sy = max2(max2(y0, y1), max2(y2, y3)) - min2(min2(y0, y1), min2(y2, y3))
    scale = max2(sx, sy)
    tol = 1e-9 * (scale * scale)
    lo = min2(min2(det, d0), min2(-d1, d2))
    hi = max2(max2(det, d0), max2(-d1, d2))
    valid = (lo > tol) | (hi < -tol)  # one sign, each beyond the tolerance
    return a0, a1, a2, b0, b1, b2, e0, e1, e2, d0, d1, d2, det, valid


@nb.njit(inline="always", **JIT)
def frame(x0, y0, x1, y1, x2, y2, x3, y3):
    """Projective frame of an image quad: (n0, n1, n2 as 9 scalars, c0, c1, c2, D, valid), c = (d1 d2, d0 d2,
    d0 d1), D = d0 d1 d2 (quad_frame)."""
    a0, a1, a2, b0, b1, b2, e0, e1, e2, d0, d1, d2, det, valid = quad_frame(x0, y0, x1, y1, x2, y2, x3, y3)
    return a0, a1, a2, b0, b1, b2, e0, e1, e2, d1 * d2, d0 * d2, d0 * d1, d0 * d1 * d2, valid

"""The row layouts of the per-variant tables the study's compiled kernels read (homocal.study.kernels,
homocal.study.method_kernels), declared once with the functions that build them (shards.prepare_variant).

The kernels index the tables by these names only; numba reads module-level integers as compile-time
constants, so a named row costs nothing over a literal.
"""
from __future__ import annotations

import numpy as np

from homocal.study.jit import FIXED

# cal (len(CAL_ROWS), M) float64: one column per calibration candidate p (the variant's mapping of its image
# point), g its ground point, o the camera's ground point, metres
CAL_ROWS = (
    "d",  # |p - o|
    "rx", "ry",  # r = p - g
    "ux", "uy",  # u = (p - o) / d
    "e_faithful",  # |p - g|, the paper's unsigned error (eq. (18))
    "e_signed",  # |g - o| - |p - o|, the signed range error
)
CAL_D, CAL_RX, CAL_RY, CAL_UX, CAL_UY, CAL_E_FAITHFUL, CAL_E_SIGNED = range(len(CAL_ROWS))

# test (len(TEST_ROWS), N) float32: one column per test point t mapped to p = H0(t) with ground truth g; every
# length in units of 1/FIXED m (jit.FIXED), and s = t / w0 (H0 s = (p, 1))
TEST_ROWS = (
    "d",  # |p - o|
    "rr", "ru2",  # |r|^2, 2 r.u (r = p - g, u = (p - o) / d; |r|^2 in units of 1/FIXED^2 m^2)
    "s0", "s1", "s2",  # s, unitless
    "rx", "ry",  # r
    "gx", "gy",  # g
    "gox", "goy",  # g - o
    "dg",  # |g - o|
)
(TEST_D, TEST_RR, TEST_RU2, TEST_S0, TEST_S1, TEST_S2, TEST_RX, TEST_RY, TEST_GX, TEST_GY, TEST_GOX, TEST_GOY,
 TEST_DG) = range(len(TEST_ROWS))


def make_cal_table(p: np.ndarray, g: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """The cal table (len(CAL_ROWS), M) of mapped candidates p (M, 2) against ground points g (M, 2), m."""
    d = np.linalg.norm(p - origin, axis=1)
    r = p - g
    cal = np.empty((len(CAL_ROWS), len(p)))
    cal[CAL_D] = d
    cal[CAL_RX], cal[CAL_RY] = r.T
    cal[CAL_UX], cal[CAL_UY] = ((p - origin) / d[:, None]).T
    cal[CAL_E_FAITHFUL] = np.linalg.norm(r, axis=1)
    cal[CAL_E_SIGNED] = np.linalg.norm(g - origin, axis=1) - d
    return cal


def make_test_table(image: np.ndarray, H0: np.ndarray, p: np.ndarray, g: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """The test table (len(TEST_ROWS), N) float32 of test points image (N, 2) px mapped by H0 (3, 3) to p (N, 2),
    ground truth g (N, 2), m."""
    f = FIXED
    d = np.linalg.norm(p - origin, axis=1)
    r = p - g
    u = (p - origin) / d[:, None]
    homogeneous = np.column_stack([image, np.ones(len(p))])
    s = homogeneous / (homogeneous @ H0[2])[:, None]
    test = np.empty((len(TEST_ROWS), len(p)))
    test[TEST_D] = f * d
    test[TEST_RR] = f * f * (r**2).sum(axis=1)
    test[TEST_RU2] = f * 2 * (r * u).sum(axis=1)
    test[TEST_S0], test[TEST_S1], test[TEST_S2] = s.T
    test[TEST_RX], test[TEST_RY] = f * r.T
    test[TEST_GX], test[TEST_GY] = f * g.T
    test[TEST_GOX], test[TEST_GOY] = f * (g - origin).T
    test[TEST_DG] = f * np.linalg.norm(g - origin, axis=1)
    return test.astype(np.float32)

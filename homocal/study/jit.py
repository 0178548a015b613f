"""What every compiled kernel of the study shares: numba's settings and the fixed-point unit of test-point
lengths (homocal.study.kernels, homocal.study.method_kernels)."""
from __future__ import annotations

import numba as nb
import numpy as np

JIT = dict(cache=True, error_model="numpy")
PATH_JIT = dict(JIT, fastmath={"contract"})  # the test-point loops (no decision depends on them)

FIXED = 2.0**26  # test-point lengths are in units of 2^-26 m (15 nm) (scene.prepare_variant scales them)
CLIP = np.float32(1e5 * FIXED)  # a point error is clipped at 100 km: the int64 sum cannot overflow (1e6 points)


@nb.njit(inline="always", **JIT)
def to_fixed(e):
    """A float32 point error in units of 2^-26 m as an int64 (truncated, clipped): integer sums are exact, so
    they give the same bits in every order (a float reduction vectorises differently in different compilations)."""
    return np.int64(e if e < CLIP else CLIP)

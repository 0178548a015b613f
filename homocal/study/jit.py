"""What every compiled kernel of the study shares: numba's settings and the fixed-point unit of test-point
lengths (homocal.study.kernels, homocal.study.method_kernels)."""
from __future__ import annotations

import numba as nb
import numpy as np

JIT = dict(cache=True, error_model="numpy")
PATH_JIT = dict(JIT, fastmath={"contract"})  # the test-point loops (no decision depends on them)

# test-point lengths are in units of 2^-18 m (3.8 um: float32's resolution at 32-64 m, the operating range), so a
# point error fits an int32 (scene.prepare_variant scales them); one is clipped at 8 km (the largest float32 below
# 2^31 units): no corrected mean path error of the paper-preset study comes near it (the largest is 66 m)
FIXED = 2.0**18
CLIP = np.float32(2.0**31 - 2.0**7)


@nb.njit(inline="always", **JIT)
def to_fixed(e):
    """A float32 point error in units of 2^-18 m, rounded to an int32 (clipped) and widened to int64: integer sums
    are exact, so they give the same bits in every order (a float reduction vectorises differently in different
    compilations); the float32-to-int32 conversion vectorises on AVX2 (to int64 it does not): about 1.25x faster."""
    return np.int64(np.int32(np.float32(0.5) + (e if e < CLIP else CLIP)))

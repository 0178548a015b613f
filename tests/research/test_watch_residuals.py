"""research/watch_residuals.py's dependence figures on increments whose dependence is known."""
import importlib.util
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location("watch_residuals", ROOT / "research" / "watch_residuals.py")
script = importlib.util.module_from_spec(spec)
spec.loader.exec_module(script)


@pytest.mark.parametrize("rho", [0.0, 0.5])
def test_dependence_of_ar1_increments(rho):
    """Two recordings of 20,000 AR(1) increments (lag-1 correlation rho): the lag-1 autocorrelation within 4 standard
    errors (1 / sqrt(n)) of rho, and the variance of sums of BLOCK over BLOCK times the variance within 4 of its
    standard errors (sqrt(2 / blocks) relative; neighbouring blocks correlate by under 0.1) of 1 + 2 sum_k (1 - k /
    BLOCK) rho^k; recordings are not chained (the second starts afresh: a jump between them does not count)."""
    rng = np.random.default_rng(1)
    frames = []
    for name, offset in (("a", 0.0), ("b", 5.0)):
        e = rng.standard_normal(20_000)
        u = np.empty_like(e)
        u[0] = e[0]
        for i in range(1, len(e)):
            u[i] = rho * u[i - 1] + math.sqrt(1 - rho * rho) * e[i]
        frames.append(pd.DataFrame({"dataset": name, "u": u + offset}))
    lag1, ratio = script.dependence(pd.concat(frames, ignore_index=True))
    assert abs(lag1 - rho) < 4 / math.sqrt(40_000)
    expected = 1 + 2 * sum((1 - k / script.BLOCK) * rho ** k for k in range(1, script.BLOCK))
    assert abs(ratio / expected - 1) < 4 * math.sqrt(2 / (40_000 / script.BLOCK))

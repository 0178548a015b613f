"""research/foot_noise.py: the robust sigma, the height fit and the autocorrelation against known generators."""
import importlib.util
from pathlib import Path

import numpy as np

SCRIPT = Path(__file__).resolve().parents[2] / "research" / "foot_noise.py"
spec = importlib.util.spec_from_file_location("foot_noise", SCRIPT)
script = importlib.util.module_from_spec(spec)
spec.loader.exec_module(script)


def test_binned_robust_sigma_and_fit_recover_a_linear_noise():
    rng = np.random.default_rng(0)
    n = 40_000
    height = rng.choice([15.0, 25, 35, 50, 70, 100, 140, 200, 300], n)  # one height a bin of BIN_EDGES_PX
    err = rng.normal(0, 1, (n, 2)) * (0.5 + 0.04 * height)[:, None] + [1.0, -2.0]  # a bias the MAD ignores
    bins = script.binned_sigma(err, height)
    h, w = np.array([b[0] for b in bins]), np.array([b[1] for b in bins], float)
    s = np.array([b[2] for b in bins])
    # 1.4826 MAD of ~4,400 normal draws: its sampling error is 1.65 / sqrt(2 n) ~ 2 %
    np.testing.assert_allclose(s, np.repeat((0.5 + 0.04 * h)[:, None], 2, axis=1), rtol=0.08)
    np.testing.assert_allclose([b[3] for b in bins], np.broadcast_to([1.0, -2.0], (len(bins), 2)), atol=0.5)
    a, b = script.fit_linear(np.r_[h, h], np.r_[s[:, 0], s[:, 1]], np.r_[w, w])
    assert abs(b / 0.04 - 1) < 0.05 and abs(a - 0.5) < 0.3
    np.testing.assert_allclose(script.fit_linear(np.array([1.0, 2, 3]), np.array([2.0, 4, 6]), np.ones(3), ratio=True),
                               (0.0, 2.0))
    wild = np.r_[rng.normal(0, 1, 9500), np.full(500, 500.0)]  # 5 % wild boxes move 1.4826 MAD by under 10 %
    assert 1.0 < script.robust_sigma(wild) < 1.1


def test_autocorrelation_of_an_ar1_series_per_agent():
    rng = np.random.default_rng(1)
    rho, n, agents = 0.8, 2000, 3
    e, ids, frames = [], [], []
    for k in range(agents):
        x = np.zeros(n)
        for i in range(1, n):
            x[i] = rho * x[i - 1] + rng.normal()
        e.append(x + 10 * k)  # each agent its own offset: the per-agent median takes it away
        ids.append(np.full(n, k))
        frames.append(np.arange(n))
    e, ids, frames = np.concatenate(e), np.concatenate(ids), np.concatenate(frames)
    order = rng.permutation(len(e))  # any row order
    for lag in (1, 3):
        # AR(1): rho^lag; sampling error of a correlation over 6000 pairs ~ (1 - rho^2) / sqrt(6000 / 9) ~ 0.015
        assert abs(script.autocorrelation(e[order], ids[order], frames[order], lag) - rho**lag) < 0.06


def test_correlation_time_of_an_exponential_autocorrelation():
    """An AR(1)'s autocorrelation rho^k at lags k frames dt apart is exp(-k dt / tau), tau = -dt / ln(rho)."""
    rho, dt = 0.9, 0.05
    acf = rho ** np.arange(1, 6)
    assert abs(script.correlation_time(acf, dt) - (-dt / np.log(rho))) < 1e-12

"""The two-regime motion model of homocal.measure.kalman (imm_filter, imm_smoother) against independent
computations: with its two q equal it is the Kalman filter and RTS smoother; its likelihood and smoothed states
against the exact sum over the regime sequences, each a Gaussian written in closed form; on tracks drawn from
the two-regime model its error bars against the single-q filter's."""
import itertools

import numpy as np
import pytest

from homocal.measure.kalman import (fit_accel_psd, imm_filter, imm_smoother, innovation_log_likelihood,
                                    kalman_filter, mixture, rts_smoother)
from homocal.measure.kalman import START_POSITION_SIGMA_M as P0, START_SPEED_SIGMA_MPS as V0


def irregular_tracks(rng, n=3, L=30):
    """kalman_filter's (t, z, R) of n tracks: irregular steps, a skipped measurement, a padded end."""
    t = np.cumsum(rng.uniform(0.03, 0.12, (n, L)), axis=1)
    z = np.stack([2.0 + 1.2 * t, 18.0 - 0.4 * t], axis=-1) + rng.normal(0, 0.1, (n, L, 2))
    z[0, 5] = np.nan
    t[2, 20:], z[2, 20:] = t[2, 19], np.nan
    R = np.broadcast_to([[0.012, 0.003], [0.003, 0.02]], (n, L, 2, 2)).copy()
    return t, z, R


def smoothed(filtered):
    """imm_smoother's states and covariances as the models' mixture."""
    x, P, mu = imm_smoother(filtered)
    return mixture(mu, x, P)


def test_two_equal_models_are_the_kalman_filter_and_rts_smoother():
    t, z, R = irregular_tracks(np.random.default_rng(1))
    R_b = np.broadcast_to([[0.02, 0.005], [0.005, 0.03]], R.shape)
    for q, foot in ((0.7, None), (0.2, (R_b, 0.3))):
        kf = kalman_filter(t, z, R, q, foot)
        imm = imm_filter(t, z, R, (q, q), (0.3, 1.0), foot)
        scale = np.abs(kf["x"]).max()  # rounding of sums of this size
        for (x, P), (x_ref, P_ref) in ((mixture(imm["mu"], imm["x"], imm["P"]), (kf["x"], kf["P"])),
                                       (smoothed(imm), rts_smoother(kf))):
            np.testing.assert_allclose(x, x_ref, atol=1e-12 * scale)
            np.testing.assert_allclose(P, P_ref, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(imm["loglik"], innovation_log_likelihood(t, z, R, q, foot), rtol=1e-12)


def regime_sequences(t, qs, rates):
    """Every sequence of the models over a track's steps t (L,) s with its prior probability: the first model
    from the chain's stationary distribution, each next one by the switching probabilities over its step."""
    stationary = np.array([rates[1], rates[0]]) / sum(rates)
    for seq in itertools.product(range(len(qs)), repeat=len(t)):
        p = stationary[seq[0]]
        for k in range(1, len(t)):
            stay = np.exp(-rates[seq[k - 1]] * (t[k] - t[k - 1]))
            p *= stay if seq[k] == seq[k - 1] else 1 - stay
        yield seq, p


def gaussian_of_sequence(t, R, qs, seq):
    """The joint covariance of one track's measurements and velocities, in closed form, when step k (from t[k-1]
    to t[k]) takes white acceleration qs[seq[k]]: per axis x(t) = x0 + v0 s + int (s - r) a(r) dr, v(t) = v0 +
    int a(r) dr, s = t - t[0], x0 ~ N(0, P0^2), v0 ~ N(0, V0^2). Returns C_zz (2L, 2L) (with R) and C_vz (2L, 2L),
    coordinates ordered (x, y) per step."""
    s = t - t[0]
    q = np.array([qs[m] for m in seq[1:]])
    a, b = s[:-1], s[1:]  # each step's interval of r

    def integral(f):  # sum over steps of q int_a^b f(r) dr up to min(s_j, s_l), f's antiderivative given
        j, l = np.meshgrid(s, s, indexing="ij")
        upper = np.minimum(b, np.minimum(j, l)[..., None])
        return np.sum(q * np.where(upper > a, f(j[..., None], l[..., None], upper) - f(j[..., None], l[..., None], a), 0), axis=-1)

    xx = P0**2 + V0**2 * np.outer(s, s) + integral(lambda j, l, r: j * l * r - (j + l) * r**2 / 2 + r**3 / 3)
    vx = V0**2 * np.outer(np.ones_like(s), s) + integral(lambda j, l, r: l * r - r**2 / 2)  # Cov(v(s_j), x(s_l))
    C_zz = np.kron(xx, np.eye(2)) + np.block([[R[k] if k == m else np.zeros((2, 2)) for m in range(len(t))]
                                              for k in range(len(t))])
    return C_zz, np.kron(vx, np.eye(2))


def exact_posterior(t, z, R, qs, rates):
    """The log-likelihood of one track's measurements z (L, 2) (the 2 pi term dropped) and its velocities'
    posterior means (L, 2) and variances (L, 2) under the two-regime model: the sum over all regime sequences."""
    like, means, second = [], [], []
    for seq, p in regime_sequences(t, qs, rates):
        C_zz, C_vz = gaussian_of_sequence(t, R, qs, seq)
        y = z.reshape(-1)
        like.append(np.log(p) - 0.5 * (np.linalg.slogdet(C_zz)[1] + y @ np.linalg.solve(C_zz, y)))
        s = t - t[0]
        C_vv = np.kron(V0**2 + sum(qs[m] * np.clip(np.minimum.outer(s, s) - s[k - 1], 0, s[k] - s[k - 1])
                                   for k, m in enumerate(seq) if k), np.eye(2))
        mean = C_vz @ np.linalg.solve(C_zz, y)
        cov = C_vv - C_vz @ np.linalg.solve(C_zz, C_vz.T)
        means.append(mean.reshape(-1, 2))
        second.append(np.diag(cov).reshape(-1, 2) + means[-1]**2)
    w = np.exp(np.array(like) - max(like))
    loglik = np.log(w.sum()) + max(like)
    w /= w.sum()
    mean = np.einsum("s,sld->ld", w, means)
    return loglik, mean, np.einsum("s,sld->ld", w, second) - mean**2


def test_likelihood_is_the_sum_over_regime_sequences_where_the_imm_is_exact():
    """The IMM merges its models' states at each step, so its likelihood is exact where nothing is merged: over
    two steps (both models start from the same state), and with no switching (each model its own Kalman filter)."""
    rng = np.random.default_rng(2)
    qs = (0.05, 3.0)
    for L, rates in ((2, (0.4, 1.5)), (6, (1e-9, 1e-9))):
        t = np.cumsum(rng.uniform(0.05, 0.3, L))
        z = np.column_stack([2.0 + 1.2 * t, 18.0 - 0.4 * t]) + rng.normal(0, 0.2, (L, 2))
        R = np.array([[[0.01 + 0.002 * k, 0.003], [0.003, 0.02]] for k in range(L)])
        exact = exact_posterior(t, z, R, qs, rates)[0]
        np.testing.assert_allclose(imm_filter(t[None], z[None], R[None], qs, rates)["loglik"], exact, rtol=1e-9)

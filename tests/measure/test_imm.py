"""The two-regime motion model of homocal.measure.kalman (imm_filter, imm_smoother) against independent
computations: with its two q equal it is the Kalman filter and RTS smoother; its likelihood and smoothed states
against the exact sum over the regime sequences, each a Gaussian written in closed form; on tracks drawn from
the two-regime model its error bars against the single-q filter's, and the fitted scale of their noise."""
import itertools

import numpy as np
import pytest

from homocal.measure.kalman import (fit_accel_psd, fit_noise_scale, imm_filter, imm_smoother,
                                    innovation_log_likelihood, kalman_filter, mixture, rts_smoother)
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


def two_regime_tracks(rng, qs, rates, n=100, L=150, dt=0.05, s=0.1):
    """n tracks of L steps dt apart drawn from the two-regime model: the model at each step from the Markov
    chain (leaving model i with probability 1 - exp(-rates[i] dt)), its white acceleration qs[model] over the
    step, each axis's step covariance from its definition; measured with white noise s (m) per axis. Returns
    kalman_filter's (t, z, R), the true velocities (n, L, 2) and models (n, L)."""
    Qa = np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    model = (rng.random(n) < rates[0] / sum(rates)).astype(int)
    pos, vel = rng.normal(0, 10, (n, 2)), rng.normal(0, 1.4, (n, 2))
    z, v, m = np.empty((n, L, 2)), np.empty((n, L, 2)), np.empty((n, L), int)
    for k in range(L):
        if k:
            model = np.where(rng.random(n) < 1 - np.exp(-np.array(rates)[model] * dt), 1 - model, model)
            w = rng.multivariate_normal(np.zeros(2), Qa, (n, 2)) * np.sqrt(np.array(qs)[model])[:, None, None]
            pos, vel = pos + vel * dt + w[..., 0], vel + w[..., 1]
        z[:, k], v[:, k], m[:, k] = pos + rng.normal(0, s, (n, 2)), vel, model
    t = np.broadcast_to(np.arange(L) * dt, (n, L))
    return (t, z, np.broadcast_to(s**2 * np.eye(2), (n, L, 2, 2))), v, m


@pytest.mark.slow
def test_imm_bars_follow_the_regime_where_one_q_cannot():
    """Walkers mostly steady (q 0.02) with manoeuvres (q 4, about a sixth of the time): the share of true
    velocities inside the smoothed 68 % ellipse (chi-square(2)), per true regime, 1 s from the tracks' ends.
    One q (the maximum-likelihood one) is too wide on the steady and covers under half its share in the
    manoeuvres; the IMM with the true constants covers the manoeuvres within 10 pp of 68 % and is nearer it on
    the steady (it is not at 68 % there: a steady stretch cannot be told from a short manoeuvre at once, and
    Kim's smoother is an approximation). Binomial spread of these shares: under 1 pp."""
    qs, rates = (0.02, 4.0), (0.2, 1.0)
    tracks, v, m = two_regime_tracks(np.random.default_rng(3), qs, rates)
    inner, m = slice(20, -20), m[:, 20:-20]
    cover = {}
    for name, (x, P) in {"imm": smoothed(imm_filter(*tracks, qs, rates)),
                         "one q": rts_smoother(kalman_filter(*tracks, fit_accel_psd(*tracks)))}.items():
        e = (x[..., 2:4] - v)[:, inner]
        nees = np.einsum("...i,...ij,...j->...", e, np.linalg.inv(P[:, inner, 2:4, 2:4]), e)
        cover[name] = [np.mean(nees[m == r] < -2 * np.log(1 - 0.6827)) for r in (0, 1)]
    assert abs(cover["imm"][1] - 0.6827) < 0.10 and cover["one q"][1] < 0.6827 / 2, cover
    assert 0.6827 < cover["imm"][0] < cover["one q"][0], cover


@pytest.mark.parametrize("qs, rates, c", [((0.02, 4.0), (0.2, 1.0), 0.5), ((0.3,), (), 2.0)])
def test_noise_scale_fit_recovers_the_scale_of_the_drawn_noise(qs, rates, c):
    """Tracks drawn from the motion model (two regimes, or one q) with white noise s per axis, given to the fit
    with R stating s / c: the fitted scale is c. 6,000 measured points: the scale's standard error is about
    1/sqrt(4 x 6,000), 0.7 % (less precise where the motion's noise shares the innovations: a few %); 10 %."""
    (t, z, R), _, _ = two_regime_tracks(np.random.default_rng(5), qs if len(qs) == 2 else qs * 2,
                                        rates or (0.2, 1.0), n=60, L=100)
    assert abs(np.log(fit_noise_scale([(t, z, R / c**2, None)], qs, rates) / c)) < 0.1

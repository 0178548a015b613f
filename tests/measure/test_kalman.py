"""The filter and smoother of homocal.measure.kalman against independent computations: the smoother's states are
the batch least-squares solution of the whole track's Gaussian model, the filter's last state too; the speed's
delta-method sigma against Monte Carlo; a mixture's bars against the quantiles of draws from it."""
from math import erf

import numpy as np
import pytest

from homocal.measure.kalman import (ACCEL_PSD_BOUNDS, HALF_WIDTH_TOLERANCE, fit_accel_psd, innovation_log_likelihood,
                                    kalman_filter, mixture, mixture_half_width, mixture_speed, rts_smoother,
                                    speed_and_sigma, start_state, transition)
from homocal.measure.kalman import START_POSITION_SIGMA_M as P0, START_SPEED_SIGMA_MPS as V0


def batch_solution(t, z, R, q, foot=None):
    """Mean (L, d) and marginal covariances (L, d, d) of all states given all measurements: the Gaussian model
    (prior, transitions, measurements) written as one weighted least-squares problem and solved densely. foot:
    None (d = 4), or (R_b (L, 2, 2), tau): the measurement error's correlated part b, an AR(1) (d = 6), written
    here from its definition: b_0 ~ N(0, R_b[0]), b_k = exp(-dt / tau) b_(k-1) + N(0, (1 - exp(-2 dt / tau)) R_b[k]),
    z_k = (x, y)_k + b_k + N(0, R[k])."""
    L = len(t)
    d = 4 if foot is None else 6
    x0, P0 = start_state(1)
    blocks, rhs = [], []  # whitened rows: W (A X - b)

    def add(A, b, cov):
        W = np.linalg.inv(np.linalg.cholesky(cov))
        blocks.append(W @ A)
        rhs.append(W @ b)

    A = np.zeros((4, d * L))
    A[:, :4] = np.eye(4)
    add(A, x0[0], P0[0])
    if foot is not None:
        R_b, tau = foot
        A = np.zeros((2, d * L))
        A[:, 4:6] = np.eye(2)
        add(A, np.zeros(2), R_b[0])
    for k in range(1, L):
        dt = t[k] - t[k - 1]
        F, Q = transition(np.array([dt]), q)  # the motion's part (checked above without the foot)
        A = np.zeros((4, d * L))
        A[:, d * k:d * k + 4] = np.eye(4)
        A[:, d * k - d:d * k - d + 4] = -F[0]
        add(A, np.zeros(4), Q[0])
        if foot is not None:
            A = np.zeros((2, d * L))
            A[:, d * k + 4:d * k + 6] = np.eye(2)
            A[:, d * k - 2:d * k] = -np.exp(-dt / tau) * np.eye(2)
            add(A, np.zeros(2), (1 - np.exp(-2 * dt / tau)) * R_b[k])
    for k in range(L):
        if np.isfinite(z[k]).all():
            A = np.zeros((2, d * L))
            A[:, d * k:d * k + 2] = np.eye(2)
            if foot is not None:
                A[:, d * k + 4:d * k + 6] = np.eye(2)
            add(A, z[k], R[k])
    J, b = np.vstack(blocks), np.concatenate(rhs)
    info = J.T @ J
    cov = np.linalg.inv(info)
    mean = cov @ (J.T @ b)
    return mean.reshape(L, d), np.array([cov[d * k:d * k + d, d * k:d * k + d] for k in range(L)])


def test_smoother_is_the_batch_solution():
    rng = np.random.default_rng(1)
    L = 9
    t = np.cumsum(np.r_[0.0, rng.uniform(0.05, 0.3, L - 1)])  # uneven steps: a gap in the track
    z = np.column_stack([1.0 + 1.3 * t, 20.0 - 0.4 * t]) + rng.normal(0, 0.1, (L, 2))
    z[4] = np.nan  # a point beyond the horizon: predicted only
    A = rng.normal(0, 0.2, (L, 2, 2))
    R = A @ A.transpose(0, 2, 1) + 0.01 * np.eye(2)  # correlated x, y errors, as a mapping's
    q = 0.5
    filtered = kalman_filter(t[None], z[None], R[None], q)
    xs, Ps = rts_smoother(filtered)
    mean, cov = batch_solution(t, z, R, q)
    # conditioning: the prior's 100 m against 0.1 m measurements, about 1e6; float64 leaves ~1e-10 relative
    np.testing.assert_allclose(xs[0], mean, rtol=0, atol=1e-8 * np.abs(mean).max())
    np.testing.assert_allclose(Ps[0], cov, rtol=0, atol=1e-8 * np.abs(cov).max())
    # the filter's state at the last step is conditioned on everything: the same
    np.testing.assert_allclose(filtered["x"][0, -1], mean[-1], rtol=0, atol=1e-8 * np.abs(mean).max())
    # and at step 5 it is the batch solution of the first six measurements
    m5, c5 = batch_solution(t[:6], z[:6], R[:6], q)
    np.testing.assert_allclose(filtered["x"][0, 5], m5[-1], rtol=0, atol=1e-8 * np.abs(m5).max())
    np.testing.assert_allclose(filtered["P"][0, 5], c5[-1], rtol=0, atol=1e-8 * np.abs(c5).max())


def test_batched_tracks_are_independent_and_padding_is_inert():
    rng = np.random.default_rng(2)
    t1, t2 = np.arange(6) * 0.1, np.arange(4) * 0.2
    z1, z2 = rng.normal(0, 1, (6, 2)), rng.normal(0, 1, (4, 2))
    R = np.broadcast_to(0.04 * np.eye(2), (6, 2, 2))
    t = np.vstack([t1, np.r_[t2, t2[-1], t2[-1]]])  # track 2 padded: its last time repeated, no measurement
    z = np.stack([z1, np.vstack([z2, np.full((2, 2), np.nan)])])
    xs, _ = rts_smoother(kalman_filter(t, z, np.stack([R, R])))
    alone, _ = rts_smoother(kalman_filter(t2[None], z2[None], R[None, :4]))
    np.testing.assert_allclose(xs[1, :4], alone[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(xs[1, 4:], np.broadcast_to(alone[0, -1], (2, 4)), rtol=0, atol=1e-9)


def test_speed_sigma_against_monte_carlo():
    v = np.array([1.2, -0.5])
    A = np.array([[0.03, 0.01], [0.0, 0.02]])
    Pv = A @ A.T
    speed, sigma = speed_and_sigma(v, Pv)
    draws = np.random.default_rng(3).multivariate_normal(v, Pv, 400_000)
    assert speed == np.hypot(1.2, 0.5)
    # Monte Carlo: std error 0.1 %; the delta method's own error ~ sigma / speed ~ 2 % here
    np.testing.assert_allclose(sigma, np.linalg.norm(draws, axis=1).std(), rtol=0.03)
    # at rest: the largest spread of the velocity
    assert speed_and_sigma(np.zeros(2), Pv)[1] == np.sqrt(np.linalg.eigvalsh(Pv)[-1])


def test_mixture_half_width_is_the_quantile_of_draws_from_the_mixture():
    """Rows of two-normal mixtures (a narrow core with a wide tail, two apart, one component) about a centre: the
    half-width holding 68.27 % (k = 1) and 95.45 % (k = 2) against the same quantile of |draw - centre| over
    draws from each mixture, within 4 of the sample quantile's standard errors (sqrt(p (1 - p) / n) over the
    density of |draw - centre| there, written from the components) plus the bisection's tolerance."""
    w = np.array([[0.97, 0.03], [0.6, 0.4], [1.0, 0.0]])
    means = np.array([[1.30, 1.10], [0.40, 1.00], [2.00, 2.00]])
    sigmas = np.array([[0.05, 0.70], [0.10, 0.20], [0.30, 0.30]])
    centre = np.array([1.29, 0.70, 2.10])
    rng = np.random.default_rng(8)
    n = 400_000
    for k in (1.0, 2.0):
        h = mixture_half_width(centre, w, means, sigmas, k)
        share = erf(k / np.sqrt(2))
        for i in range(len(centre)):
            which = rng.random(n) < w[i, 0]
            draws = np.where(which, rng.normal(means[i, 0], sigmas[i, 0], n), rng.normal(means[i, 1], sigmas[i, 1], n))
            quantile = np.quantile(np.abs(draws - centre[i]), share)
            density = sum(w[i, m] * (np.exp(-0.5 * ((centre[i] + side * quantile - means[i, m]) / sigmas[i, m])**2))
                          / (sigmas[i, m] * np.sqrt(2 * np.pi)) for m in range(2) for side in (1, -1))
            se = np.sqrt(share * (1 - share) / n) / density
            assert abs(h[i] - quantile) < 4 * se + HALF_WIDTH_TOLERANCE * quantile, (k, i, h[i], quantile, se)
    # point masses (sigma 0: exact states): 90 % at the centre holds 68 %; 95.45 % needs the 10 % 0.2 away
    exact = [mixture_half_width(np.array([1.0]), np.array([[0.9, 0.1]]), np.array([[1.0, 1.2]]), np.zeros((1, 2)), k)[0]
             for k in (1.0, 2.0)]
    assert exact[0] < 1e-12 and abs(exact[1] - 0.2) <= HALF_WIDTH_TOLERANCE * 0.2, exact
    # the narrow core's bar is far under the moment-matched sigma, which the tail's variance dominates
    assert mixture_half_width(centre, w, means, sigmas)[0] < 0.5 * np.sqrt(np.sum(w[0] * (sigmas[0]**2 + (means[0] - w[0] @ means[0])**2)))


def test_one_models_speed_sigma_is_the_delta_method_sigma_exactly():
    rng = np.random.default_rng(9)
    v = rng.normal(0, 1, (50, 1, 2))
    A = rng.normal(0, 0.1, (50, 1, 2, 2))
    Pv = A @ A.transpose(0, 1, 3, 2)
    v[0] = 0.0  # at rest: the largest spread
    speed, sigma = mixture_speed(np.ones((50, 1)), v, Pv)
    ref_speed, ref_sigma = speed_and_sigma(v[:, 0], Pv[:, 0])
    np.testing.assert_array_equal(speed, ref_speed)
    np.testing.assert_array_equal(sigma, ref_sigma)
    # and of a mixture: the speed is the mean velocity's (as mixture gives it), the bar about it
    w = np.array([[0.9, 0.1]])
    v2, P2 = np.array([[[1.0, 0.0], [1.0, 0.5]]]), np.array([[np.eye(2) * 0.01, np.eye(2) * 0.25]])
    assert mixture_speed(w, v2, P2)[0][0] == np.linalg.norm(mixture(w, v2, P2)[0][0])


def test_smoother_over_a_padded_track_whose_last_measurement_is_exact():
    """A shorter track padded to the batch's length (dt = 0, no measurement) whose last measurement has zero
    covariance (a foot point's sigma of 0): its filtered covariance is singular there; the smoother keeps that
    point exactly, the padding repeats it, and the track's states are those of the track smoothed alone."""
    t = np.array([np.arange(6) / 10, np.r_[np.arange(3) / 10, [0.2] * 3]])
    z = np.full((2, 6, 2), np.nan)
    z[0] = np.column_stack([np.zeros(6), np.arange(6) / 10])
    z[1, :3] = np.column_stack([np.ones(3), 0.5 * np.arange(3) / 10 + [0.0, 0.01, -0.01]])
    R = np.full((2, 6, 2, 2), np.nan)
    R[0], R[1, :3] = 0.01 * np.eye(2), 0.01 * np.eye(2)
    R[1, 2] = 0.0
    x, P = rts_smoother(kalman_filter(t, z, R))
    np.testing.assert_allclose(x[1, 2, :2], z[1, 2], atol=1e-12)
    np.testing.assert_allclose(x[1, 3:], np.broadcast_to(x[1, 2], (3, 4)), atol=0)
    alone, _ = rts_smoother(kalman_filter(t[1:, :3], z[1:, :3], R[1:, :3]))
    np.testing.assert_allclose(x[1, :3], alone[0], rtol=1e-9, atol=1e-12)


def test_smoother_with_a_correlated_foot_error_is_the_batch_solution():
    """The state augmented with an AR(1) foot-point error (kalman_filter(foot=...)): smoother and filter against
    the batch least-squares solution of the same model written from its definition."""
    rng = np.random.default_rng(4)
    L = 9
    t = np.cumsum(np.r_[0.0, rng.uniform(0.05, 0.3, L - 1)])
    z = np.column_stack([1.0 + 1.3 * t, 20.0 - 0.4 * t]) + rng.normal(0, 0.1, (L, 2))
    z[4] = np.nan
    A = rng.normal(0, 0.2, (L, 2, 2))
    R_b = A @ A.transpose(0, 2, 1) + 0.01 * np.eye(2)  # the correlated part, changing along the track
    R = np.broadcast_to(1e-4 * np.eye(2), (L, 2, 2))  # a small white part
    q, tau = 0.5, 0.4
    filtered = kalman_filter(t[None], z[None], R[None], q, (R_b[None], tau))
    xs, Ps = rts_smoother(filtered)
    mean, cov = batch_solution(t, z, R, q, (R_b, tau))
    assert xs.shape == (1, L, 6)
    # conditioning as above (the prior's 100 m against 1 cm white measurements, 1e8): float64 leaves ~1e-8
    np.testing.assert_allclose(xs[0], mean, rtol=0, atol=1e-7 * np.abs(mean).max())
    np.testing.assert_allclose(Ps[0], cov, rtol=0, atol=1e-7 * np.abs(cov).max())
    m5, c5 = batch_solution(t[:6], z[:6], R[:6], q, (R_b[:6], tau))
    np.testing.assert_allclose(filtered["x"][0, 5], m5[-1], rtol=0, atol=1e-7 * np.abs(m5).max())


def test_a_correlated_foot_error_of_no_memory_is_white_noise():
    """tau -> 0: the foot error forgets itself between frames (phi = exp(-dt / tau) = 0), so the augmented filter
    with no white part is the plain filter whose measurement noise is R_b."""
    rng = np.random.default_rng(5)
    L = 12
    t = np.arange(L) * 0.05
    z = np.column_stack([0.5 + 1.1 * t, 15.0 + 0.3 * t]) + rng.normal(0, 0.05, (L, 2))
    R_b = np.broadcast_to(np.array([[0.004, 0.001], [0.001, 0.009]]), (L, 2, 2))
    xs, Ps = rts_smoother(kalman_filter(t[None], z[None], np.zeros((1, L, 2, 2)), 0.5, (R_b[None], 1e-6)))
    plain, plain_P = rts_smoother(kalman_filter(t[None], z[None], R_b[None], 0.5))
    np.testing.assert_allclose(xs[0, :, :4], plain[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(Ps[0, :, :4, :4], plain_P[0], rtol=0, atol=1e-9)


def test_correlated_foot_error_velocity_covariance_against_monte_carlo():
    """Tracks drawn from the model itself (constant velocity, white acceleration q, an AR(1) foot error of
    correlation time tau): the smoothed velocity's error has the covariance the smoother states (its normalised
    squared error averages 2, chi-square with 2 degrees of freedom), and the plain filter, blind to the
    correlation, states one too small."""
    rng = np.random.default_rng(6)
    n, L, dt, q, tau, s = 1000, 30, 0.05, 0.05, 0.5, 0.1
    t = np.broadcast_to(np.arange(L) * dt, (n, L))
    F, Q = transition(np.full(n, dt), q)
    x = np.column_stack([rng.normal(0, 5, (n, 2)), rng.normal(0, 1, (n, 2))])
    phi = np.exp(-dt / tau)
    b = rng.normal(0, s, (n, 2))
    truth, z = np.empty((n, L, 4)), np.empty((n, L, 2))
    for k in range(L):
        if k:
            x = np.einsum("nij,nj->ni", F, x) + rng.multivariate_normal(np.zeros(4), Q[0], n)
            b = phi * b + rng.normal(0, s * np.sqrt(1 - phi**2), (n, 2))
        truth[:, k], z[:, k] = x, x[:, :2] + b
    R_b = np.broadcast_to(s**2 * np.eye(2), (n, L, 2, 2))
    k = L // 2
    nees = {}
    for name, args in (("correlated", (np.zeros((n, L, 2, 2)), q, (R_b, tau))), ("white", (R_b, q))):
        xs, Ps = rts_smoother(kalman_filter(t, z, *args))
        e = xs[:, k, 2:4] - truth[:, k, 2:]
        nees[name] = np.einsum("ni,nij,nj->n", e, np.linalg.inv(Ps[:, k, 2:4, 2:4]), e).mean()
    # the mean of 1000 chi-square(2) draws: standard error 2 / sqrt(1000) = 0.063; 4 of them
    assert abs(nees["correlated"] - 2) < 0.25, nees
    assert nees["white"] > 3, nees  # the white filter's bars too narrow: its squared errors several times its variance


def joint_log_density(t, z, R, q, foot=None):
    """ln N(z; 0, C) of one track's measurements z (L, 2) (NaN rows left out) without the 2 pi term, C written in
    closed form: per axis x(t) = x0 + v0 t + the integral of white acceleration twice, x0 ~ N(0, P0^2),
    v0 ~ N(0, V0^2), Cov = P0^2 + V0^2 t_j t_k + q m^2 (3 M - m) / 6 (m, M the smaller and larger time since
    the first step: integrated Brownian motion), plus R on each step and, with foot = (R_b (2, 2), tau), the
    stationary AR(1) exp(-|t_j - t_k| / tau) R_b."""
    s = t - t[0]
    m, M = np.minimum.outer(s, s), np.maximum.outer(s, s)
    axis = P0**2 + V0**2 * np.outer(s, s) + q * m**2 * (3 * M - m) / 6
    C = np.kron(axis, np.eye(2)) + np.kron(np.eye(len(t)), np.ones((2, 2))) * np.concatenate(
        [np.concatenate(list(R), axis=1)] * len(t))  # the block diagonal of R
    if foot is not None:
        C += np.kron(np.exp(-np.abs(s[:, None] - s) / foot[1]), foot[0])
    ok = np.repeat(np.isfinite(z).all(axis=1), 2)
    C, y = C[np.ix_(ok, ok)], z.reshape(-1)[ok]
    return -0.5 * (np.linalg.slogdet(C)[1] + y @ np.linalg.solve(C, y))


def test_innovation_log_likelihood_is_the_joint_gaussian_density():
    """The prediction-error decomposition: the sum of the innovations' log densities is the joint density of all
    of a track's measurements, written here in closed form (irregular steps, a skipped measurement; white noise
    and the correlated foot error)."""
    rng = np.random.default_rng(7)
    t = np.cumsum(rng.uniform(0.03, 0.12, 9))
    z = np.column_stack([2.0 + 1.2 * t, 18.0 - 0.4 * t]) + rng.normal(0, 0.1, (9, 2))
    z[4] = np.nan
    R = np.array([[[0.01 + 0.002 * k, 0.003], [0.003, 0.02]] for k in range(9)])
    R_b = np.array([[0.02, 0.005], [0.005, 0.03]])
    for q in (0.01, 0.5, 3.0):
        np.testing.assert_allclose(innovation_log_likelihood(t[None], z[None], R[None], q),
                                   joint_log_density(t, z, R, q), rtol=1e-9)
        foot = (np.broadcast_to(R_b, (1, 9, 2, 2)), 0.3)
        np.testing.assert_allclose(innovation_log_likelihood(t[None], z[None], R[None], q, foot),
                                   joint_log_density(t, z, R, q, (R_b, 0.3)), rtol=1e-9)


def simulated_tracks(rng, q, n=60, L=60, dt=0.05, s=0.1, tau=None):
    """n tracks of L steps dt apart drawn from the model with white acceleration q (m^2/s^3), each axis's step
    covariance written from its definition, measured with noise s (m) per axis: white, or an AR(1) of
    correlation time tau. Returns kalman_filter's (t, z, R) or (t, z, R, foot) of the model."""
    Qa = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    pos, vel = rng.normal(0, 10, (n, 2)), rng.normal(0, 1.4, (n, 2))
    b = rng.normal(0, s, (n, 2))
    phi = 0.0 if tau is None else np.exp(-dt / tau)
    z = np.empty((n, L, 2))
    for k in range(L):
        if k:
            w = rng.multivariate_normal(np.zeros(2), Qa, (n, 2))  # (n, axis, (position, velocity))
            pos, vel = pos + vel * dt + w[..., 0], vel + w[..., 1]
            b = phi * b + rng.normal(0, s * np.sqrt(1 - phi**2), (n, 2))
        z[:, k] = pos + b
    t = np.broadcast_to(np.arange(L) * dt, (n, L))
    R = np.broadcast_to(s**2 * np.eye(2), (n, L, 2, 2))
    return (t, z, R) if tau is None else (t, z, np.zeros((n, L, 2, 2)), (R, tau))


@pytest.mark.slow
def test_fitted_q_recovers_the_q_tracks_were_drawn_with():
    """On tracks drawn from the model with a known q (white and correlated measurement noise), the
    maximum-likelihood q lies within 4 of its standard errors of the truth; the standard error of ln q from the
    likelihood's curvature (the observed information), small enough for the check to tell q from 2 q."""
    rng = np.random.default_rng(8)
    for q, tau in ((0.05, None), (1.0, None), (0.1, 0.3)):
        tracks = simulated_tracks(rng, q, tau=tau)
        fitted = fit_accel_psd(*tracks)
        ll = [innovation_log_likelihood(*tracks[:3], fitted * np.exp(h), *tracks[3:]) for h in (-0.1, 0.0, 0.1)]
        se = 1 / np.sqrt(-(ll[0] - 2 * ll[1] + ll[2]) / 0.1**2)
        assert se < 0.15, (q, tau, se)
        assert abs(np.log(fitted / q)) < 4 * se, (q, tau, fitted, se)


def test_fitted_q_stops_at_its_bound():
    """Tracks far wilder than people (q 1000 m^2/s^3): the fit stops at its upper bound."""
    wild = simulated_tracks(np.random.default_rng(9), 1e3, n=20, L=30)
    assert ACCEL_PSD_BOUNDS[1] / 1.1 < fit_accel_psd(*wild) <= ACCEL_PSD_BOUNDS[1]

"""The filter and smoother of homocal.measure.kalman against independent computations: the smoother's states are
the batch least-squares solution of the whole track's Gaussian model, the filter's last state too; the speed's
delta-method sigma against Monte Carlo."""
import numpy as np

from homocal.measure.kalman import kalman_filter, rts_smoother, speed_and_sigma, start_state, transition


def batch_solution(t, z, R, q):
    """Mean (L, 4) and marginal covariances (L, 4, 4) of all states given all measurements: the Gaussian model
    (prior, transitions, measurements) written as one weighted least-squares problem and solved densely."""
    L = len(t)
    x0, P0 = start_state(1)
    blocks, rhs = [], []  # whitened rows: W (A X - b)

    def add(A, b, cov):
        W = np.linalg.inv(np.linalg.cholesky(cov))
        blocks.append(W @ A)
        rhs.append(W @ b)

    A = np.zeros((4, 4 * L))
    A[:, :4] = np.eye(4)
    add(A, x0[0], P0[0])
    for k in range(1, L):
        F, Q = transition(np.array([t[k] - t[k - 1]]), q)
        A = np.zeros((4, 4 * L))
        A[:, 4 * k:4 * k + 4] = np.eye(4)
        A[:, 4 * k - 4:4 * k] = -F[0]
        add(A, np.zeros(4), Q[0])
    for k in range(L):
        if np.isfinite(z[k]).all():
            A = np.zeros((2, 4 * L))
            A[:, 4 * k:4 * k + 2] = np.eye(2)
            add(A, z[k], R[k])
    J, b = np.vstack(blocks), np.concatenate(rhs)
    info = J.T @ J
    cov = np.linalg.inv(info)
    mean = cov @ (J.T @ b)
    return mean.reshape(L, 4), np.array([cov[4 * k:4 * k + 4, 4 * k:4 * k + 4] for k in range(L)])


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

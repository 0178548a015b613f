"""The heavy-tailed (Student-t) foot noise of homocal.measure.kalman against independent computations: the
variational Bayes update against its iteration written out by hand on scalars, the innovations' density
against scipy's multivariate t, a huge dof against the Kalman filter, the IMM against the Kalman filter with
the same tails; the maximum-likelihood scale and degrees of freedom on tracks drawn from the model; bad
values refused."""
import numpy as np
import pytest
from scipy.stats import multivariate_t

from homocal.measure.kalman import (STUDENT_WEIGHT_TOLERANCE, fit_student_noise, imm_filter, innovation_log_density,
                                    innovation_log_likelihood, kalman_filter, mixture, rts_smoother, student_update,
                                    summed_log_likelihood)
from homocal.measure.tracks import foot_noise_options, measure_tracks
from homocal.geometry import PinholeCamera


def hand_update(x, p, z, r, dof, w):
    """One track's update on scalars with diagonal P and R (each axis on its own given w), at weight w: the
    posterior means and variances per axis and the next weight (dof + 2) / (dof + sum ((z - m)^2 + p') / r)."""
    m, pp = [], []
    for a in range(2):
        k = p[a] / (p[a] + r[a] / w)
        m.append(x[a] + k * (z[a] - x[a]))
        pp.append((1 - k) * p[a])
    spread = sum(((z[a] - m[a]) ** 2 + pp[a]) / r[a] for a in range(2))
    return m, pp, (dof + 2) / (dof + spread)


@pytest.mark.parametrize("z, dof", [((0.3, -0.2), 4.0), ((2.5, 1.0), 3.0), ((6.0, -4.0), 1.5), ((0.05, 0.0), 30.0)])
def test_student_update_is_the_variational_fixed_point(z, dof):
    """The update's weight is the fixed point of the hand-written iteration: its error there is within what
    the stopping rule leaves (STUDENT_WEIGHT_TOLERANCE x w times rho / (1 - rho), rho the map's slope at the
    fixed point by a central difference), and its state is the hand-written posterior at that weight."""
    x, p, r = (0.0, 0.0), (0.8, 0.5), (0.6, 0.9)
    P = np.diag([p[0], p[1], 2.0, 2.0])[None]
    xu, Pu, w = student_update(np.zeros((1, 4)), P, np.array([z]), np.diag(r)[None], dof)
    w_star = 1.0
    for _ in range(10_000):  # to the end of the rounding
        w_next = hand_update(x, p, z, r, dof, w_star)[2]
        if w_next == w_star:
            break
        w_star = w_next
    h = 1e-6 * w_star
    rho = abs(hand_update(x, p, z, r, dof, w_star + h)[2] - hand_update(x, p, z, r, dof, w_star - h)[2]) / (2 * h)
    assert rho < 1  # a contraction there
    assert abs(w[0] - w_star) <= 2 * STUDENT_WEIGHT_TOLERANCE * w_star * max(rho / (1 - rho), 1)
    m, pp, _ = hand_update(x, p, z, r, dof, w[0])
    np.testing.assert_allclose(xu[0, :2], m, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(np.diag(Pu[0])[:2], pp, rtol=1e-12)
    np.testing.assert_array_equal(xu[0, 2:], 0.0)  # no velocity covariance with the position: untouched


def test_a_far_foot_point_counts_less():
    """The weight falls as the measurement lies farther (a jump counts little) and is about 1 for one that
    lies where it is expected to."""
    P, R = np.eye(4)[None] * 0.1, np.eye(2)[None] * 0.1
    w = [student_update(np.zeros((1, 4)), P, np.array([[d, 0.0]]), R, 4.0)[2][0] for d in (0.1, 1.0, 5.0)]
    assert w[0] > 1.0 > w[1] > w[2] and w[2] < 0.1


def test_innovation_log_density_is_scipys_multivariate_t():
    """ln t_dof(nu; 0, S) + ln 2 pi (the constant the filter drops), and the normal's as dof grows."""
    rng = np.random.default_rng(3)
    A = rng.normal(size=(5, 2, 2))
    S = A @ A.transpose(0, 2, 1) + 0.1 * np.eye(2)
    nu = rng.normal(size=(5, 2)) * 2
    for dof in (0.7, 3.0, 40.0):
        ref = [multivariate_t(np.zeros(2), S[i], df=dof).logpdf(nu[i]) + np.log(2 * np.pi) for i in range(5)]
        np.testing.assert_allclose(innovation_log_density(nu, S, dof), ref, rtol=1e-12)
    normal = innovation_log_density(nu, S)
    r2 = np.einsum("ni,ni->n", nu, np.linalg.solve(S, nu[..., None])[..., 0])
    # ln t - ln N = O(r^4 / dof): at dof 1e8 within 1e-6 of it for these r^2
    np.testing.assert_allclose(innovation_log_density(nu, S, 1e8), normal, atol=1e-8 * (1 + r2.max()) ** 2)


def tracks(rng, n=4, L=40, dof=None, scale=1.0):
    """kalman_filter's (t, z, R) of n walkers at 1.3 m/s with irregular steps, a skipped measurement, a padded
    end; their noise normal or (dof) Student-t of scale R times scale^2, drawn as a normal over sqrt(chi^2 / dof)."""
    t = np.cumsum(rng.uniform(0.03, 0.12, (n, L)), axis=1)
    R = np.broadcast_to([[0.012, 0.003], [0.003, 0.02]], (n, L, 2, 2)).copy()
    e = rng.multivariate_normal(np.zeros(2), R[0, 0], (n, L)) * scale
    if dof is not None:
        e /= np.sqrt(rng.chisquare(dof, (n, L, 1)) / dof)
    z = np.stack([2.0 + 1.2 * t, 18.0 - 0.4 * t], axis=-1) + e
    z[0, 5] = np.nan
    t[-1, L // 2:], z[-1, L // 2:] = t[-1, L // 2 - 1], np.nan
    return t, z, R


def test_a_huge_dof_is_the_kalman_filter():
    """dof 1e12: every weight is within (2 + r^2) / dof of 1, so the filtered and smoothed states are the
    Kalman filter's within that share of their updates; the likelihood the normal's to O(r^4 / dof)."""
    t, z, R = tracks(np.random.default_rng(5))
    dof = 1e12
    kf, st = kalman_filter(t, z, R, 0.5), kalman_filter(t, z, R, 0.5, dof=dof)
    ok = np.isfinite(z).all(axis=-1)
    step = np.abs(kf["x"] - kf["x_pred"])[ok].max()  # the largest update
    bound = step * 100 / dof  # r^2 < 100 here, whatever the draw
    np.testing.assert_allclose(st["x"], kf["x"], atol=bound)
    np.testing.assert_allclose(rts_smoother(st)[0], rts_smoother(kf)[0], atol=bound * 10)
    np.testing.assert_allclose(innovation_log_likelihood(t, z, R, 0.5, dof=dof),
                               innovation_log_likelihood(t, z, R, 0.5), atol=ok.sum() * 100**2 / dof)


def test_the_imm_with_equal_models_is_the_kalman_filter_with_the_same_tails():
    """The tails reach the IMM: its two equal models give the Student-t Kalman filter, states and likelihood."""
    t, z, R = tracks(np.random.default_rng(6), dof=2.0)
    kf = kalman_filter(t, z, R, 0.7, dof=3.0)
    imm = imm_filter(t, z, R, (0.7, 0.7), (0.3, 1.0), dof=3.0)
    scale = np.abs(kf["x"]).max()
    np.testing.assert_allclose(mixture(imm["mu"], imm["x"], imm["P"])[0], kf["x"], atol=1e-9 * scale)
    np.testing.assert_allclose(imm["loglik"], innovation_log_likelihood(t, z, R, 0.7, dof=3.0), rtol=1e-9)


def test_the_smoother_ignores_a_jump_the_normal_filter_follows():
    """One foot point 3 m off (hidden feet): with Student-t tails the smoothed track stays within a few sigma
    of the truth there; with normal noise it is pulled by a large part of the jump."""
    t, z, R = tracks(np.random.default_rng(7), dof=None)
    z[1, 20, 0] += 3.0
    truth = 2.0 + 1.2 * t[1, 20]
    normal = rts_smoother(kalman_filter(t, z, R, 0.5))[0][1, 20, 0]
    student = rts_smoother(kalman_filter(t, z, R, 0.5, dof=4.0))[0][1, 20, 0]
    assert abs(normal - truth) > 0.3 and abs(student - truth) < 3 * np.sqrt(R[0, 0, 0, 0])


@pytest.mark.slow
def test_the_fit_recovers_the_scale_and_dof_of_tracks_drawn_from_the_model():
    """Tracks of Student-t noise (scale 0.6 on R, dof 3), drawn apart from the fit's code, under the one-model
    filter they were drawn with, give back c and dof within four standard errors of the fit (from the
    likelihood's curvature at its maximum, central differences on ln c, ln dof) plus the likelihood's own
    bias: it takes each innovation as Student-t with the prediction's normal error in its scale, so the
    innovations look wider and less heavy tailed than the noise by about the share b of the prediction in
    their scale (mean of tr(H P_pred H^T S^-1) / 2 over the steps; it falls as tracks grow): ln c is biased
    up by 0.4-0.6 b and ln dof by 1.5-2.2 b on these tracks at 60-300 steps, so the bounds take b and 3 b."""
    c, dof = 0.6, 3.0
    t, z, R = tracks(np.random.default_rng(8), n=40, L=300, dof=dof, scale=c)
    inputs = [(t, z, R, None)]
    motion = ((1e-4,), ())
    c_hat, dof_hat = fit_student_noise(inputs, *motion)
    s0, h = np.log([c_hat, dof_hat]), 0.05

    def ll(s):
        return summed_log_likelihood(inputs, *motion, float(np.exp(2 * s[0])), float(np.exp(s[1])))

    H, e = np.empty((2, 2)), h * np.eye(2)  # central differences of step 2h on the diagonal, h on each axis off it
    ll0 = ll(s0)
    for i in range(2):
        H[i, i] = (ll(s0 + 2 * e[i]) - 2 * ll0 + ll(s0 - 2 * e[i])) / (4 * h * h)
    H[0, 1] = H[1, 0] = (ll(s0 + e[0] + e[1]) - ll(s0 + e[0] - e[1]) - ll(s0 - e[0] + e[1]) + ll(s0 - e[0] - e[1])) / (4 * h * h)
    se = np.sqrt(np.diag(np.linalg.inv(-H)))
    f = kalman_filter(t, z, c**2 * R, *motion[0], dof=dof)
    ok = np.isfinite(z).all(axis=-1)
    HPH = f["P_pred"][ok][:, :2, :2]
    b = np.mean(np.trace(np.linalg.solve(HPH + c**2 * R[ok], HPH), axis1=1, axis2=2) / 2)
    assert abs(np.log(c_hat / c)) < 4 * se[0] + b and abs(np.log(dof_hat / dof)) < 4 * se[1] + 3 * b, (c_hat, dof_hat, se, b)


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), "4", True])
def test_bad_degrees_of_freedom_are_refused_by_name(bad):
    camera = PinholeCamera()
    ground = np.array([[-3.0, 40.0], [3.0, 40.0], [3.0, 10.0], [-3.0, 10.0]])
    from homocal.geometry import ViewTransformer
    vt = ViewTransformer(camera.project_ground(ground), ground)
    feet = camera.project_ground(np.column_stack([np.zeros(5), 10.0 + np.arange(5.0)]))
    with pytest.raises(ValueError, match="student_dof: expected None or a number > 0"):
        next(measure_tracks(vt, np.arange(5), feet, np.zeros(5, int), 10.0, student_dof=bad))


def test_student_tails_need_a_white_foot_noise():
    with pytest.raises(ValueError, match="foot_tails student: needs foot_noise fixed, not correlated"):
        foot_noise_options("correlated", np.zeros((0, 4)), 1.0, "student")
    with pytest.raises(ValueError, match="foot_tails: expected one of normal, student, got 'cauchy'"):
        foot_noise_options("fixed", np.zeros((0, 4)), 1.0, "cauchy")

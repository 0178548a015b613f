"""homocal.study.method_kernels against the readable correctors, on a few hundred random samples of the paper's
camera: perturbed hand-placed trapezoids and random calibration triples (5-50 m, some off the centre line)."""
import numpy as np
import pytest

from homocal.correctors import HorizonCorrector, LeastChangeCorrector, RegressionCorrector, fit_quadratic_intercept
from homocal.correctors.least_change import mapped_jacobian
from homocal.geometry import PinholeCamera, ViewTransformer
from homocal.study import kernels, method_kernels as mk
from homocal.study.rows import CAL_D, CAL_E_SIGNED, make_cal_table, make_test_table

CAM = PinholeCamera()
GROUND = np.array([[-3.5, 30.0], [3.5, 30.0], [3.5, 8.0], [-3.5, 8.0]])
IMAGE = CAM.project_ground(GROUND)
CANDIDATES_G = np.column_stack([np.tile([0.0, 0.0, 1.5, -2.0], 12), np.linspace(5.0, 50.0, 48)])
CANDIDATES_Q = CAM.project_ground(CANDIDATES_G)
ORIGIN = np.zeros(2)
N_CASES = 300


def cases():
    """(transformer, triple (3,)) per case: a base error of up to +/-10 px on the top corners' rows (a tilt-like
    horizon error) plus 0-3 px on every coordinate, and three distinct calibration candidates."""
    rng = np.random.default_rng(20261123)
    out = []
    for _ in range(N_CASES):
        offsets = rng.uniform(-3.0, 3.0, (4, 2))
        offsets[:2, 1] += rng.uniform(-10.0, 10.0)
        out.append((ViewTransformer(IMAGE + offsets, GROUND), rng.choice(len(CANDIDATES_G), 3, replace=False)))
    return out


CASES = cases()


def cal_table(vt):
    """The study's cal table of every candidate (homocal.study.rows)."""
    return make_cal_table(vt.transform_points(CANDIDATES_Q), CANDIDATES_G, ORIGIN)


def test_intercept_regression_agrees():
    worst = 0.0
    for vt, sel in CASES:
        cal = cal_table(vt)
        i, j, k = sel
        a, b, c, degenerate = mk.fit_quadratic_intercept3(*cal[CAL_D, sel], *cal[CAL_E_SIGNED, sel])
        reg = RegressionCorrector(signed=True, intercept=True).fit(vt, CANDIDATES_Q[sel], CANDIDATES_G[sel], ORIGIN)
        assert degenerate == reg.degenerate_
        assert (a, b, c) == pytest.approx((reg.a_, reg.b_, reg.c_), rel=1e-9, abs=1e-12)
        after = sum(mk.radial_error_intercept(cal, t, a, b, c) for t in (i, j, k)) / 3
        assert after == pytest.approx(reg.error_after_, rel=1e-9, abs=1e-12)
        worst = max(worst, abs(a - reg.a_) / abs(reg.a_))
    assert worst < 1e-9


@pytest.mark.parametrize("d", [[20.0, 20.0, 30.0], [20.0, 20.0, 20.0], [10.0, 10.0 + 1e-9, 40.0]])
def test_degenerate_triples_agree(d):
    e = [0.1, -0.2, 0.4]
    assert mk.fit_quadratic_intercept3(*d, *e) == pytest.approx(fit_quadratic_intercept(np.array(d), np.array(e)))


def test_intercept_path_error_agrees():
    test_g = np.stack(np.meshgrid(np.linspace(-6.0, 6.0, 7), np.linspace(6.0, 50.0, 23)), -1).reshape(-1, 2)
    test_q = CAM.project_ground(test_g)
    for vt, sel in CASES[:40]:
        reg = RegressionCorrector(signed=True, intercept=True).fit(vt, CANDIDATES_Q[sel], CANDIDATES_G[sel], ORIGIN)
        pt = vt.transform_points(test_q)
        test = make_test_table(test_q, vt.m, pt, test_g, ORIGIN)
        expected = np.linalg.norm(reg.transform_points(test_q) - test_g, axis=1).mean()
        before = np.linalg.norm(pt - test_g, axis=1).mean()
        # float32 residual form: path improvement (percent of before) to 1e-3 pp, as test_study_kernels
        assert mk.regression_path_intercept(test, reg.a_, reg.b_, reg.c_) == pytest.approx(expected, abs=1e-5 * before)


def test_horizon_agrees():
    out = np.empty((3, 3))
    for vt, sel in CASES:
        q, g = CANDIDATES_Q[sel], CANDIDATES_G[sel]
        hc = HorizonCorrector().fit(vt, q, g, ORIGIN)
        args = np.column_stack([q, g]).ravel()
        eps, delta = mk.fit_horizon_shift3(vt.m, *args)
        assert delta == pytest.approx(hc.search_half_width_, rel=1e-12)
        assert eps == pytest.approx(hc.horizon_shift_, rel=1e-9, abs=1e-9)
        n = np.column_stack([q, np.ones(3)]) @ vt.m.T
        loss = mk.horizon_loss3(*np.column_stack([n, g]).ravel(), vt.m[0, 1], vt.m[1, 1], vt.m[2, 1], eps)
        assert loss == pytest.approx(np.sum((hc.transform_points(q) - g) ** 2), rel=1e-9, abs=1e-15)
        assert mk.horizon_mean_error3(vt.m, eps, *args) == pytest.approx(hc.error_after_, rel=1e-9, abs=1e-12)
        mk.horizon_homography_into(vt.m, eps, out)
        np.testing.assert_allclose(out, hc.m, rtol=0, atol=1e-12)


def test_horizon_beyond_the_horizon_is_nan():
    q = np.array([[640.0, 100.0], *CANDIDATES_Q[:2]])  # the first point is above the horizon
    args = np.column_stack([q, CANDIDATES_G[:3]]).ravel()
    assert np.isnan(mk.fit_horizon_shift3(ViewTransformer(IMAGE, GROUND).m, *args)).all()


def least_change_cases():
    """(transformer, triple) per case as cases(), the map trapezoid moved too (up to 0.3 m per coordinate: the study
    perturbs both quads)."""
    rng = np.random.default_rng(7)
    return [(ViewTransformer(vt.source, GROUND + rng.uniform(-0.3, 0.3, (4, 2))), sel) for vt, sel in CASES[:150]]


@pytest.mark.parametrize("kw", [{}, {"map_sigma_m": 0.0}, {"click_sigma_px": 40.0, "point_sigma_m": 0.001, "iterations": 4}])
def test_least_change_agrees(kw):
    """The same corrected quads (to 1e-6 px and 1e-6 m: the fit's own stopping accuracy, ~1e-6 prior sigmas) and
    final objective (to 1e-9 relative) as LeastChangeCorrector, under the default prior, a fixed map and a wild
    prior whose fits halve their steps and mostly run out of iterations."""
    lc = LeastChangeCorrector(**kw)
    p = lc.get_params()
    z, Bt = np.empty(16), np.empty((3, 3))
    for vt, sel in least_change_cases():
        q, g = CANDIDATES_Q[sel], CANDIDATES_G[sel]
        lc.fit(vt, q, g, ORIGIN)
        z0 = np.concatenate([vt.source.ravel(), vt.target.ravel()])
        steps, phi = mk.least_change3(z0, q, g, p["click_sigma_px"], p["map_sigma_m"], p["point_sigma_m"],
                                      p["iterations"], z, Bt)
        np.testing.assert_allclose(Bt, kernels.target_basis(z[8:].reshape(4, 2)), rtol=1e-12, atol=1e-12)
        assert 1 <= steps <= p["iterations"]
        assert phi == pytest.approx(lc.objective_final_, rel=1e-9)
        np.testing.assert_allclose(z[:8], lc.transformer_.source.ravel(), rtol=0, atol=1e-6)
        np.testing.assert_allclose(z[8:], lc.transformer_.target.ravel(), rtol=0, atol=1e-6)
        assert phi < lc.objective_initial_ * (1 - 1e-3)  # a real correction, not the start kept


def test_least_change_jacobian_is_the_readable_one():
    """The kernel's df/dx against least_change.mapped_jacobian (itself checked against central differences)."""
    sigma = np.repeat([1.0, 0.2], 8)
    J, r, y, X, bs, bt = np.empty((6, 16)), np.empty(6), np.empty(3), np.empty(3), np.empty(13), np.empty(13)
    for vt, sel in least_change_cases()[:30]:
        q, g = CANDIDATES_Q[sel], CANDIDATES_G[sel]
        z = np.concatenate([vt.source.ravel(), vt.target.ravel()])
        assert mk._basis_into(z, 0, bs) and mk._basis_into(z, 8, bt)
        mk._jacobian_into(z, bs, bt, q, g, sigma, J, r, y, X, np.empty((3, 3)), np.empty((16, 3)))
        np.testing.assert_allclose(J, mapped_jacobian(vt.source, vt.target, q).reshape(6, 16) * sigma, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(r, (g - vt.transform_points(q)).ravel(), rtol=0, atol=1e-10)


def far_test_table():
    """(test table, mapped p, ground g) of test points 5-50 m ahead, 0.5 m off their ground truth."""
    g = np.column_stack([np.linspace(-4.0, 4.0, 40), np.linspace(5.0, 50.0, 40)])
    p = g + [0.3, 0.4]
    return make_test_table(CAM.project_ground(g), ViewTransformer(IMAGE, GROUND).m, p, g, ORIGIN), p, g


def test_intercept_error_beyond_8_km_keeps_its_true_value():
    """A regression-intercept sample whose three calibration points are 2 mm apart in range and 1 m apart in signed
    error: its quadratic moves the far test points by thousands of km. The kernel's mean path error is the float64
    one (no clip: the fixed-point sum had one at 8 km)."""
    test, p, g = far_test_table()
    a, b, c, degenerate = mk.fit_quadratic_intercept3(20.0, 20.001, 20.002, 0.0, 1.0, 0.0)
    assert not degenerate
    d = np.linalg.norm(p - ORIGIN, axis=1)
    corrected = p + (p - ORIGIN) / d[:, None] * (a * d**2 + b * d + c)[:, None]
    expected = np.linalg.norm(corrected - g, axis=1).mean()
    assert expected > 1e6  # metres: far beyond 8 km
    assert mk.regression_path_intercept(test, a, b, c) == pytest.approx(expected, rel=1e-6)
    in_range = np.abs(np.linalg.norm(g - ORIGIN, axis=1) - np.abs(d + a * d**2 + b * d + c)).mean()
    assert kernels.regression_path_range(test, a, b, c) == pytest.approx(in_range, rel=1e-6)


@pytest.mark.parametrize("a", [1e3, 1e30, np.inf, np.nan])
def test_path_error_sums_are_exact_or_fail(a):
    """Regression's mean path error for a = 1e3 /m (errors up to 2,500 km) is the float64 one; one whose point errors
    overflow float32 or are NaN is not a number (a failed correction), never a clipped value."""
    test, p, g = far_test_table()
    faithful, signed = kernels.regression_path(test, a, 0.0, False), kernels.regression_path(test, 0.0, 0.0, False)
    d = np.linalg.norm(p - ORIGIN, axis=1)
    expected = np.linalg.norm(p + (p - ORIGIN) * (a * d)[:, None] - g, axis=1).mean()
    if np.isfinite(a) and a < 1e10:
        assert faithful == pytest.approx(expected, rel=1e-6)
    else:
        assert np.isnan(faithful)
    assert signed == pytest.approx(np.linalg.norm(p - g, axis=1).mean(), rel=1e-6)

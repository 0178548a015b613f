"""homocal.correctors against independent computations: np.linalg.lstsq for eq. (22), geometry for eq. (24),
a brute-force grid for descent phase 1, a pinhole camera for recovery; checks, hybrid choice, JSON."""
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from homocal.correctors import (
    Corrector,
    DescentCorrector,
    HorizonCorrector,
    HybridCorrector,
    RegressionCorrector,
    fit_horizon_shift,
    fit_quadratic_error,
    fit_quadratic_intercept,
    load_corrector,
    radial_correction,
)
from homocal.correctors.catalogue import METHODS, get_method, label, method_of
from homocal.error_model import horizon_shift
from homocal.geometry import PinholeCamera, ViewTransformer, apply_homography

CAM = PinholeCamera()  # the paper's camera: 1280x720, 95 deg hfov, 4 m high, 15 deg down
GROUND = np.array([[-3.5, 30.0], [3.5, 30.0], [3.5, 8.0], [-3.5, 8.0]])  # TL, TR, BR, BL (far edge on top)
IMAGE = CAM.project_ground(GROUND)  # the exact image trapezoid
CALIB_G = np.array([[0.0, 10.0], [0.0, 20.0], [0.0, 35.0]])  # calibration objects in front of the camera
CALIB_Q = CAM.project_ground(CALIB_G)
ORIGIN = np.zeros(2)
HAND_ERROR = np.array([[2.0, -1.0], [-1.0, 2.0], [3.0, 1.0], [-2.0, -2.0]])  # px, a plausible clicking error
TEST_G = np.stack(np.meshgrid(np.linspace(-3.0, 3.0, 7), np.linspace(6.0, 40.0, 18)), -1).reshape(-1, 2)
TEST_Q = CAM.project_ground(TEST_G)
# An identity mapping (pixels = ground units) on which the mapped calibration points p_i are chosen freely.
SQUARE = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0], [0.0, 100.0]])
IDENTITY = ViewTransformer(SQUARE, SQUARE)


def perturbed(offsets: np.ndarray) -> ViewTransformer:
    return ViewTransformer(IMAGE + np.asarray(offsets, dtype=float).reshape(4, 2), GROUND)


def mean_error(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.mean(np.hypot(*(a - b).T)))


def radial_ground(p: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Ground points at distance e_i from p_i, radially outwards from the origin (so ||p - g|| = |e|)."""
    return p + p / np.linalg.norm(p, axis=1)[:, None] * e[:, None]


class TestFitQuadraticError:
    @pytest.mark.parametrize("seed", range(8))
    @pytest.mark.parametrize("n", [3, 5])
    def test_eq22_matches_lstsq(self, seed, n):
        rng = np.random.default_rng(seed)
        d, e = rng.uniform(5.0, 50.0, n), rng.normal(0.0, 2.0, n)
        a, b, degenerate = fit_quadratic_error(d, e)
        (a_ref, b_ref), *_ = np.linalg.lstsq(np.column_stack([d**2, d]), e, rcond=None)
        assert not degenerate
        assert a == pytest.approx(a_ref, rel=1e-7, abs=1e-12) and b == pytest.approx(b_ref, rel=1e-7, abs=1e-10)

    def test_exact_quadratic_is_recovered(self):
        d = np.array([10.0, 20.0, 35.0])
        assert fit_quadratic_error(d, 0.002 * d**2 + 0.01 * d)[:2] == pytest.approx((0.002, 0.01), rel=1e-9)

    @pytest.mark.parametrize("d", [[20.0, 20.0, 20.0], [20.0, 20.0 + 1e-7, 20.0 - 1e-7]])
    def test_equal_distances_fall_back_to_linear(self, d):
        d, e = np.array(d), np.array([0.5, 0.7, 0.6])
        a, b, degenerate = fit_quadratic_error(d, e)
        (b_ref,), *_ = np.linalg.lstsq(d[:, None], e, rcond=None)
        assert degenerate and a == 0.0 and b == pytest.approx(b_ref, rel=1e-12)


class TestFitQuadraticIntercept:
    @pytest.mark.parametrize("seed", range(8))
    @pytest.mark.parametrize("n", [3, 4, 7])
    def test_matches_lstsq(self, seed, n):
        rng = np.random.default_rng(seed)
        d, e = rng.uniform(5.0, 50.0, n), rng.normal(0.0, 2.0, n)
        a, b, c, degenerate = fit_quadratic_intercept(d, e)
        ref, *_ = np.linalg.lstsq(np.column_stack([d**2, d, np.ones(n)]), e, rcond=None)
        assert not degenerate
        np.testing.assert_allclose([a, b, c], ref, rtol=1e-8, atol=1e-10 * np.abs(ref).max())

    @pytest.mark.parametrize("d", [[10.0, 20.0, 35.0], [5.0, 5.5, 48.0], [30.0, 31.0, 32.0]])
    def test_exact_through_three_points(self, d):
        d = np.array(d)
        e = np.array([0.3, -0.4, 1.1])
        a, b, c, _ = fit_quadratic_intercept(d, e)
        np.testing.assert_allclose([a, b, c], np.polyfit(d, e, 2), rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(a * d**2 + b * d + c, e, atol=1e-9)

    def test_two_equal_distances_fit_a_line(self):
        d, e = np.array([10.0, 10.0, 30.0]), np.array([0.2, 0.4, 1.0])
        a, b, c, degenerate = fit_quadratic_intercept(d, e)
        (b_ref, c_ref), *_ = np.linalg.lstsq(np.column_stack([d, np.ones(3)]), e, rcond=None)
        assert degenerate and a == 0.0
        assert (b, c) == pytest.approx((b_ref, c_ref), rel=1e-9)

    def test_all_equal_distances_fit_a_constant(self):
        assert fit_quadratic_intercept(np.full(3, 20.0), np.array([0.1, 0.2, 0.6])) == (0.0, 0.0, pytest.approx(0.3), True)


class TestRadialCorrection:
    @pytest.mark.parametrize("a,b", [(0.002, 0.01), (-0.003, 0.02), (0.0, -0.05)])
    def test_moves_points_radially_by_c(self, a, b):
        rng = np.random.default_rng(0)
        o = np.array([1.0, -2.0])
        p = rng.uniform(-40.0, 40.0, (20, 2))
        out = radial_correction(p, o, a, b)
        r_before, r_after = np.linalg.norm(p - o, axis=1), np.linalg.norm(out - o, axis=1)
        np.testing.assert_allclose(r_after, np.abs(r_before + a * r_before**2 + b * r_before), rtol=1e-12)
        np.testing.assert_allclose(  # the bearing from o is kept (eq. (24) moves along (o - p))
            np.arctan2(*(out - o).T[::-1]), np.arctan2(*(p - o).T[::-1]), atol=1e-12
        )

    def test_intercept_adds_a_constant_shift(self):
        p = np.array([[3.0, 4.0], [0.0, 10.0]])
        out = radial_correction(p, np.zeros(2), 0.01, 0.1, -0.5)
        np.testing.assert_allclose(np.linalg.norm(out, axis=1), [5 + 0.25 + 0.5 - 0.5, 10 + 1 + 1 - 0.5])

    def test_origin_and_nan_stay(self):
        p = np.array([[1.0, 2.0], [np.nan, np.nan]])
        np.testing.assert_array_equal(radial_correction(p, np.array([1.0, 2.0]), 0.1, 0.1), p)


class TestRegressionCorrector:
    def test_fit_uses_eq18_errors_and_eq22(self):
        p = np.array([[3.0, 10.0], [-2.0, 25.0], [5.0, 40.0]])
        e = np.array([0.3, 1.1, 3.0])
        reg = RegressionCorrector().fit(IDENTITY, p, radial_ground(p, e), ORIGIN)
        d = np.linalg.norm(p, axis=1)
        (a_ref, b_ref), *_ = np.linalg.lstsq(np.column_stack([d**2, d]), e, rcond=None)
        assert (reg.a_, reg.b_) == pytest.approx((max(a_ref, 0), max(b_ref, 0)), rel=1e-9)
        assert reg.error_before_ == pytest.approx(e.mean(), rel=1e-12)

    @pytest.mark.parametrize(
        "a,b,expected",  # unclamped law e = a d^2 + b d; each coefficient is clamped on its own
        [(0.002, 0.01, (0.002, 0.01)), (-0.0005, 0.08, (0.0, 0.08)), (0.004, -0.02, (0.004, 0.0))],
    )
    def test_faithful_clamps_each_coefficient(self, a, b, expected):
        p = np.array([[0.0, 10.0], [0.0, 20.0], [0.0, 35.0]])
        reg = RegressionCorrector().fit(IDENTITY, p, radial_ground(p, a * p[:, 1] ** 2 + b * p[:, 1]), ORIGIN)
        assert (reg.a_, reg.b_) == pytest.approx(expected, rel=1e-7, abs=1e-12) and not reg.degenerate_

    def test_degenerate_distances_use_linear_fallback(self):
        p = 20.0 * np.array([[0.0, 1.0], [0.6, 0.8], [-0.8, 0.6]])  # all at 20 from the origin
        reg = RegressionCorrector().fit(IDENTITY, p, radial_ground(p, np.array([0.4, 0.5, 0.6])), ORIGIN)
        assert reg.degenerate_ and reg.a_ == 0.0 and reg.b_ == pytest.approx(0.5 / 20.0, rel=1e-12)

    def test_signed_corrects_overestimated_range_faithful_cannot(self):
        # Top corners clicked 3 px too low: the far edge is assigned to nearer pixels, so range is overestimated.
        vt = perturbed([[0, 3], [0, 3], [0, 0], [0, 0]])
        p = vt.transform_points(CALIB_Q)
        assert np.all(np.linalg.norm(p, axis=1) > np.linalg.norm(CALIB_G, axis=1))
        faithful = RegressionCorrector().fit(vt, CALIB_Q, CALIB_G, ORIGIN)
        signed = RegressionCorrector(signed=True).fit(vt, CALIB_Q, CALIB_G, ORIGIN)
        assert faithful.calibration_improvement_ < 0  # pushed further away
        assert signed.calibration_improvement_ > 90
        path_before = mean_error(vt.transform_points(TEST_Q), TEST_G)
        assert mean_error(signed.transform_points(TEST_Q), TEST_G) < 0.5 * path_before

    def test_improvement_definition(self):
        reg = RegressionCorrector(signed=True).fit(perturbed(HAND_ERROR), CALIB_Q, CALIB_G, ORIGIN)
        after = mean_error(reg.transform_points(CALIB_Q), CALIB_G)
        assert reg.error_after_ == pytest.approx(after, rel=1e-12)
        assert reg.calibration_improvement_ == pytest.approx(100 * (reg.error_before_ - after) / reg.error_before_)

    def test_exact_mapping_has_nan_improvement(self):
        reg = RegressionCorrector().fit(ViewTransformer(IMAGE, GROUND), CALIB_Q, CALIB_G, ORIGIN)
        assert reg.error_before_ == pytest.approx(0.0, abs=1e-9)


    def test_intercept_fits_signed_errors_without_clamping(self):
        p = np.array([[3.0, 10.0], [-2.0, 25.0], [5.0, 40.0]])
        e = np.array([-0.3, 0.4, -1.0])  # signed range errors g - p along the ray
        reg = RegressionCorrector(signed=True, intercept=True).fit(IDENTITY, p, radial_ground(p, e), ORIGIN)
        a, b, c = np.polyfit(np.linalg.norm(p, axis=1), e, 2)
        assert (reg.a_, reg.b_, reg.c_) == pytest.approx((a, b, c), rel=1e-9)
        assert reg.error_after_ < 1e-12 and reg.calibration_improvement_ == pytest.approx(100.0)

    def test_intercept_needs_signed(self):
        with pytest.raises(ValueError, match="intercept=True needs signed=True"):
            RegressionCorrector(intercept=True)

    @pytest.mark.parametrize("offsets", [HAND_ERROR, [[0, 3], [0, 3], [0, 0], [0, 0]], [[1, -3], [-2, 0], [3, 2], [0, -1]]])
    def test_intercept_corrects_the_calibration_line(self, offsets):
        vt = perturbed(offsets)
        reg = RegressionCorrector(signed=True, intercept=True).fit(vt, CALIB_Q, CALIB_G, ORIGIN)
        line_g = np.column_stack([np.zeros(18), np.linspace(6.0, 40.0, 18)])
        line_q = CAM.project_ground(line_g)
        corrected_range = np.linalg.norm(reg.transform_points(CALIB_Q), axis=1)
        np.testing.assert_allclose(corrected_range, np.linalg.norm(CALIB_G, axis=1), atol=1e-9)  # 3 points: exact
        assert mean_error(reg.transform_points(line_q), line_g) < 0.3 * mean_error(vt.transform_points(line_q), line_g)


def row_shift(eps: float) -> np.ndarray:
    """(3, 3) image homography (u, v) -> (u, v + eps), pixels."""
    return np.array([[1.0, 0.0, 0.0], [0.0, 1.0, eps], [0.0, 0.0, 1.0]])


def shifted_mapping(eps: float) -> ViewTransformer:
    """The paper camera's exact mapping with its horizon eps pixels lower (eq. (9)): H(u, v - eps)."""
    H = CAM.image_to_ground @ row_shift(-eps)
    return ViewTransformer(IMAGE, apply_homography(H, IMAGE))


class TestHorizonCorrector:
    @pytest.mark.parametrize("eps", [-12.0, -3.0, 0.7, 5.0, 20.0])
    def test_recovers_an_injected_horizon_shift(self, eps):
        vt = shifted_mapping(eps)
        assert horizon_shift(CAM.image_to_ground, vt.m, 639.5) == pytest.approx(eps, abs=1e-9)
        hc = HorizonCorrector().fit(vt, CALIB_Q, CALIB_G, ORIGIN)
        assert hc.horizon_shift_ == pytest.approx(eps, abs=1e-8)
        far_g = np.stack(np.meshgrid(np.linspace(-8.0, 8.0, 5), np.linspace(5.0, 60.0, 12)), -1).reshape(-1, 2)
        np.testing.assert_allclose(hc.transform_points(CAM.project_ground(far_g)), far_g, atol=1e-6)
        H_true = CAM.image_to_ground / np.sign(CAM.image_to_ground[2, 1])
        np.testing.assert_allclose(hc.m, H_true, atol=1e-10)  # .m is the true image-to-ground homography

    @pytest.mark.parametrize("tilt_error", [-1.0, -0.5, 0.5, 1.0])
    def test_a_tilt_error_is_mostly_a_horizon_shift(self, tilt_error):
        # The trapezoid clicked where a camera tilted tilt_error degrees more would see it: the true error is a
        # rotation (K R_x K^-1), not a row shift, so the fit is close, not exact (measured: within 6 % of the
        # true shift, corrected points within 0.16 m out to 50 m where uncorrected ones are 4-14 m off).
        vt = ViewTransformer(PinholeCamera(tilt_deg=CAM.tilt_deg + tilt_error).project_ground(GROUND), GROUND)
        hc = HorizonCorrector().fit(vt, CALIB_Q, CALIB_G, ORIGIN)
        true_shift = horizon_shift(CAM.image_to_ground, vt.m, 639.5)
        assert abs(true_shift) > 5 and hc.horizon_shift_ == pytest.approx(true_shift, rel=0.06)
        test_g = np.stack(np.meshgrid(np.linspace(-5.0, 5.0, 5), np.linspace(6.0, 50.0, 10)), -1).reshape(-1, 2)
        test_q = CAM.project_ground(test_g)
        assert np.abs(vt.transform_points(test_q) - test_g).max() > 4.0
        assert np.abs(hc.transform_points(test_q) - test_g).max() < 0.2

    @pytest.mark.parametrize("offsets", [HAND_ERROR, [[1, -3], [-2, 0], [3, 2], [0, -1]], [[0, 3], [0, 3], [0, 0], [0, 0]]])
    def test_least_squares_against_a_dense_scan(self, offsets):
        vt = perturbed(offsets)
        eps, delta = fit_horizon_shift(vt.m, CALIB_Q, CALIB_G)
        scan = np.linspace(-delta, delta, 400001)[1:]
        # independent of the corrector's code: the base mapping applied to the shifted points (u, v + eps)
        shifted = np.repeat(CALIB_Q[None], len(scan), axis=0) + np.stack([np.zeros_like(scan), scan], -1)[:, None]
        losses = np.sum((apply_homography(vt.m, shifted.reshape(-1, 2)).reshape(-1, 3, 2) - CALIB_G) ** 2, axis=(1, 2))

        def sq(e):
            return np.sum((apply_homography(vt.m, CALIB_Q + [0.0, e]) - CALIB_G) ** 2)

        best = scan[np.argmin(losses)]
        assert eps == pytest.approx(best, abs=2 * delta / 400000)
        assert sq(eps) <= (1 + 1e-11) * min(sq(best), sq(0.0))
        h = 1e-5  # the derivative vanishes at the fit (an interior minimum)
        assert abs(sq(eps + h) - sq(eps - h)) / (2 * h) < 1e-6 * max(1.0, sq(0.0))

    def test_search_range_is_below_the_nearest_reference_point(self):
        vt = perturbed(HAND_ERROR)
        hc = HorizonCorrector().fit(vt, CALIB_Q, CALIB_G, ORIGIN)
        v_h = vt.horizon_row(CALIB_Q[:, 0])
        assert hc.search_half_width_ == pytest.approx(np.min(CALIB_Q[:, 1] - v_h), rel=1e-12)
        assert -hc.search_half_width_ < hc.horizon_shift_ <= hc.search_half_width_

    def test_matrix_is_what_transform_points_applies(self):
        hc = HorizonCorrector().fit(perturbed(HAND_ERROR), CALIB_Q, CALIB_G, ORIGIN)
        np.testing.assert_array_equal(hc.transform_points(TEST_Q), apply_homography(hc.m, TEST_Q))
        assert np.linalg.norm(hc.m) == pytest.approx(1.0) and hc.get_params() == {}


class TestDescentCorrector:
    @pytest.mark.slow  # 12 descents
    @settings(max_examples=12, deadline=None)
    @given(st.lists(st.integers(-3, 3), min_size=8, max_size=8), st.integers(0, 2**64 - 1))
    def test_never_ends_above_initial_loss(self, offsets, seed):
        desc = DescentCorrector(seed=seed).fit(perturbed(offsets), CALIB_Q, CALIB_G, ORIGIN)
        assert desc.loss_final_ <= desc.loss_initial_ == desc.error_before_
        assert desc.error_after_ == pytest.approx(desc.loss_final_, rel=1e-12)
        assert desc.calibration_improvement_ >= 0 or math.isnan(desc.calibration_improvement_)
        assert np.abs(desc.transformer_.source - perturbed(offsets).source).max() <= desc.delta_max

    @pytest.mark.parametrize("delta_max,grid", [(1.0, (-1.0, 0.0, 1.0)), (0.5, (0.0,)), (3.0, (-2.0, 0.0, 2.0))])
    def test_respects_delta_max(self, delta_max, grid):
        vt = perturbed(HAND_ERROR * 2)
        desc = DescentCorrector(delta_max=delta_max, grid_offsets=grid).fit(vt, CALIB_Q, CALIB_G, ORIGIN)
        assert np.abs(desc.transformer_.source - vt.source).max() <= delta_max

    def test_phase1_is_the_first_best_grid_point(self):
        vt = perturbed(HAND_ERROR)
        desc = DescentCorrector(max_evals=0).fit(vt, CALIB_Q, CALIB_G, ORIGIN)
        best, best_offsets = math.inf, None
        for dtl_u in desc.grid_offsets:  # the documented order: dTL.u, dTL.v, dBR.u, dBR.v
            for dtl_v in desc.grid_offsets:
                for dbr_u in desc.grid_offsets:
                    for dbr_v in desc.grid_offsets:
                        quad = vt.source + [[dtl_u, dtl_v], [0, 0], [dbr_u, dbr_v], [0, 0]]
                        err = mean_error(ViewTransformer(quad, GROUND).transform_points(CALIB_Q), CALIB_G)
                        if err < best:
                            best, best_offsets = err, quad
        assert desc.evaluations_ == 0
        np.testing.assert_array_equal(desc.transformer_.source, best_offsets)
        assert desc.loss_final_ == pytest.approx(best, rel=1e-12)

    @pytest.mark.parametrize("max_evals", [1, 7, 30])
    def test_budget(self, max_evals):
        desc = DescentCorrector(max_evals=max_evals).fit(perturbed(HAND_ERROR * 1.5), CALIB_Q, CALIB_G, ORIGIN)
        assert desc.evaluations_ == max_evals

    def test_deterministic_for_a_seed(self):
        fits = [DescentCorrector(seed=7).fit(perturbed(HAND_ERROR), CALIB_Q, CALIB_G, ORIGIN) for _ in range(2)]
        np.testing.assert_array_equal(fits[0].transformer_.source, fits[1].transformer_.source)
        assert fits[0].evaluations_ == fits[1].evaluations_

    @pytest.mark.parametrize("offsets", [HAND_ERROR, [[1, -3], [-2, 0], [3, 2], [0, -1]], [[0, 3], [0, 3], [0, 0], [0, 0]]])
    def test_recovers_most_of_the_error_along_the_calibration_line(self, offsets):
        # Three calibration objects on x = 0 constrain the mapping there; off that line the paper's caveat
        # holds (descent may overfit: it can trade lateral error elsewhere for a perfect centre line).
        vt = perturbed(offsets)
        desc = DescentCorrector().fit(vt, CALIB_Q, CALIB_G, ORIGIN)
        line_g = np.column_stack([np.zeros(18), np.linspace(6.0, 40.0, 18)])
        line_q = CAM.project_ground(line_g)
        assert desc.calibration_improvement_ > 80
        assert mean_error(desc.transform_points(line_q), line_g) < 0.3 * mean_error(vt.transform_points(line_q), line_g)

    @pytest.mark.parametrize(
        "kwargs,match",
        [
            ({"grid_offsets": (-10.0, 0.0)}, "delta_max"),
            ({"grid_offsets": (-1.0, 1.0)}, "include 0"),
            ({"delta_max": 0.0}, "delta_max"),
            ({"min_step": 2.0}, "min_step"),
            ({"max_evals": -1}, "max_evals"),
            ({"seed": -1}, "seed"),
        ],
    )
    def test_bad_parameters(self, kwargs, match):
        with pytest.raises(ValueError, match=match):
            DescentCorrector(**kwargs)


class TestHybridCorrector:
    @pytest.mark.parametrize("threshold,chosen", [(-math.inf, "regression"), (math.inf, "descent"), (75.0, None)])
    def test_choice_follows_threshold(self, threshold, chosen):
        vt = perturbed(HAND_ERROR)
        hyb = HybridCorrector(threshold=threshold, signed=True).fit(vt, CALIB_Q, CALIB_G, ORIGIN)
        reg = RegressionCorrector(signed=True).fit(vt, CALIB_Q, CALIB_G, ORIGIN)
        expected = chosen or ("regression" if reg.calibration_improvement_ >= 75.0 else "descent")
        assert hyb.chosen_ == expected
        picked = hyb.regression_ if expected == "regression" else hyb.descent_
        assert hyb.calibration_improvement_ == picked.calibration_improvement_
        np.testing.assert_array_equal(hyb.transform_points(TEST_Q), picked.transform_points(TEST_Q))

    def test_threshold_is_inclusive(self):
        vt = perturbed(HAND_ERROR)
        reg = RegressionCorrector(signed=True).fit(vt, CALIB_Q, CALIB_G, ORIGIN)
        hyb = HybridCorrector(threshold=reg.calibration_improvement_, signed=True).fit(vt, CALIB_Q, CALIB_G, ORIGIN)
        assert hyb.chosen_ == "regression"


FITTED = {
    "regression": lambda: RegressionCorrector(),
    "regression-signed": lambda: RegressionCorrector(signed=True),
    "regression-intercept": lambda: RegressionCorrector(signed=True, intercept=True),
    "horizon": lambda: HorizonCorrector(),
    "descent": lambda: DescentCorrector(seed=3, max_evals=100),
    "hybrid": lambda: HybridCorrector(threshold=50.0, max_evals=50),
}


class TestJson:
    @pytest.mark.parametrize("name", FITTED)
    def test_round_trip_gives_identical_mapping(self, name, tmp_path):
        c = FITTED[name]().fit(perturbed(HAND_ERROR), CALIB_Q, CALIB_G, ORIGIN)
        c.save(tmp_path / "c.json")
        for loaded in (load_corrector(tmp_path / "c.json"), type(c).load(tmp_path / "c.json")):
            assert type(loaded) is type(c) and loaded.get_params() == c.get_params()
            np.testing.assert_array_equal(loaded.transform_points(TEST_Q), c.transform_points(TEST_Q))
            assert loaded.calibration_improvement_ == c.calibration_improvement_
        assert [p.name for p in tmp_path.iterdir()] == ["c.json"]  # no temporary file left

    def test_regression_file_without_intercept_loads(self, tmp_path):
        c = RegressionCorrector(signed=True).fit(perturbed(HAND_ERROR), CALIB_Q, CALIB_G, ORIGIN)
        d = c.to_dict()
        del d["params"]["intercept"], d["fitted"]["c"]  # as written before the intercept existed
        (tmp_path / "old.json").write_text(json.dumps(d))
        old = load_corrector(tmp_path / "old.json")
        assert old.intercept is False and old.c_ == 0.0
        np.testing.assert_array_equal(old.transform_points(TEST_Q), c.transform_points(TEST_Q))

    def test_nan_improvement_is_strict_json(self):
        q = SQUARE[1:]
        c = RegressionCorrector().fit(IDENTITY, q, IDENTITY.transform_points(q), [-1.0, -1.0])  # no error before
        assert c.error_before_ == 0.0 and math.isnan(c.calibration_improvement_)
        assert json.loads(c.to_json())["calibration_improvement"] is None
        assert math.isnan(Corrector.from_json(c.to_json()).calibration_improvement_)

    def test_other_method_is_refused(self, tmp_path):
        RegressionCorrector().fit(IDENTITY, SQUARE[1:], SQUARE[1:] + 1, ORIGIN).save(tmp_path / "r.json")
        with pytest.raises(ValueError, match="'regression' correction, not 'descent'"):
            DescentCorrector.load(tmp_path / "r.json")

    @pytest.mark.parametrize(
        "edit,match",
        [
            (lambda d: d.update(format="other"), "not a homocal correction"),
            (lambda d: d.update(format_version=99), "format_version"),
            (lambda d: d.update(method="magic"), "unknown method"),
            (lambda d: d.pop("fitted"), "missing key 'fitted'"),
            (lambda d: d["transformer"].update(source=[[0, 0]] * 4), "same point"),
            (lambda d: d.update(params={"signed": "yes"}), "signed"),
        ],
    )
    def test_bad_content(self, edit, match, tmp_path):
        d = RegressionCorrector().fit(IDENTITY, SQUARE[1:], SQUARE[1:] + 1, ORIGIN).to_dict()
        edit(d)
        (tmp_path / "c.json").write_text(json.dumps(d))
        with pytest.raises(ValueError, match=match):
            load_corrector(tmp_path / "c.json")

    @pytest.mark.parametrize("name,edit,match", [  # issue 12 class 5: hand-edited files
        ("regression", lambda d: d["fitted"].update(a=-5.0), r"field fitted\.a: must be >= 0"),
        ("regression", lambda d: d["fitted"].update(b=math.nan), r"field fitted\.b: expected a finite number"),
        ("regression", lambda d: d["fitted"].update(a="0.1"), r"field fitted\.a: expected a number"),
        ("regression", lambda d: d["fitted"].update(degenerate="false"), r"field fitted\.degenerate: expected true"),
        ("regression", lambda d: d["fitted"].update(c=0.5), r"field fitted\.c: must be 0 without the intercept"),
        ("regression", lambda d: d["fitted"].update(degenerate=True), r"field fitted\.a: must be 0 for a degenerate"),
        ("regression", lambda d: d["params"].update(intercept=True), r"field params: intercept=True needs signed"),
        ("regression-signed", lambda d: d["fitted"].update(a=math.inf), r"field fitted\.a: expected a finite"),
        ("regression-intercept", lambda d: d["fitted"].update(c=None), r"field fitted\.c: expected a number"),
        ("regression", lambda d: d.update(error_before=-1.0), r"field error_before: must be >= 0"),
        ("regression", lambda d: d.update(error_after=math.nan), r"field error_after: expected a finite"),
        ("regression", lambda d: d.update(calibration_improvement=50.0), r"field calibration_improvement: 50\.0 does"),
        ("regression", lambda d: d.update(calibration_improvement=None), r"field calibration_improvement: None does"),
        ("regression", lambda d: d["transformer"]["source"][0].__setitem__(0, 1e308), r"field transformer: .*out of range"),
        ("regression", lambda d: d.update(camera_origin=[0.0, math.nan]), r"field camera_origin"),
        ("regression", lambda d: d.update(camera_origin=["a", "b"]), r"field camera_origin: must be 2 finite"),
        ("regression", lambda d: d.update(params=[True]), r"field params: expected an object"),
        ("descent", lambda d: d["fitted"]["source"][1].__setitem__(1, d["fitted"]["source"][1][1] + 20), r"moved .*delta_max"),
        ("descent", lambda d: d["fitted"].update(source=[[0, 0]] * 4), r"field fitted\.source: .*same point"),
        ("descent", lambda d: d["fitted"].update(loss_final=d["fitted"]["loss_initial"] + 1), r"above loss_initial"),
        ("descent", lambda d: d["fitted"].update(evaluations=101), r"field fitted\.evaluations: expected an integer"),
        ("descent", lambda d: d["fitted"].update(evaluations=1.5), r"field fitted\.evaluations"),
        ("hybrid", lambda d: d["fitted"].update(chosen="regression" if d["fitted"]["chosen"] == "descent" else "descent"),
         r"field fitted\.chosen"),
        ("hybrid", lambda d: d["fitted"]["regression"]["fitted"].update(a=-5.0), r"field fitted\.regression: .*fitted\.a"),
        ("hybrid", lambda d: d["fitted"]["descent"]["params"].update(max_evals=500), r"field fitted\.descent\.params"),
        ("horizon", lambda d: d["fitted"].update(horizon_shift=1e6), r"field fitted\.horizon_shift: .*search range"),
        ("horizon", lambda d: d["fitted"].update(search_half_width=-1.0), r"field fitted\.search_half_width: must be"),
        ("horizon", lambda d: d["fitted"].pop("horizon_shift"), r"missing key 'horizon_shift'"),
    ])
    def test_hand_edited_fields_are_refused(self, name, edit, match, tmp_path):
        d = json.loads(FITTED[name]().fit(perturbed(HAND_ERROR), CALIB_Q, CALIB_G, ORIGIN).to_json())
        edit(d)
        (tmp_path / "c.json").write_text(json.dumps(d))
        with pytest.raises(ValueError, match=f"c.json: bad .*{match}"):
            load_corrector(tmp_path / "c.json")

    @pytest.mark.parametrize("text,match", [(None, "no such file"), ("{not json", "not a JSON"), ("[1]", "object")])
    def test_bad_file(self, text, match, tmp_path):
        if text is not None:
            (tmp_path / "c.json").write_text(text)
        with pytest.raises(ValueError, match=match):
            load_corrector(tmp_path / "c.json")


class TestFitInputChecks:
    @pytest.mark.parametrize("cls", [RegressionCorrector, DescentCorrector, HybridCorrector, HorizonCorrector])
    @pytest.mark.parametrize(
        "q,g,o,match",
        [
            (CALIB_Q[:2], CALIB_G[:2], ORIGIN, "at least 3"),
            (CALIB_Q, CALIB_G[:2], ORIGIN, "3 points but ground_points has 2"),
            (np.vstack([CALIB_Q[:1], [[np.nan, 400.0]], CALIB_Q[2:]]), CALIB_G, ORIGIN, r"image_points\[1\]"),
            (CALIB_Q, np.vstack([CALIB_G[:2], [[0.0, np.inf]]]), ORIGIN, r"ground_points\[2\]"),
            (np.vstack([CALIB_Q[:2], [[640.0, 100.0]]]), CALIB_G, ORIGIN, r"image_points\[2\].*horizon"),
            (CALIB_Q, CALIB_G, [0.0, np.nan], "camera_origin"),
            (CALIB_Q, CALIB_G, [0.0, 0.0, 0.0], "camera_origin"),
            (CALIB_Q.ravel(), CALIB_G, ORIGIN, "shape"),
        ],
    )
    def test_bad_input_names_the_problem(self, cls, q, g, o, match):
        with pytest.raises(ValueError, match=match):
            cls().fit(perturbed(HAND_ERROR), q, g, o)

    @pytest.mark.parametrize("which,index", [("image_points", 2), ("ground_points", 1)])
    def test_duplicate_reference_points(self, which, index):
        q, g = CALIB_Q.copy(), CALIB_G.copy()
        (q if which == "image_points" else g)[index] = (q if which == "image_points" else g)[0]
        with pytest.raises(ValueError, match=rf"{which}\[0\] and {which}\[{index}\] are the same point"):
            RegressionCorrector().fit(perturbed(HAND_ERROR), q, g, ORIGIN)

    @pytest.mark.parametrize("order,pair", [
        ((0, 1, 2, 1, 0), (0, 4)),  # two points measured twice: the first of them is named, with its repeat
        ((0, 1, 2, 2, 1), (1, 4)),
        ((0, 1, 2, 3, 3), (3, 4)),
    ])
    def test_duplicates_name_the_first_point_measured_twice(self, order, pair):
        g = np.array([[0.0, 10.0], [1.0, 20.0], [-1.0, 30.0], [2.0, 40.0]])[list(order)]
        q = CAM.project_ground(np.column_stack([np.arange(5.0), np.full(5, 15.0)]))  # distinct image points
        with pytest.raises(ValueError, match=rf"ground_points\[{pair[0]}\] and ground_points\[{pair[1]}\] are the same"):
            RegressionCorrector().fit(perturbed(HAND_ERROR), q, g, ORIGIN)

    def test_more_than_max_reference_points_is_refused(self):
        from homocal.correctors import MAX_REFERENCE_POINTS

        g = np.column_stack([np.zeros(MAX_REFERENCE_POINTS + 1), 10.0 + np.arange(MAX_REFERENCE_POINTS + 1) * 1e-4])
        with pytest.raises(ValueError, match=r"image_points: at most 100,000 reference points, got 100,001"):
            RegressionCorrector().fit(perturbed(HAND_ERROR), CAM.project_ground(g), g, ORIGIN)

    @pytest.mark.parametrize("which", ["image_points", "ground_points"])
    def test_overflow_has_its_own_message(self, which):
        q, g = CALIB_Q.copy(), CALIB_G.copy()
        (q if which == "image_points" else g)[1, 0] = 1e308
        with pytest.raises(ValueError, match=rf"{which}: point 1 = \[1e\+308, .*out of range"):
            RegressionCorrector().fit(perturbed(HAND_ERROR), q, g, ORIGIN)

    def test_point_behind_the_camera_warns(self):
        g = CALIB_G * [[1.0, -1.0], [1.0, 1.0], [1.0, 1.0]]  # a sign error: y negative
        with pytest.warns(UserWarning, match=r"ground_points\[0\] = \[0\.0, -10\.0\] is behind the camera"):
            RegressionCorrector().fit(perturbed(HAND_ERROR), CALIB_Q, g, ORIGIN)

    def test_not_fitted(self):
        with pytest.raises(RuntimeError, match="not fitted"):
            RegressionCorrector().transform_points(CALIB_Q)

    def test_accepts_n12_and_beyond_horizon_gives_nan(self):
        reg = RegressionCorrector().fit(perturbed(HAND_ERROR), CALIB_Q.reshape(-1, 1, 2), CALIB_G, ORIGIN)
        out = reg.transform_points([[640.0, 100.0], [640.0, 600.0]])
        assert np.isnan(out[0]).all() and np.isfinite(out[1]).all()


# ---- the method catalogue -------------------------------------------------------------------------------
def standing_people(n: int = 40) -> np.ndarray:
    """Boxes (n, 4) homocal px of people 1.5-1.8 m tall standing 8-40 m ahead of CAM (columns +-0.2 m)."""
    y = np.linspace(8.0, 40.0, n)
    feet = np.column_stack([np.linspace(-3.0, 3.0, n), y])
    foot, head = CAM.project_ground(feet), CAM.project(np.column_stack([feet, np.linspace(1.5, 1.8, n)]))
    half = CAM.focal_px * 0.2 / y
    return np.column_stack([foot[:, 0] - half, head[:, 1], foot[:, 0] + half, foot[:, 1]])


class TestCatalogue:
    def test_study_columns_are_the_shards_columns(self):
        """The shards' column names are a data format (data_schema.md): the catalogue's order is theirs."""
        from homocal.study import kernels

        assert kernels.OUT_COLUMNS[1:] == tuple(f"{kind}_{m}" for m in (
            "regression", "regression_signed", "regression_intercept", "horizon", "least_change", "descent", "hybrid")
            for kind in ("cal", "path")) + ("hybrid_regression",)

    @pytest.mark.parametrize("name", list(METHODS))
    def test_each_method_round_trips_through_its_json(self, name, tmp_path):
        """An entry makes its class, the fitted corrector (from reference points or from people's boxes, as its
        evidence says) is found again by method_of, also after save/load."""
        method = METHODS[name]
        corrector = method.make()
        assert isinstance(corrector, method.corrector) and method_of(corrector) is method
        clicked = ViewTransformer(IMAGE + HAND_ERROR, GROUND)
        if method.evidence == "boxes":
            corrector.fit(clicked, standing_people(), convention="homocal", K=CAM.K, camera_height_m=4.0)
        else:
            corrector.fit(clicked, CALIB_Q, CALIB_G, ORIGIN)
        corrector.save(tmp_path / "c.json")
        loaded = load_corrector(tmp_path / "c.json")
        assert json.loads((tmp_path / "c.json").read_text())["method"] == method.json_method
        assert method_of(loaded) is method and label(loaded).split(" ")[0] == name

    @pytest.mark.parametrize("name, settings, message", [
        ("regression", {"seed": 1}, "seed: not a setting of regression"),
        ("descent", {"threshold": 50.0}, "threshold: not a setting of descent"),
        ("least-change", {"click_sigma_px": -1.0}, "click_sigma_px must be a finite number > 0"),
    ])  # fmt: skip
    def test_bad_settings(self, name, settings, message):
        with pytest.raises(ValueError, match=message):
            METHODS[name].make(**settings)

    @pytest.mark.parametrize("name", ["magic", ["regression"], None, ""])
    def test_unknown_method_names_the_parameter(self, name):
        with pytest.raises(ValueError, match="method: expected one of regression, "):
            get_method(name)


def test_ui_and_study_never_import_the_cli_module():
    """The page and the study call the library, not a command-line module (issue 24)."""
    root = Path(__file__).resolve().parents[2] / "homocal"
    offenders = [str(p.relative_to(root)) for folder in ("ui", "study") for p in (root / folder).rglob("*.py")
                 if re.search(r"homocal\.correctors\.cli|from homocal\.correctors import cli", p.read_text())]
    assert offenders == []

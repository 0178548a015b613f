"""homocal.ground_uncertainty against Monte Carlo on the paper's camera, sigma_radius against eigenvalues,
max_trustworthy_range against a dense scan of the same radii; bad input."""
import math

import numpy as np
import pytest

from homocal import PinholeCamera, ViewTransformer, ground_uncertainty, max_trustworthy_range, sigma_radius
from homocal.geometry import homography_from_quads, apply_homography
from homocal.uncertainty import straight_ahead_column

CAM = PinholeCamera()
GROUND = np.array([[-3.5, 30.0], [3.5, 30.0], [3.5, 8.0], [-3.5, 8.0]])
VT = ViewTransformer(CAM.project_ground(GROUND), GROUND)
POINTS_G = np.array([[0.0, 5.0], [0.0, 10.0], [0.0, 20.0], [0.0, 35.0], [0.0, 50.0], [-6.0, 15.0], [8.0, 40.0]])
POINTS_Q = CAM.project_ground(POINTS_G)


def monte_carlo(click, point, map_sigma, draws=4000, seed=0):
    """Sample covariances (N, 2, 2) of the mapped points under the same independent Gaussian errors."""
    rng = np.random.default_rng(seed)
    out = np.empty((draws, len(POINTS_Q), 2))
    for n in range(draws):
        H = homography_from_quads(VT.source + rng.normal(0, click, (4, 2)), VT.target + rng.normal(0, map_sigma, (4, 2)))
        out[n] = apply_homography(H, POINTS_Q + rng.normal(0, point, POINTS_Q.shape))
    d = out - out.mean(axis=0)
    return np.einsum("sni,snj->nij", d, d) / (draws - 1)


@pytest.mark.parametrize("click,point,map_sigma", [(1.5, 1.0, 0.0), (1.5, 0.0, 0.0), (0.0, 1.0, 0.0), (0.5, 0.5, 0.1)])
def test_radii_match_monte_carlo_out_to_50_m(click, point, map_sigma):
    cov = ground_uncertainty(VT, POINTS_Q, click_sigma_px=click, point_sigma_px=point, map_sigma_px=map_sigma)
    mc = monte_carlo(click, point, map_sigma)
    np.testing.assert_allclose(sigma_radius(cov), sigma_radius(mc), rtol=0.10)
    np.testing.assert_allclose(np.sqrt(np.trace(cov, axis1=1, axis2=2)), np.sqrt(np.trace(mc, axis1=1, axis2=2)),
                               rtol=0.10)


def test_radius_grows_with_range_beyond_the_trapezoid():
    r = sigma_radius(ground_uncertainty(VT, POINTS_Q[1:5]))  # 10-50 m (5 m, below the trapezoid, is extrapolated)
    assert np.all(np.diff(r) > 0) and r[-1] > 10 * r[0]


def test_sigma_radius_is_the_largest_eigenvalue():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(20, 2, 2))
    cov = A @ A.transpose(0, 2, 1)
    np.testing.assert_allclose(sigma_radius(cov), np.sqrt(np.linalg.eigvalsh(cov)[:, -1]), rtol=1e-12)


def test_above_horizon_is_nan():
    cov = ground_uncertainty(VT, [[640.0, 100.0], [640.0, 500.0]])
    assert np.isnan(cov[0]).all() and np.isfinite(cov[1]).all()


def test_zero_sigmas_give_zero():
    np.testing.assert_array_equal(ground_uncertainty(VT, POINTS_Q, 0.0, 0.0), 0.0)


@pytest.mark.parametrize("kwargs,match", [
    ({"click_sigma_px": -1.0}, "click_sigma_px"),
    ({"point_sigma_px": math.nan}, "point_sigma_px"),
    ({"map_sigma_px": math.inf}, "map_sigma_px"),
])
def test_bad_sigmas(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ground_uncertainty(VT, POINTS_Q, **kwargs)


class TestMaxTrustworthyRange:
    def test_straight_ahead_is_the_principal_column(self):
        assert straight_ahead_column(VT) == pytest.approx(CAM.K[0, 2], abs=1e-6)

    @pytest.mark.parametrize("tolerance", [0.1, 0.5, 2.0])
    @pytest.mark.parametrize("u", [639.5, 300.0])
    def test_matches_a_dense_scan(self, tolerance, u):
        rows = VT.horizon_row(u) + np.geomspace(VT.source[:, 1].max() - VT.horizon_row(u), 0.5, 20000)
        q = np.column_stack([np.full(len(rows), u), rows])
        ok = sigma_radius(ground_uncertainty(VT, q)) <= tolerance
        first_bad = np.argmin(ok)
        assert ok[0] and not ok[first_bad]
        expected = np.linalg.norm(VT.transform_points(q[first_bad - 1 : first_bad + 1]), axis=1)
        r = max_trustworthy_range(VT, tolerance, columns=[u])
        assert r.shape == (1,) and expected[0] <= r[0] <= expected[1]

    def test_default_column_and_scalar_result(self):
        r = max_trustworthy_range(VT, 0.5)
        assert isinstance(r, float) and r == max_trustworthy_range(VT, 0.5, columns=[straight_ahead_column(VT)])[0]
        assert 10.0 < r < 80.0

    def test_limits(self):
        assert max_trustworthy_range(VT, 1e-6) == 0.0
        assert max_trustworthy_range(VT, 0.5, click_sigma_px=0.0, point_sigma_px=0.0) == math.inf

    @pytest.mark.parametrize("tolerance", [0.0, -1.0, math.nan, math.inf])
    def test_bad_tolerance(self, tolerance):
        with pytest.raises(ValueError, match="tolerance_m"):
            max_trustworthy_range(VT, tolerance)


def test_readme_street_example_figures():
    """The figures the README's Python example shows (examples/street)."""
    from homocal import HorizonCorrector, SiteMap

    site_map = SiteMap(scale_px_per_m=10.0, origin_px=(400, 600))
    vt = ViewTransformer(source=[[573, 282], [707, 285], [875, 480], [404, 479]],
                         target=site_map.to_metres([[365, 300], [435, 300], [435, 520], [365, 520]]))
    cov = ground_uncertainty(vt, [[384.0, 394.7], [614.8, 253.6]])
    assert cov.shape == (2, 2, 2) and np.round(sigma_radius(cov), 3).tolist() == [0.178, 1.751]
    assert round(max_trustworthy_range(vt, 0.5), 1) == 28.1
    assert np.round(max_trustworthy_range(vt, 0.5, columns=[300.0, 980.0]), 1).tolist() == [17.1, 16.7]
    hc = HorizonCorrector().fit(vt, [[639.5, 429.4], [648.1, 321.7], [636.1, 272.1]],
                                [[0.0, 10.0], [0.3, 20.0], [-0.2, 35.0]], camera_origin=[0.0, 0.0])
    assert round(hc.horizon_shift_, 3) == 0.313 and hc.m.shape == (3, 3)


class TestThroughTheLens:
    """Clicks and detections on a distorted frame (scene3's camera: a wide barrel lens, roll 1, yaw 8): the
    sigmas are the frame's pixels; ground_uncertainty(lens=) against Monte Carlo through the real lens (the
    noisy frame pixels undistorted by Lens.undistort_points, then the closed-form homography)."""

    CAM3 = PinholeCamera(roll_deg=1.0, yaw_deg=8.0, distortion=(-0.30678, 0.0825017, 0.0028784, -0.00015829, 0.0))
    GROUND3 = np.array([[-7.5, 30.0], [7.5, 30.0], [7.5, 7.0], [-7.5, 7.0]])  # the sidewalks' outer edges, 7-30 m
    POINTS3 = np.array([[-7.5, 6.0], [-7.0, 12.0], [7.0, 8.0], [7.5, 20.0], [6.0, 5.0], [0.0, 15.0], [-3.0, 45.0]])

    def monte_carlo(self, click, point, draws=20000, seed=0):
        lens, rng = self.CAM3.lens, np.random.default_rng(seed)
        corners, points = self.CAM3.project_ground(self.GROUND3), self.CAM3.project_ground(self.POINTS3)
        clicked = lens.undistort_points((corners + rng.normal(0, click, (draws, 4, 2))).reshape(-1, 2)).reshape(draws, 4, 2)
        seen = lens.undistort_points((points + rng.normal(0, point, (draws, *points.shape))).reshape(-1, 2))
        seen = seen.reshape(draws, *points.shape)
        x, y, (X, Y), one, zero = clicked[..., 0], clicked[..., 1], self.GROUND3.T, np.ones((draws, 4)), np.zeros((draws, 4))
        rows = np.concatenate([np.stack([x, y, one, zero, zero, zero, -X * x, -X * y], -1),
                               np.stack([zero, zero, zero, x, y, one, -Y * x, -Y * y], -1)], axis=1)  # the DLT, h33 = 1
        H = np.append(np.linalg.solve(rows, np.broadcast_to(np.concatenate([X, Y])[:, None], (draws, 8, 1)))[..., 0], one[:, :1], 1)
        mapped = np.concatenate([seen, np.ones((draws, len(points), 1))], 2) @ H.reshape(draws, 3, 3).transpose(0, 2, 1)
        out = mapped[..., :2] / mapped[..., 2:]
        d = out - out.mean(axis=0)
        return np.einsum("sni,snj->nij", d, d) / (draws - 1)

    @pytest.mark.parametrize("click,point", [(0.5, 0.0), (0.0, 0.5), (0.5, 0.5)])
    def test_matches_monte_carlo_through_the_lens(self, click, point):
        """Each axis of every point's 1-sigma ellipse within 2.5 % of the Monte Carlo's: 20,000 draws give a
        standard deviation to 1 / sqrt(2 * 20000) = 0.5 % (5 standard errors), and 0.5 px keeps the first order's
        own error below that (here within 1.1 %). The pinhole's propagation (no lens) misses by 26-50 %: this
        trapezoid's corners and the points lie out towards the frame's edges, where the lens stretches 1.3-2x."""
        lens = self.CAM3.lens
        vt = ViewTransformer(lens.undistort_points(self.CAM3.project_ground(self.GROUND3)), self.GROUND3)
        q = lens.undistort_points(self.CAM3.project_ground(self.POINTS3))
        mc = self.monte_carlo(click, point)
        cov = ground_uncertainty(vt, q, click_sigma_px=click, point_sigma_px=point, lens=lens)
        for which in (0, 1):  # the ellipse's minor and major axes
            np.testing.assert_allclose(np.sqrt(np.linalg.eigvalsh(cov)[:, which]), np.sqrt(np.linalg.eigvalsh(mc)[:, which]),
                                       rtol=0.025)
        pinhole = sigma_radius(ground_uncertainty(vt, q, click_sigma_px=click, point_sigma_px=point))
        assert np.max(np.abs(pinhole / sigma_radius(mc) - 1)) > 0.25  # the lens term is needed

    def test_distort_jacobian_against_differences(self):
        """Lens.distort_jacobian against central differences of distort_points (step 1e-4 px: truncation
        ~ step^2 times the model's third derivative, far below 1e-6)."""
        lens = self.CAM3.lens
        u = np.stack(np.meshgrid(np.linspace(-300, 1580, 9), np.linspace(-200, 920, 7)), -1).reshape(-1, 2)
        h = 1e-4
        diff = np.stack([(lens.distort_points(u + e) - lens.distort_points(u - e)) / (2 * h) for e in ([h, 0], [0, h])], axis=2)
        np.testing.assert_allclose(lens.distort_jacobian(u), diff, atol=1e-6)

    def test_identity_lens_changes_nothing(self):
        from homocal.geometry.lens import Lens
        flat = Lens(CAM.K, np.zeros(5), (CAM.width, CAM.height))
        np.testing.assert_array_equal(ground_uncertainty(VT, POINTS_Q, lens=flat), ground_uncertainty(VT, POINTS_Q))

    def test_a_correction_with_a_lens_uses_it(self):
        """Corrector.ground_uncertainty of a correction carrying a lens (lens_, as homocal fit --camera-json saves
        it) is ground_uncertainty of its mapping through that lens, not the pinhole's."""
        from homocal.correctors.horizon import HorizonCorrector
        lens = self.CAM3.lens
        vt = ViewTransformer(lens.undistort_points(self.CAM3.project_ground(self.GROUND3)), self.GROUND3)
        q = lens.undistort_points(self.CAM3.project_ground(self.POINTS3))
        c = HorizonCorrector().fit(vt, q[:3], self.POINTS3[:3], (0.0, 0.0))
        c.lens_ = lens
        np.testing.assert_array_equal(c.ground_uncertainty(q), ground_uncertainty(c.mapping, q, lens=lens))
        assert not np.allclose(c.ground_uncertainty(q), ground_uncertainty(c.mapping, q))

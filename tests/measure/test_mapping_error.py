"""homocal measure's split of the error model (measure_tracks(split_mapping_error=True)): the filter's
measurement noise the foot point's own, the shared mapping error's share of a velocity against a Monte Carlo over
perturbed clicked trapezoids, and the smoothed speed's sigma against a batch least-squares line fit."""
import numpy as np
import pytest

from homocal.geometry import Lens, apply_homography, homography_from_quads, read_trapezoid_file
from homocal.measure.kalman import HALF_WIDTH_TOLERANCE
from homocal.measure.tracks import (TrapezoidMapping, box_height_sigma_px, mapping_modes, mapping_velocity_covariance,
                                    measure_tracks, point_noise)
from homocal.uncertainty import ground_uncertainty

CLICK_PX = 1.5
TRANSFORMER = read_trapezoid_file("examples/street/trapezoid.json")[0]  # metres, camera at the origin
MAPPING = TrapezoidMapping(TRANSFORMER)
LENS = Lens(np.array([[586.452, 0.0, 639.5], [0.0, 586.452, 359.5], [0.0, 0.0, 1.0]]),
            [-0.2, 0.04, 5e-4, -3e-4, -0.002], (1280, 720))  # a wide barrel lens on the street's 1280x720 frame


def monte_carlo_velocity_cov(ground: np.ndarray, v: np.ndarray, n: int = 2000) -> np.ndarray:
    """(2, 2) covariance of the velocity v (2,) m/s at ground point (2,) seen through n trapezoids whose clicked
    corners move by CLICK_PX: each perturbed homography applied to the foot points of ground -+ v h."""
    h = 0.05
    q = TRANSFORMER.inverse_transform_points(np.stack([ground - h * v, ground + h * v]))
    rng = np.random.default_rng(0)
    dv = []
    for _ in range(n):
        a, b = apply_homography(homography_from_quads(TRANSFORMER.source + rng.normal(0, CLICK_PX, (4, 2)),
                                                       TRANSFORMER.target), q)
        dv.append((b - a) / (2 * h))
    return np.cov(np.array(dv).T)


def test_point_noise_is_the_foot_points_own_part_and_the_modes_the_rest():
    feet = TRANSFORMER.inverse_transform_points(np.array([[0.0, 10.0], [2.0, 25.0], [-3.0, 40.0]]))
    cov = MAPPING.ground_uncertainty(feet, click_sigma_px=CLICK_PX, point_sigma_px=2.0)
    own = ground_uncertainty(TRANSFORMER, feet, click_sigma_px=0.0, point_sigma_px=2.0)
    np.testing.assert_allclose(point_noise(MAPPING, feet, 2.0), own, rtol=1e-9, atol=1e-12)
    J, C = mapping_modes(MAPPING, feet, CLICK_PX)
    np.testing.assert_allclose(J @ C @ J.transpose(0, 2, 1), cov - own, rtol=1e-9, atol=1e-12)


@pytest.mark.slow  # ~3-6 s: the Monte Carlo
def test_mapping_velocity_covariance_against_monte_carlo():
    for ground, v in (([0.0, 12.0], [0.0, 1.3]), ([3.0, 25.0], [1.3, 0.0]), ([-2.0, 40.0], [-0.9, 0.9])):
        ground, v = np.array(ground), np.array(v)
        feet = TRANSFORMER.inverse_transform_points(ground[None])
        S = mapping_velocity_covariance(MAPPING, feet, v[None], CLICK_PX)[0]
        mc = monte_carlo_velocity_cov(ground, v)
        u = v / np.linalg.norm(v)
        # 2000 draws: the sample sigma is good to ~2 % (1 / sqrt(2 n)); first order at 1.5 px to a few %
        assert abs(np.sqrt(u @ S @ u) / np.sqrt(u @ mc @ u) - 1) < 0.1, (ground, v)
        assert abs(np.sqrt(np.trace(S) / np.trace(mc)) - 1) < 0.1, (ground, v)


def test_split_speed_sigma_is_the_line_fit_plus_the_mapping_share():
    """A straight walk at constant velocity with almost no process noise: the smoothed velocity's covariance is
    the weighted least-squares line fit's, [sum A_k^T R_k^-1 A_k]^-1 with A_k = [I, t_k I] and R_k the foot
    point's own covariance; the speed's variance adds the Monte Carlo's mapping share along the velocity."""
    fps, v = 10.0, np.array([0.8, 1.1])
    t = np.arange(30) / fps
    ground = np.array([-2.0, 15.0]) + t[:, None] * v
    feet = TRANSFORMER.inverse_transform_points(ground)
    (table,) = measure_tracks(TRANSFORMER, np.arange(30), feet, np.zeros(30, int), fps, accel_psd=1e-12,
                              click_sigma_px=CLICK_PX, split_mapping_error=True)
    R = ground_uncertainty(TRANSFORMER, feet, click_sigma_px=0.0, point_sigma_px=1.0)
    info = np.zeros((4, 4))
    for tk, Rk in zip(t, R):
        A = np.hstack([np.eye(2), tk * np.eye(2)])
        info += A.T @ np.linalg.inv(Rk) @ A
    Pv = np.linalg.inv(info)[2:, 2:]
    u = v / np.linalg.norm(v)
    np.testing.assert_allclose(table["speed_mps"], np.linalg.norm(v), rtol=1e-5)  # the start prior's pull
    for k in (0, 29):
        expected = np.sqrt(u @ (Pv + monte_carlo_velocity_cov(ground[k], v)) @ u)
        assert abs(table["speed_sigma_mps"][k] / expected - 1) < 0.1, k


def test_pedestrians_fitted_horizon_share_against_moving_the_horizon():
    """A PedestrianCorrector's shared error includes its fitted horizon's (sigma horizon_sigma_px_): its share of
    a velocity against the velocity seen through the correction with its horizon moved by -+ sigma / 100."""
    import copy

    from tests.correctors.test_pedestrians import _fit
    c = _fit()
    assert not c.roll_estimated_
    ground, v = np.array([[1.0, 30.0]]), np.array([[0.6, -1.2]])
    h = 0.05
    q = c.transformer_.inverse_transform_points(np.vstack([ground - h * v, ground + h * v]))
    moved, ends = copy.copy(c), []
    for sign in (1.0, -1.0):
        moved.horizon_row_ = c.horizon_row_ + sign * c.horizon_sigma_px_ / 100
        moved._set_transformer()
        a, b = moved.transform_points(q)
        ends.append((b - a) / (2 * h))
    d = 100 * (ends[0] - ends[1]) / 2  # the velocity's change per sigma of the horizon
    feet = c.transformer_.inverse_transform_points(ground)
    S = mapping_velocity_covariance(c, feet, v, click_sigma_px=0.0)[0]
    np.testing.assert_allclose(S, np.outer(d, d), rtol=1e-3, atol=1e-3 * (d @ d))
    assert d @ d > 1e-6  # not negligible


@pytest.mark.parametrize("lens", [None, LENS], ids=["pinhole", "lens"])
def test_per_axis_point_noise_against_the_mappings_derivative(lens):
    """point_noise with a (u, v) sigma pair a foot point: J diag(s_u^2, s_v^2) J^T, J the derivative of the ground
    point with respect to the foot point where it is detected (the lens's distorted frame), by central differences
    of transform_points after the lens's inverse (undistort_points, exact to ~1e-12 px); exact also for a sigma far
    below the clicking error at 40 m, where taking the shared part away from the whole covariance lost 1e-4 of it
    at 1e-6 px. Tolerance: over h = 1e-3 px the differences' truncation is ~(h / d)^2 relative, d >= 30 px the
    points' distance to the horizon (1e-9), their rounding ~1e-12 px / h (1e-9): rtol 1e-6."""
    mapping = TrapezoidMapping(TRANSFORMER, lens)
    feet = TRANSFORMER.inverse_transform_points(np.array([[0.0, 10.0], [2.0, 25.0], [3.0, 45.0]]))  # undistorted px
    seen = feet if lens is None else lens.distort_points(feet)
    to_ground = lambda d: TRANSFORMER.transform_points(d if lens is None else lens.undistort_points(d))  # noqa: E731
    h = 1e-3
    J = np.stack([(to_ground(seen + h * e) - to_ground(seen - h * e)) / (2 * h) for e in np.eye(2)], axis=-1)
    sigma = np.array([[3.0, 1.0], [0.5, 2.0], [1e-6, 1e-6]])
    expected = J @ (sigma[:, :, None]**2 * np.eye(2)) @ J.transpose(0, 2, 1)
    actual = point_noise(mapping, feet, sigma)
    for a, e in zip(actual, expected):  # an off-diagonal term near 0: to 1e-9 of its covariance's largest
        np.testing.assert_allclose(a, e, rtol=1e-6, atol=1e-9 * np.abs(e).max())
    swapped = point_noise(mapping, feet, sigma[:, ::-1])  # straight ahead the range, y, is v's: 3 px of v, not 1
    assert swapped[0, 1, 1] > 4 * actual[0, 1, 1]


def test_box_height_sigma_is_the_fitted_pair_times_the_height():
    """A box of height h px: (u, v) sigmas FOOT_SIGMA_PER_BOX_HEIGHT x h, whichever way up its corners come."""
    xyxy = np.array([[100.0, 200.0, 140.0, 280.0], [10.0, 70.0, 20.0, 50.0]])  # 80 px, 20 px (y2 < y1)
    np.testing.assert_allclose(box_height_sigma_px(xyxy), [[0.086 * 80, 0.032 * 80], [0.086 * 20, 0.032 * 20]],
                               rtol=1e-14)


def test_point_sigma_of_another_shape_is_refused():
    feet = TRANSFORMER.inverse_transform_points(np.array([[0.0, 10.0], [1.0, 11.0]]))
    with pytest.raises(ValueError, match=r"point_sigma_px: expected a number or \(N, 2\)"):
        next(measure_tracks(MAPPING, [0, 1], feet, [0, 0], 10.0, point_sigma_px=np.ones(2)))


def test_per_box_sigma_of_one_value_is_the_scalar_and_the_bar_grows_with_it():
    fps, v = 10.0, np.array([0.8, 1.1])
    t = np.arange(30) / fps
    feet = TRANSFORMER.inverse_transform_points(np.array([-2.0, 15.0]) + t[:, None] * v)
    frames, ids = np.arange(30), np.zeros(30, int)
    run = lambda s: next(measure_tracks(MAPPING, frames, feet, ids, fps, point_sigma_px=s, split_mapping_error=True))  # noqa: E731
    same, scalar = run(np.full((30, 2), 2.0)), run(2.0)
    for c in ("sigma_m", "speed_mps", "speed_sigma_mps"):
        np.testing.assert_allclose(same[c], scalar[c], rtol=1e-12)
    wide = run(np.r_[np.full((15, 2), 2.0), np.full((15, 2), 8.0)])
    assert (wide["sigma_m"][15:] > scalar["sigma_m"][15:]).all()
    np.testing.assert_allclose(wide["sigma_m"][:15], scalar["sigma_m"][:15], rtol=1e-12)
    assert wide["speed_sigma_mps"][-1] > scalar["speed_sigma_mps"][-1]


@pytest.mark.parametrize("accel_psd", [0.5, "imm"])
def test_noise_scale_is_the_foot_points_sigma_times_it_in_the_filter(accel_psd):
    """With the split the filter's R is the foot point's own noise, point_noise, quadratic in its sigma: the filter
    with R x c^2 (noise_scale c) is the filter at the foot sigma c times as large, whose points' sigma_m alone
    differ (the same products in another order, 1e-16 apart, through the filter's conditioning: 1e-9; the IMM's
    sigma a bisection's, to HALF_WIDTH_TOLERANCE); noise_scale 1 is the filter as it is, to the bit."""
    fps, v = 10.0, np.array([0.8, 1.1])
    t = np.arange(30) / fps
    feet = TRANSFORMER.inverse_transform_points(np.array([-2.0, 15.0]) + t[:, None] * v)
    feet = feet + np.random.default_rng(4).normal(0, 1.0, feet.shape)
    frames, ids = np.arange(30), np.zeros(30, int)
    run = lambda s, c=1.0, **kw: next(measure_tracks(MAPPING, frames, feet, ids, fps, accel_psd=accel_psd, point_sigma_px=s,  # noqa: E731
                                                     split_mapping_error=True, noise_scale=c, **kw))
    scaled, wide = run(2.0, 0.4), run(0.8)
    for c in ("x_smooth", "y_smooth", "vx", "vy", "speed_mps", "speed_sigma_mps"):
        np.testing.assert_allclose(scaled[c], wide[c], rtol=HALF_WIDTH_TOLERANCE if c == "speed_sigma_mps" else 1e-9)
    same = run(2.0)
    for c in same:
        np.testing.assert_array_equal(same[c], next(measure_tracks(MAPPING, frames, feet, ids, fps, accel_psd=accel_psd,
                                                                   point_sigma_px=2.0, split_mapping_error=True))[c])


@pytest.mark.parametrize("tau, split", [(0.5, False), (0.0, True), (-1.0, True)])
def test_foot_correlation_needs_the_split_and_a_positive_time(tau, split):
    feet = TRANSFORMER.inverse_transform_points(np.array([[0.0, 10.0], [0.1, 10.1]]))
    with pytest.raises(ValueError, match="foot_correlation_s: expected > 0 with split_mapping_error=True"):
        next(measure_tracks(MAPPING, np.arange(2), feet, np.zeros(2, int), 10.0, split_mapping_error=split,
                            foot_correlation_s=tau))


@pytest.mark.parametrize("scale", [0.0, -1.0, float("nan")])
def test_noise_scale_must_be_positive(scale):
    feet = TRANSFORMER.inverse_transform_points(np.array([[0.0, 10.0], [0.1, 10.1]]))
    with pytest.raises(ValueError, match="noise_scale: expected a finite number > 0"):
        next(measure_tracks(MAPPING, np.arange(2), feet, np.zeros(2, int), 10.0, noise_scale=scale))

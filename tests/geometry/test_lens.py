"""homocal.geometry.Lens against OpenCV's projectPoints, brute-force radial maps and round trips."""
import cv2
import numpy as np
import pytest

from homocal.geometry import Lens, PinholeCamera

K = PinholeCamera().K  # the card's camera: 1280x720, f = 586.45 px
SIZE = (1280, 720)
BARREL = [-0.2, 0.04, 0.0, 0.0, 0.0]  # monotonic everywhere (1 - 0.6 s + 0.2 s^2 has no real root)
STRONG = [-0.30, 0.09, 5e-4, -3e-4, -0.012]  # folds at r* = 1.777, inside the frame's corners
ROUND_TRIP_PX = 1e-6


def frame_grid(step: float = 8.0) -> np.ndarray:
    """(N, 2) pixels covering the whole frame, its outer pixel edges included."""
    u, v = np.meshgrid(np.append(np.arange(-0.5, 1279.5, step), 1279.5), np.append(np.arange(-0.5, 719.5, step), 719.5))
    return np.column_stack([u.ravel(), v.ravel()])


def opencv_distort(undistorted_px: np.ndarray, distortion) -> np.ndarray:
    """cv2.projectPoints of the rays through ideal pinhole pixels: the independent forward model."""
    rays = np.column_stack([(undistorted_px - K[:2, 2]) / np.diag(K)[:2], np.ones(len(undistorted_px))])
    pixels, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), K, np.asarray(distortion, float))
    return pixels[:, 0, :]


class TestForward:
    @pytest.mark.parametrize("distortion", [BARREL, STRONG, [0.1, -0.02, 2e-3, 1e-3, 0.001]])
    def test_matches_project_points(self, distortion):
        rng = np.random.default_rng(0)
        pts = rng.uniform([-300, -300], [1580, 1020], size=(2000, 2))
        np.testing.assert_allclose(Lens(K, distortion, SIZE).distort_points(pts), opencv_distort(pts, distortion),
                                   atol=1e-9)

    def test_identity_is_a_copy(self):
        lens = Lens(K, np.zeros(5), SIZE)
        pts = frame_grid(64.0)
        assert lens.is_identity and not Lens(K, BARREL, SIZE).is_identity
        for out in (lens.distort_points(pts), lens.undistort_points(pts)):
            assert out.tobytes() == pts.tobytes() and out is not pts


class TestInverse:
    def test_barrel_round_trip_whole_frame(self):
        lens = Lens(K, BARREL, SIZE).check_folds()
        pts = frame_grid()
        und = lens.undistort_points(pts)
        assert np.isfinite(und).all()
        assert np.abs(opencv_distort(und, BARREL) - pts).max() < ROUND_TRIP_PX

    def test_strong_lens_round_trip_where_monotonic(self):
        """Every frame point re-distorts exactly or is NaN; NaN only within the tangential terms' reach of the fold
        (their displacement is at most 4 (|p1| + |p2|) r^2, normalised) or beyond it."""
        lens = Lens(K, STRONG, SIZE)
        pts = frame_grid(6.0)
        und = lens.undistort_points(pts)
        ok = np.isfinite(und).all(axis=1)
        assert np.abs(opencv_distort(und[ok], STRONG) - pts[ok]).max() < ROUND_TRIP_PX
        rd = np.hypot(*((pts - K[:2, 2]) / K[0, 0]).T)
        r_star = lens.max_monotonic_radius
        band = 4 * (5e-4 + 3e-4) * r_star**2
        assert ok[rd < lens.max_distorted_radius - band].all()
        assert not ok[rd > lens.max_distorted_radius + band].any()
        assert 0.5 < ok.mean() < 1.0  # the test covers both kinds

    def test_strong_lens_inverse_is_unique(self):
        """Undistorted points inside the fold distort and come back to themselves (not another pre-image)."""
        lens = Lens(K, STRONG, SIZE)
        rng = np.random.default_rng(1)
        r, theta = 0.97 * lens.max_monotonic_radius * np.sqrt(rng.uniform(size=3000)), rng.uniform(0, 2 * np.pi, 3000)
        und = K[:2, 2] + K[0, 0] * np.column_stack([r * np.cos(theta), r * np.sin(theta)])
        back = lens.undistort_points(opencv_distort(und, STRONG))
        np.testing.assert_allclose(back, und, atol=ROUND_TRIP_PX)

    def test_nan_in_nan_out(self):
        out = Lens(K, BARREL, SIZE).undistort_points([[np.nan, 3.0], [640.0, 360.0]])
        assert np.isnan(out[0]).all() and np.isfinite(out[1]).all()


class TestFolds:
    def test_monotonic_radius_against_brute_force(self):
        r = np.linspace(0, 3, 300_001)
        k1, k2, _, _, k3 = STRONG
        g = r * (1 + k1 * r**2 + k2 * r**4 + k3 * r**6)
        first_drop = r[np.flatnonzero(np.diff(g) < 0)[0]]
        assert Lens(K, STRONG, SIZE).max_monotonic_radius == pytest.approx(first_drop, abs=2e-5)
        assert Lens(K, STRONG, SIZE).max_distorted_radius == pytest.approx(g.max(), abs=1e-9)
        assert Lens(K, BARREL, SIZE).max_monotonic_radius == np.inf

    @pytest.mark.parametrize("distortion", [STRONG, [-0.5, 0, 0, 0, 0], [0.1, -0.2, 0, 0, 0]])
    def test_fold_inside_frame_refused(self, distortion):
        with pytest.raises(ValueError, match=r"^distortion: .* folds the image at radius [^\n]*$"):
            Lens(K, distortion, SIZE).check_folds()

    def test_fold_outside_frame_accepted(self):
        lens = Lens(K - [[0, 0, 320], [0, 0, 180], [0, 0, 0]], STRONG, (640, 360))  # the central 640x360 crop
        assert lens.check_folds() is lens
        with pytest.raises(ValueError, match="folds"):
            lens.check_folds(SIZE)


@pytest.mark.parametrize("K_, distortion, size, field", [
    (np.eye(2), BARREL, SIZE, "K"),
    (np.where(np.eye(3) > 0, np.nan, K), BARREL, SIZE, "K"),
    (np.diag([-1.0, 1.0, 1.0]), BARREL, SIZE, "K"),
    (K + [[0, 1, 0], [0, 0, 0], [0, 0, 0]], BARREL, SIZE, "K"),
    ("K", BARREL, SIZE, "K"),
    (K, [-0.2, 0.04, 0.0, 0.0], SIZE, "distortion"),
    (K, [-0.2, np.inf, 0.0, 0.0, 0.0], SIZE, "distortion"),
    (K, BARREL, (1280.5, 720), "image_size"),
    (K, BARREL, (0, 720), "image_size"),
    (K, BARREL, (True, 720), "image_size"),
    (K, BARREL, (1280, 720, 3), "image_size"),
    (K, BARREL, (10**6, 720), "image_size"),
])
def test_bad_input_names_the_field(K_, distortion, size, field):
    with pytest.raises(ValueError, match=f"^{field}: [^\n]*$"):
        Lens(K_, distortion, size)


def test_equality_and_dict():
    lens = Lens(K, BARREL, SIZE)
    assert lens == Lens(K.tolist(), tuple(BARREL), [1280, 720]) and lens != Lens(K, STRONG, SIZE)
    assert lens.to_dict() == {"K": K.tolist(), "distortion": BARREL, "image_size": [1280, 720]}
    assert Lens(**lens.to_dict()) == lens


OTHER_F = K * [[1.01, 1, 1], [1, 1.01, 1], [1, 1, 1]]  # the focal length 1 % longer


@pytest.mark.parametrize("K_, size, field, given", [
    (OTHER_F, None, "K", str(OTHER_F.tolist())),
    (K + [[0, 0, 2.0], [0, 0, 0], [0, 0, 0]], SIZE, "K", "641.5"),  # the principal point 2 px right
    (np.where(np.eye(3) > 0, np.nan, K), SIZE, "K", "nan"),
    (np.eye(2), SIZE, "K", "[[1.0, 0.0], [0.0, 1.0]]"),
    ([[1, 2], [3]], SIZE, "K", "[[1, 2], [3]]"),
    (K, (1920, 1080), "image_size", "(1920, 1080)"),
    (None, (640, 360), "image_size", "(640, 360)"),
])
def test_check_matches_names_both(K_, size, field, given):
    """A K or image size other than the lens's: one line naming the value given and the lens's own."""
    lens = Lens(K, BARREL, SIZE)
    own = str(K.tolist()) if field == "K" else str(SIZE)
    with pytest.raises(ValueError, match=f"^{field}: [^\n]*$") as e:
        lens.check_matches(K_, size)
    assert given in str(e.value) and own in str(e.value)


def test_check_matches_accepts_the_same_camera():
    lens = Lens(K, BARREL, SIZE)
    assert lens.check_matches(K.tolist(), [1280, 720]) is lens and lens.check_matches() is lens
    assert lens.check_matches(K * (1 + 1e-12), np.array(SIZE)) is lens  # within a rounding of a text round trip

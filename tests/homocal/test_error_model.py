"""The Section 3 error model against the exact error of perturbed mappings (the paper's camera)."""
import numpy as np
import pytest

from homocal.error_model import column_model, first_order_error, horizon_shift, quadratic_error
from homocal.geometry import PinholeCamera, ViewTransformer

CAM = PinholeCamera()
GROUND = np.array([[-3.5, 30.0], [3.5, 30.0], [3.5, 8.0], [-3.5, 8.0]])
IMAGE = CAM.project_ground(GROUND)
H = ViewTransformer(IMAGE, GROUND).m
RANGES = np.arange(5.0, 51.0, 5.0)


def column_pixels(x: float) -> np.ndarray:
    """Pixels (N, 2) of the ground points (x, RANGES)."""
    return CAM.project_ground(np.column_stack([np.full_like(RANGES, x), RANGES]))


def exact_range(H_: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    p = np.column_stack([pixels, np.ones(len(pixels))]) @ H_.T
    return p[:, 1] / p[:, 2]


def row_shift(H_: np.ndarray, eps: float) -> np.ndarray:
    """The homography whose horizon is eps rows lower and which is otherwise the same: H(u, v - eps)."""
    return H_ @ np.array([[1.0, 0.0, 0.0], [0.0, 1.0, -eps], [0.0, 0.0, 1.0]])


def test_column_model_reproduces_the_mapping():
    pixels = column_pixels(0.0)
    m = column_model(H, pixels[:, 0])
    np.testing.assert_allclose(m.range_at(pixels[:, 1]), RANGES, atol=1e-9)
    np.testing.assert_allclose(m.v_h, CAM.horizon_row, atol=1e-9)


def test_K_and_offset_of_the_tilted_pinhole():
    """Independent derivation: Y = h f / (cos^2 t (v - v_h)) - h tan t on the central column."""
    t, f = np.radians(15.0), CAM.focal_px
    m = column_model(H, 639.5)
    assert m.K == pytest.approx(4.0 * f / np.cos(t) ** 2, rel=1e-12)
    assert m.offset == pytest.approx(-4.0 * np.tan(t), rel=1e-12)


@pytest.mark.parametrize("eps", [0.1, 0.5, 1.0, 3.0])
@pytest.mark.parametrize("x", [0.0, -6.0])
def test_horizon_shift_gives_the_quadratic_law(eps, x):
    pixels = column_pixels(x)
    Hp = row_shift(H, eps)
    assert horizon_shift(H, Hp, pixels[:, 0]) == pytest.approx(eps, rel=1e-9)
    m = column_model(H, pixels[:, 0])
    exact = exact_range(Hp, pixels) - RANGES
    predicted = quadratic_error(eps, m.K, RANGES - m.offset)
    q = m.K / (RANGES - m.offset)  # v - v_h
    # first order: exact = K eps / (q (q - eps)), prediction K eps / q^2: relative gap eps / (q - eps)
    np.testing.assert_allclose(exact / predicted - 1.0, eps / (q - eps), rtol=1e-6)
    # the paper's form with the true range: the Offset (about -1.07 m) is a small relative correction
    paper = quadratic_error(eps, m.K, RANGES)
    assert np.all(np.abs(paper / exact - 1.0)[RANGES >= 20] < 0.12 + 2 * eps / q[RANGES >= 20])


def test_first_order_error_is_second_order_accurate():
    """A general trapezoid error: the residual of the first-order model shrinks as the square of its size."""
    rng = np.random.default_rng(0)
    direction = rng.choice([-3.0, -2.0, -1.0, 1.0, 2.0, 3.0], size=(4, 2))
    pixels = column_pixels(1.5)
    residuals = []
    for scale in (1.0, 0.5, 0.25):
        Hp = ViewTransformer(IMAGE + scale * direction, GROUND).m
        exact = exact_range(Hp, pixels) - RANGES
        residuals.append(np.abs(exact - first_order_error(H, Hp, pixels[:, 0], RANGES)).max())
    assert residuals[0] / residuals[1] == pytest.approx(4.0, rel=0.25)
    assert residuals[1] / residuals[2] == pytest.approx(4.0, rel=0.25)


def test_error_grows_quadratically_with_range():
    """Fit the exact error of a 1 px horizon shift: the d^2 term explains it at range."""
    pixels = column_pixels(0.0)
    exact = exact_range(row_shift(H, 1.0), pixels) - RANGES
    coeffs = np.polyfit(RANGES, exact, 2)
    m = column_model(H, 639.5)
    assert coeffs[0] == pytest.approx(1.0 / m.K, rel=0.1)
    assert exact[-1] / exact[0] > 50  # 10x the range, roughly 100x the error

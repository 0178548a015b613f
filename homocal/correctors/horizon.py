"""Beyond the paper: its own error model (Section 3) turned into a correction. A trapezoid error shifts the
horizon by epsilon (eq. (9)); fit that one number to the reference points and undo it, as a homography."""
from __future__ import annotations

import math

import numpy as np

from homocal.correctors.base import Corrector
from homocal.correctors.serialization import number
from homocal.geometry import ViewTransformer

GRID_INTERVALS = 8  # the bracketing grid: epsilon_k = -delta + 2 delta k / 8, k = 1..8
NEWTON_STEPS = 8  # safeguarded Newton steps in the bracket at most (on tests/study/test_method_kernels.py's
# 300 cases: converged after 3-7 derivative evaluations, 5.6 on average)
FLAT = 1e-12  # the refined epsilon is kept unless its loss is above the grid's best by more than this, relative


def shifted_points(H: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n (N, 3), h (3,)): n_i = H (u_i, v_i, 1), h = H[:, 1], so that H_eps = H . row_shift(eps) (row_shift(eps):
    the image homography (u, v) -> (u, v + eps), [[1, 0, 0], [0, 1, eps], [0, 0, 1]]) maps q_i to
    (n_xy + eps h_xy) / (n_w + eps h_w): every loss evaluation is then 2 multiply-adds and a division a point."""
    return np.column_stack([q, np.ones(len(q))]) @ H.T, H[:, 1].copy()


def horizon_loss(n: np.ndarray, h: np.ndarray, g: np.ndarray, eps: float) -> float:
    """L(eps) = sum_i ||H_eps(q_i) - g_i||^2 for (n, h) = shifted_points(H, q) and ground points g (N, 2);
    +inf if a point is on or beyond the horizon of H_eps (n_w + eps h_w <= 0)."""
    W = n[:, 2] + eps * h[2]
    if np.any(W <= 0):
        return math.inf
    r = (n[:, :2] + eps * h[:2]) * (1.0 / W[:, None]) - g
    return float(np.sum(r * r))


def horizon_loss_derivatives(n: np.ndarray, h: np.ndarray, g: np.ndarray, eps: float) -> tuple[float, float]:
    """(L', L'') at eps, analytic: with W_i = n_w + eps h_w, r_i = (n_xy + eps h_xy) / W_i - g_i and
    c_i = h_xy n_w - n_xy h_w (constant in eps): r_i' = c_i / W_i^2, r_i'' = -2 h_w c_i / W_i^3,
    L' = 2 sum r.r', L'' = 2 sum (r'.r' + r.r'')."""
    inv = 1.0 / (n[:, 2:3] + eps * h[2])
    r = (n[:, :2] + eps * h[:2]) * inv - g
    r1 = (h[:2] * n[:, 2:3] - n[:, :2] * h[2]) * (inv * inv)
    r2 = -2.0 * h[2] * r1 * inv
    return 2.0 * float(np.sum(r * r1)), 2.0 * float(np.sum(r1 * r1 + r * r2))


def newton_step(a: float, b: float, x: float, d1: float, d2: float) -> tuple[float, float, float, bool]:
    """One safeguarded Newton step on L' = 0 in the bracket [a, b] from x, given d1 = L'(x), d2 = L''(x)
    (fit_horizon_shift's step 2; the compiled kernel calls this same function): (a, b, x, converged)."""
    if d1 > 0:
        b = x
    elif d1 < 0:
        a = x
    else:
        return a, b, x, True
    step = d1 / d2 if d2 > 0 else math.inf
    if abs(step) <= 1e-12 * (1.0 + abs(x)):  # converged: x is within ~1e-12 relative of the minimum
        return a, b, x, True
    return a, b, (x - step if a < x - step < b else 0.5 * (a + b)), False


def search_half_width(H: np.ndarray, q: np.ndarray) -> float:
    """delta = min_i (v_i - v_h(u_i)), pixels: how far the nearest-to-horizon point q_i (N, 2) lies below H's
    horizon. epsilon must exceed -delta (else that point is beyond the corrected horizon)."""
    if not H[2, 1] > 0:
        raise ValueError("the mapping's horizon is not crossed by the image columns (h32 <= 0): no row shift to fit")
    w = np.column_stack([q, np.ones(len(q))]) @ H[2]
    return float(np.min(w) / H[2, 1])


def fit_horizon_shift(H: np.ndarray, q: np.ndarray, g: np.ndarray) -> tuple[float, float]:
    """(epsilon, delta): the least-squares horizon shift of H (eq. (9)) for image points q (N, 2) px and their
    ground truth g (N, 2), over the range (-delta, delta], delta = search_half_width(H, q).

    1. Bracket: L(eps) = horizon_loss at eps_k = -delta + 2 delta k / GRID_INTERVALS, k = 1..GRID_INTERVALS
       (eps = 0 among them); k* = the first smallest; bracket [a, b] = [eps_{k*-1}, eps_{k*+1}] (a = -delta for
       k* = 1, b = delta for k* = GRID_INTERVALS).
    2. Safeguarded Newton on L' = 0 from x = eps_k*, NEWTON_STEPS steps (``horizon_loss_derivatives``): L' > 0
       moves b to x, L' < 0 moves a to x (L' = 0: stop); the step x - L'/L'' is taken if L'' > 0 and it lies
       strictly inside (a, b), else the bracket's midpoint; stop (before moving) once the step is below
       1e-12 (1 + |x|).
    3. epsilon = x if L(x) <= (1 + FLAT) L(eps_k*), else eps_k*. (Near the minimum L is flat to rounding over
       ~1e-8 px: comparing there with a strict "lower" would let rounding decide between two implementations;
       the Newton steps, decided by the derivatives, converge to the minimum itself.)
    eps = 0 is on the grid, so L(epsilon) <= (1 + FLAT) L(0).
    """
    delta = search_half_width(H, q)
    n, h = shifted_points(H, q)
    grid = [-delta + 2.0 * delta * k / GRID_INTERVALS for k in range(1, GRID_INTERVALS + 1)]
    losses = [horizon_loss(n, h, g, e) for e in grid]
    k = int(np.argmin(losses))
    a = grid[k - 1] if k > 0 else -delta
    b = grid[min(k + 1, GRID_INTERVALS - 1)]
    x = grid[k]
    for _ in range(NEWTON_STEPS):
        a, b, x, converged = newton_step(a, b, x, *horizon_loss_derivatives(n, h, g, x))
        if converged:
            break
    return (x if horizon_loss(n, h, g, x) <= (1.0 + FLAT) * losses[k] else grid[k]), delta


class HorizonCorrector(Corrector):
    """The horizon shift of Section 3 as a correction: one parameter, epsilon (pixels), fitted to the reference
    points; the corrected mapping is the homography H_eps = H . row_shift(epsilon), ``.m``: the mapping whose
    horizon lies epsilon pixels above H's (H's horizon row v_h(u) becomes v_h(u) - epsilon at every column).

    Model. The paper's model of a trapezoid error is a shifted horizon, v_h -> v_h + epsilon (eq. (9)), with K
    and Offset of eq. (7) unchanged: Y_hat(v) = Offset + K / (v - v_h - epsilon). The transform of the image
    that does exactly this at every column is the row shift v -> v + epsilon applied before H (the mapping of
    eq. (10) with the horizon moved back). A change of the camera's tilt would induce K R_x(dtheta) K^-1
    instead, which also shears the image laterally and moves the bottom row about 28 % more than the horizon
    on the paper's camera (f dtheta sec^2 of the row's angle from the axis); but it needs the intrinsics K
    (focal length, principal point), which a correction file does not have (only the two trapezoids; the image size is unknown too). So the literal row
    shift: it needs nothing beyond the trapezoid and is exact for the paper's model; for a true tilt error of
    +/-0.5-1 degree on the paper's camera it recovers the horizon shift within 6 % and leaves corrected points
    within 0.16 m out to 50 m, where the uncorrected ones are 4-14 m off
    (tests/correctors/test_correctors.py::TestHorizonCorrector). Because it is a homography, lateral points move
    consistently with the range correction, and a user gets a matrix (supervision style: ``.m``).

    Fit. epsilon minimises the sum of squared Euclidean calibration residuals, sum_i ||H_eps(q_i) - g_i||^2
    (``fit_horizon_shift``: a bracketing grid, then safeguarded Newton steps inside the bracket; deterministic).
    Squared residuals, not the mean Euclidean error of eq. (25): the loss is then smooth in epsilon (the norm
    has a kink wherever a residual vanishes), so the Newton steps on L' = 0 are well founded, and it is least
    squares as the regressions are. The search range is epsilon in (-delta, delta], delta =
    ``search_half_width`` (how far the reference point nearest the horizon lies below it, in pixels): the
    corrected horizon stays above every reference point, and the range scales with the image.

    A second parameter, a row scale about the horizon (v -> v_h + (1 + k)(v - v_h), which changes K of eq. (7)),
    measured on 300 random trapezoid errors of the paper's camera (python examples/compare_corrections.py):
    median path improvement 78.7 % -> 82.8 %, 1st percentile -1.7 % -> 1.2 %. It helps, but regression-intercept
    reaches 83.4 % and 3.4 % on the same samples with a closed form, so it is not built in.

    The corrected mapping is also a trapezoid: H_eps maps the clicked image trapezoid moved epsilon pixels UP
    (source - (0, epsilon)) onto the same map trapezoid, so ``transformer_`` is that ViewTransformer
    (ground_uncertainty and the CLI's error bars use it).

    Attributes after fit: horizon_shift_ (epsilon, pixels: the base mapping's horizon lies epsilon pixels
    below the corrected one, eq. (9)), search_half_width_ (delta), transformer_ (the corrected ViewTransformer),
    m (3, 3 corrected image-to-ground homography, as ViewTransformer.m), plus those of ``Corrector``.
    """

    method = "horizon"
    param_names = ()

    def _fit(self, q: np.ndarray, p: np.ndarray, g: np.ndarray) -> None:
        self.horizon_shift_, self.search_half_width_ = fit_horizon_shift(self.base_transformer_.m, q, g)
        self._set_transformer()

    def _set_transformer(self) -> None:
        base = self.base_transformer_
        self.transformer_ = ViewTransformer(base.source - [0.0, self.horizon_shift_], base.target)

    @property
    def m(self) -> np.ndarray:
        """(3, 3) corrected image-to-ground homography (unit Frobenius norm, w > 0 on the ground side)."""
        return self.transformer_.m

    def _transform(self, q: np.ndarray) -> np.ndarray:
        return self.transformer_.transform_points(q)

    def _fitted_state(self) -> dict:
        return {"horizon_shift": self.horizon_shift_, "search_half_width": self.search_half_width_}

    def _set_fitted_state(self, state: dict) -> None:
        """Check what fit could have produced: finite numbers, delta > 0, -delta < epsilon <= delta."""
        self.search_half_width_ = number(state["search_half_width"], "fitted.search_half_width")
        self.horizon_shift_ = number(state["horizon_shift"], "fitted.horizon_shift")
        if not self.search_half_width_ > 0:
            raise ValueError(f"field fitted.search_half_width: must be > 0, got {self.search_half_width_}")
        if not -self.search_half_width_ < self.horizon_shift_ <= self.search_half_width_:
            raise ValueError(f"field fitted.horizon_shift: {self.horizon_shift_} is outside the search range "
                             f"(-{self.search_half_width_}, {self.search_half_width_}] fit uses")
        try:
            self._set_transformer()
        except ValueError as e:
            raise ValueError(f"field fitted.horizon_shift: {e}") from None

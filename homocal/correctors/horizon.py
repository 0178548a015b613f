"""Beyond the paper: its own error model (Section 3) turned into a correction. A trapezoid error shifts the
horizon by epsilon (eq. (9)); fit that one number to the reference points and undo it, as a homography."""
from __future__ import annotations

import math

import numpy as np

from homocal.correctors.base import Corrector
from homocal.correctors.serialization import number
from homocal.geometry import ViewTransformer, apply_homography

GRID_INTERVALS = 64  # the bracketing grid: epsilon_k = -delta + 2 delta k / 64, k = 1..64
GOLDEN_ITERATIONS = 40  # shrink the bracket (about 4 px) by 0.618^40 (1e-8): to about 1e-7 px
NEWTON_STEPS = 3  # Gauss-Newton steps after the golden section, each kept unless it raises the loss
FLAT = 1e-12  # ... by more than this, relative: near the minimum the loss is flat to rounding
INV_PHI = (math.sqrt(5.0) - 1.0) / 2.0


def row_shift(eps: float) -> np.ndarray:
    """(3, 3) image homography (u, v) -> (u, v + eps), pixels."""
    return np.array([[1.0, 0.0, 0.0], [0.0, 1.0, eps], [0.0, 0.0, 1.0]])


def horizon_loss(H: np.ndarray, eps: float, q: np.ndarray, g: np.ndarray) -> float:
    """sum_i ||H_eps(q_i) - g_i||^2 over image points q (N, 2) px and ground points g (N, 2); +inf if a point
    maps on or beyond the horizon of H_eps."""
    r = apply_homography(H @ row_shift(eps), q) - g
    return math.inf if np.isnan(r).any() else float(np.sum(r * r))


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

    1. Bracket: L(eps) = horizon_loss(H, eps, q, g) at eps_k = -delta + 2 delta k / GRID_INTERVALS,
       k = 1..GRID_INTERVALS (eps = 0 among them); k* = the first smallest; bracket [eps_{k*-1}, eps_{min(k*+1, 64)}].
    2. Golden section: GOLDEN_ITERATIONS iterations on the bracket (c = b - (b - a) / phi, d = a + (b - a) / phi;
       if L(c) < L(d) keep [a, d], else [c, b]); its point of lower loss (c on ties) replaces eps_k* if lower.
    3. Gauss-Newton: NEWTON_STEPS steps eps -= sum r.J / sum J.J with residuals r_i = H_eps(q_i) - g_i and
       J_i = dr_i/deps = (h_xy w_i - n_i h_w) / w_i^2 ((n_i, w_i) = H_eps (q_i, 1), h = H[:, 1]), each kept if
       it stays in (-delta, delta] and L(step) <= (1 + FLAT) L. (Near the minimum L is flat to rounding over
       ~1e-8 px, where the golden section's last comparisons are decided by rounding; a strict "lower" would
       let rounding decide the steps too, so two implementations would end 1e-8 px apart. The steps, decided by
       the derivative, converge to the minimum itself.)
    eps = 0 is on the grid and every step keeps the least loss (up to FLAT per Gauss-Newton step), so
    L(epsilon) <= (1 + 3e-12) L(0).
    """
    delta = search_half_width(H, q)

    def loss(eps: float) -> float:
        return horizon_loss(H, eps, q, g)

    grid = [-delta + 2.0 * delta * k / GRID_INTERVALS for k in range(1, GRID_INTERVALS + 1)]
    losses = [loss(e) for e in grid]
    k = int(np.argmin(losses))
    eps, best = grid[k], losses[k]
    a = grid[k - 1] if k > 0 else -delta
    b = grid[min(k + 1, GRID_INTERVALS - 1)]
    c, d = b - INV_PHI * (b - a), a + INV_PHI * (b - a)
    fc, fd = loss(c), loss(d)
    for _ in range(GOLDEN_ITERATIONS):
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - INV_PHI * (b - a)
            fc = loss(c)
        else:
            a, c, fc = c, d, fd
            d = a + INV_PHI * (b - a)
            fd = loss(d)
    golden, f_golden = (c, fc) if fc <= fd else (d, fd)
    if f_golden < best:
        eps, best = golden, f_golden
    h = H[:, 1]
    for _ in range(NEWTON_STEPS):
        n = np.column_stack([q, np.ones(len(q))]) @ (H @ row_shift(eps)).T  # (N, 3): x, y, w
        w = n[:, 2:3]
        r = n[:, :2] / w - g
        J = (h[:2] * w - n[:, :2] * h[2]) / w**2
        jj = float(np.sum(J * J))
        if not jj > 0:
            break
        cand = eps - float(np.sum(r * J)) / jj
        f_cand = loss(cand) if -delta < cand <= delta else math.inf
        if f_cand <= (1.0 + FLAT) * best:
            eps, best = cand, f_cand
    return eps, delta


class HorizonCorrector(Corrector):
    """The horizon shift of Section 3 as a correction: one parameter, epsilon (pixels), fitted to the reference
    points; the corrected mapping is the homography H_eps = H . row_shift(epsilon), ``.m``: the mapping whose
    horizon lies epsilon pixels above H's (H's horizon row v_h(u) becomes v_h(u) - epsilon at every column).

    Model. The paper's model of a trapezoid error is a shifted horizon, v_h -> v_h + epsilon (eq. (9)), with K
    and Offset of eq. (7) unchanged: Y_hat(v) = Offset + K / (v - v_h - epsilon). The transform of the image
    that does exactly this at every column is the row shift v -> v + epsilon applied before H (the mapping of
    eq. (10) with the horizon moved back). A change of the camera's tilt would induce K R_x(dtheta) K^-1
    instead, which also shears the image laterally and shifts rows by 7-40 % more at the bottom than at the
    horizon on the paper's camera; but it needs the intrinsics K (focal length, principal point), which a
    correction file does not have (only the two trapezoids; the image size is unknown too). So the literal row
    shift: it needs nothing beyond the trapezoid and is exact for the paper's model; for a true tilt error of
    +/-0.5-1 degree on the paper's camera it recovers the horizon shift within 6 % and leaves corrected points
    within 0.16 m out to 50 m, where the uncorrected ones are 4-14 m off
    (tests/homocal/test_correctors.py::TestHorizonCorrector). Because it is a homography, lateral points move
    consistently with the range correction, and a user gets a matrix (supervision style: ``.m``).

    Fit. epsilon minimises the sum of squared Euclidean calibration residuals, sum_i ||H_eps(q_i) - g_i||^2
    (``fit_horizon_shift``: a bracketing grid, golden section, Gauss-Newton; deterministic). Squared residuals,
    not the mean Euclidean error of eq. (25): the loss is then smooth in epsilon (the norm has a kink wherever a
    residual vanishes), so the golden section's bracket and the Gauss-Newton steps are well founded, and it is
    least squares as the regressions are. The search range is epsilon in (-delta, delta], delta =
    ``search_half_width`` (how far the reference point nearest the horizon lies below it, in pixels): the
    corrected horizon stays above every reference point, and the range scales with the image.

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

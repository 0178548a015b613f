"""Beyond the paper: the "least change" trapezoid correction. The clicked image trapezoid (px) and map
trapezoid (m) carry clicking errors; among the corrections that explain the reference points, take the
smallest: the MAP estimate under a Gaussian prior on the click errors (issue 10)."""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from homocal.correctors.base import Corrector
from homocal.correctors.serialization import integer, number
from homocal.geometry import ViewTransformer, apply_homography, homography_from_quads, signed_area, validate_quad
from homocal.geometry.homography import _basis_map

MAX_HALVINGS = 4  # safeguard: the step is tried at 1, 1/2, ..., 1/16 of its length, then the iterate is kept
OBJECTIVE_TOLERANCE = 1e-10  # stop once an accepted step lowers Phi by no more than this fraction of it (rounding: ~1e-15)


def predicted_points(source: np.ndarray, target: np.ndarray, q: np.ndarray, base: tuple[np.ndarray, np.ndarray]):
    """f = H(source, target)(q) (N, 2), target units, for image points q (N, 2) px; None if the quads are not
    usable: validate_quad refuses one, either goes round the other way from the base quads ``base``
    (source, target), the homography cannot be formed, or a point q_i is on or beyond its horizon (NaN)."""
    try:
        for quad, ref, name in ((source, base[0], "source"), (target, base[1], "target")):
            validate_quad(quad, name)
            if signed_area(quad) * signed_area(ref) <= 0:
                return None
        f = apply_homography(homography_from_quads(source, target), q)
    except ValueError:
        return None
    return None if np.isnan(f).any() else f


def basis_map_derivatives(quad: np.ndarray) -> np.ndarray:
    """(8, 3, 3) derivatives of B = _basis_map(quad) = P diag(lambda), P = [v1 v2 v3] (homogeneous vertices as
    columns), P lambda = v4, with respect to the quad's coordinates c = 2 j + k (vertex j, x/y k):
    j < 3: dP = e_k e_j^T, dlambda = -P^-1 dP lambda = -P^-1[:, k] lambda_j, dB = dP diag(lambda) + P diag(dlambda);
    j = 3: dP = 0, dlambda = P^-1 e_k, dB = P diag(dlambda)."""
    P = np.vstack([quad[:3].T, np.ones(3)])
    lam = np.linalg.solve(P, np.array([quad[3, 0], quad[3, 1], 1.0]))
    P_inv = np.linalg.inv(P)
    dB = np.zeros((8, 3, 3))
    for j in range(4):
        for k in range(2):
            if j < 3:
                dB[2 * j + k, k, j] = lam[j]
                dB[2 * j + k] += P * (-P_inv[:, k] * lam[j])
            else:
                dB[2 * j + k] = P * P_inv[:, k]
    return dB


def mapped_jacobian(source: np.ndarray, target: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(N, 2, 16) analytic derivative of f = H(source, target)(q) (N, 2) with respect to the 8 source (image)
    then 8 target (map) coordinates. H = B_t B_s^-1 (homography_from_quads before its scaling, which f ignores):
    dH = dB_t B_s^-1 for a target coordinate, -H dB_s B_s^-1 for a source one; with X = H (q, 1) and
    dX = dH (q, 1): df = (dX_xy - f dX_w) / X_w."""
    Bs_inv = np.linalg.inv(_basis_map(source))
    H = _basis_map(target) @ Bs_inv
    dH = np.concatenate([-H @ basis_map_derivatives(source) @ Bs_inv, basis_map_derivatives(target) @ Bs_inv])
    qh = np.column_stack([q, np.ones(len(q))])
    X = qh @ H.T
    f = X[:, :2] / X[:, 2:]
    dX = np.einsum("kij,nj->nik", dH, qh)  # (N, 3, 16)
    return (dX[:, :2] - f[:, :, None] * dX[:, 2:3]) / X[:, 2, None, None]


def objective(x: np.ndarray, f: np.ndarray, g: np.ndarray, point_sigma: float) -> float:
    """Phi(x) = ||x||^2 + ||g - f||^2 / point_sigma^2: x (16,) normalised corner offsets, f and g (N, 2)."""
    return float(x @ x + np.sum((g - f) ** 2) / point_sigma**2)


def gauss_newton_step(x: np.ndarray, J: np.ndarray, r: np.ndarray, point_sigma: float) -> np.ndarray:
    """The minimiser of Phi linearised at x: the least-squares solution x' of [J / s; I] x' = [b / s; 0].

    x (16,) normalised offsets; J (2N, 16) the Jacobian of f in normalised units; r = g - f(x) (2N,); s =
    point_sigma. With f(x') ~ f(x) + J (x' - x) =: g - b + J x', b = r + J x, Phi ~ ||x'||^2 + ||b - J x'||^2 / s^2
    is that stacked system's squared residual, minimal at x' = (J^T J + s^2 I)^-1 J^T b. Solved by orthogonal
    factorisation of the (2N + 16, 16) stacked matrix (not the normal equations, whose condition is squared:
    with s small against the click sigmas J^T J + s^2 I is nearly singular), so memory and time grow linearly
    with the point count N."""
    n = J.shape[1]
    stacked = np.vstack([J / point_sigma, np.eye(n)])
    return np.linalg.lstsq(stacked, np.concatenate([(r + J @ x) / point_sigma, np.zeros(n)]), rcond=None)[0]


def safeguarded_step(x: np.ndarray, step: np.ndarray, phi: float,
                     evaluate: Callable[[np.ndarray], float | None]) -> tuple[np.ndarray, float] | None:
    """The first of x + step / 2^h, h = 0..MAX_HALVINGS, whose evaluate(.) (Phi, or None for unusable quads)
    is not None and <= phi: (that x, its Phi); None if there is none (the caller keeps x and stops)."""
    for h in range(MAX_HALVINGS + 1):
        candidate = x + step / 2.0**h
        value = evaluate(candidate)
        if value is not None and value <= phi:
            return candidate, value
    return None


class LeastChangeCorrector(Corrector):
    """The smallest change of the clicked corners that explains the reference points (MAP estimate).

    Model. The 16 clicked corner coordinates z0 = (image trapezoid (8,) px, map trapezoid (8,) metres, order
    TL, TR, BR, BL as (x, y)) are the true ones plus independent Gaussian click errors of standard deviation
    click_sigma_px (image) and map_sigma_m (map); each reference ground point g_i (2,) m is measured with
    Gaussian noise of standard deviation point_sigma_m per coordinate. With sigma (16,) the prior sigmas and
    x (16,) the corrections in units of them (z = z0 + sigma * x), the posterior mode minimises

        Phi(x) = ||x||^2 + sum_i ||g_i - f_i(x)||^2 / point_sigma_m^2,   f_i(x) = H(z0 + sigma * x)(q_i),

    H(z) the 4-point homography of the two trapezoids (``homography_from_quads``). This generalises the loss of
    the paper's method 2 (Section 4.2, eq. (25), the mean Euclidean calibration error eq. (18) over the image
    trapezoid's 8 coordinates): the residuals are squared (the Gaussian likelihood), the map trapezoid may move
    too (the study perturbs both, Section 5.2), and the prior term ||x||^2 decides where the coordinates go that
    the reference points leave free (three points on one line fix 6 of 16 numbers), which descent leaves to its
    search order. map_sigma_m = 0 moves the image trapezoid only, like descent.

    Fit. Gauss-Newton from x = 0 (``gauss_newton_step``): x <- (J^T J + point_sigma_m^2 I)^-1 J^T (g - f + J x),
    a 16-unknown least-squares solve whose memory grows linearly with the point count,
    J (2N, 16) = df/dx = (df/dz) diag(sigma), df/dz analytic through the projective basis (``mapped_jacobian``;
    tested against central differences of the closed-form homography).
    Stopping rule: at most ``iterations`` steps; a step is taken only if it lowers Phi by more than
    OBJECTIVE_TOLERANCE = 1e-10 of it, else the fit stops where it is. Rounding changes Phi by ~1e-15 of it, so
    which steps are taken (and their count) is not decided by rounding; Gauss-Newton converges linearly here
    (rate ~0.05 on the study's triples), and the fit ends ~1e-6 prior sigmas from the optimum.
    Safeguard (``safeguarded_step``): a step is tried at full length, then halved up to MAX_HALVINGS = 4 times,
    until the iterate's quads are usable (``predicted_points``: both pass validate_quad and keep their
    orientation, every reference point maps in front of the horizon) and Phi does not increase; if none is,
    the previous iterate is kept and the fit stops. So Phi never ends above Phi(0) and the corrected quads are
    always valid; with point_sigma_m small against the click sigmas the reference points are fitted
    (almost) exactly.

    Units. The map sigma is in the transformer's target units: metres for ``homocal fit``'s files (a map
    clicked in site-map pixels: divide its clicking error by scale_px_per_m).

    Defaults. Only the ratios of the three sigmas change the result (scaling all of them scales Phi). Of the
    eight priors tried on both study scenes, hand-placed and with a 6 px horizon shift (research/compare_least_change.py
    --sweep; docs/camera.md), 1 px / 0.2 m / 0.05 m had the best sum of median and 1st
    percentile path improvement over the four settings.

    Args:
        click_sigma_px: prior sigma of each image corner coordinate, pixels (> 0).
        map_sigma_m: prior sigma of each map corner coordinate, metres (>= 0; 0: the map trapezoid stays).
        point_sigma_m: sigma of each reference point coordinate, metres (> 0).
        iterations: most Gauss-Newton steps (integer >= 1).
    Attributes after fit: transformer_ (the corrected ViewTransformer: corrected image quad px, map quad m),
    m (its 3x3 homography), iterations_ (steps accepted), objective_initial_ = Phi(0), objective_final_,
    plus those of ``Corrector``.
    """

    method = "least-change"
    param_names = ("click_sigma_px", "map_sigma_m", "point_sigma_m", "iterations")

    def __init__(self, click_sigma_px: float = 1.0, map_sigma_m: float = 0.2, point_sigma_m: float = 0.05,
                 iterations: int = 10) -> None:
        for name, value, low in (("click_sigma_px", click_sigma_px, "> 0"), ("map_sigma_m", map_sigma_m, ">= 0"),
                                 ("point_sigma_m", point_sigma_m, "> 0")):
            ok = (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
                  and (value > 0 if low == "> 0" else value >= 0))
            if not ok:
                raise ValueError(f"{name} must be a finite number {low}, got {value!r}")
        if isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 1:
            raise ValueError(f"iterations must be an integer >= 1, got {iterations!r}")
        self.click_sigma_px = float(click_sigma_px)
        self.map_sigma_m = float(map_sigma_m)
        self.point_sigma_m = float(point_sigma_m)
        self.iterations = iterations

    def _fit(self, q: np.ndarray, p: np.ndarray, g: np.ndarray) -> None:
        base = (self.base_transformer_.source, self.base_transformer_.target)
        sigma = np.repeat([self.click_sigma_px, self.map_sigma_m], 8)
        z0 = np.concatenate([base[0].ravel(), base[1].ravel()])

        def quads(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            z = z0 + sigma * x
            return z[:8].reshape(4, 2), z[8:].reshape(4, 2)

        def evaluate(x: np.ndarray) -> float | None:
            f = predicted_points(*quads(x), q, base)
            return None if f is None else objective(x, f, g, self.point_sigma_m)

        x = np.zeros(16)
        phi = self.objective_initial_ = objective(x, p, g, self.point_sigma_m)
        self.iterations_ = 0
        for _ in range(self.iterations):
            source, target = quads(x)
            J = mapped_jacobian(source, target, q).reshape(-1, 16) * sigma
            r = (g - apply_homography(homography_from_quads(source, target), q)).ravel()
            accepted = safeguarded_step(x, gauss_newton_step(x, J, r, self.point_sigma_m) - x, phi, evaluate)
            if accepted is None or phi - accepted[1] <= OBJECTIVE_TOLERANCE * phi:
                break
            x, phi = accepted
            self.iterations_ += 1
        self.objective_final_ = phi
        self.transformer_ = ViewTransformer(*quads(x))

    @property
    def m(self) -> np.ndarray:
        """(3, 3) corrected image-to-ground homography (unit Frobenius norm, w > 0 on the ground side)."""
        return self.transformer_.m

    def corner_moves(self) -> tuple[float, float]:
        """(largest image corner move, px; largest map corner move, target units): Euclidean, over the 4 corners."""
        base, fitted = self.base_transformer_, self.transformer_
        return (float(np.linalg.norm(fitted.source - base.source, axis=1).max()),
                float(np.linalg.norm(fitted.target - base.target, axis=1).max()))

    def _transform(self, q: np.ndarray) -> np.ndarray:
        return self.transformer_.transform_points(q)

    def _fitted_state(self) -> dict:
        return {
            "source": self.transformer_.source.tolist(),
            "target": self.transformer_.target.tolist(),
            "iterations": self.iterations_,
            "objective_initial": self.objective_initial_,
            "objective_final": self.objective_final_,
        }

    def _set_fitted_state(self, state: dict) -> None:
        """Check what fit could have produced: valid quads of the base quads' orientation, the map quad unmoved if
        map_sigma_m = 0, 0 <= iterations <= the parameter, finite 0 <= objective_final <= objective_initial."""
        try:
            self.transformer_ = ViewTransformer(state["source"], state["target"])
        except (TypeError, ValueError) as e:
            raise ValueError(f"field fitted.source/target: {e}") from None
        base = self.base_transformer_
        for name, quad, ref in (("source", self.transformer_.source, base.source),
                                ("target", self.transformer_.target, base.target)):
            if signed_area(quad) * signed_area(ref) <= 0:
                raise ValueError(f"field fitted.{name}: goes round the other way from the clicked trapezoid")
        if self.map_sigma_m == 0 and not np.array_equal(self.transformer_.target, base.target):
            raise ValueError("field fitted.target: differs from the clicked map trapezoid, but map_sigma_m = 0")
        self.iterations_ = integer(state["iterations"], "fitted.iterations", 0, self.iterations)
        self.objective_initial_ = number(state["objective_initial"], "fitted.objective_initial", minimum=0)
        self.objective_final_ = number(state["objective_final"], "fitted.objective_final", minimum=0)
        if self.objective_final_ > self.objective_initial_:
            raise ValueError(f"field fitted.objective_final: {self.objective_final_} is above objective_initial "
                             f"{self.objective_initial_} (the fit never ends above its start)")

"""Method 2 of the paper (Section 4.2, eq. (25)): optimise the image trapezoid's 8 coordinates so the
calibration points map onto their true positions; a coarse grid, then seeded coordinate descent."""
from __future__ import annotations

import itertools
import math

import numpy as np

from homocal.correctors.base import Corrector, mean_error
from homocal.correctors.serialization import integer, number
from homocal.geometry import ViewTransformer, apply_homography, homography_from_quads, validate_quad

REACH_TOLERANCE = 1e-9  # px: far above the rounding of a coordinate's offset (~1e-13 px), far below any step


def within_reach(offset: float, delta_max: float) -> bool:
    """Descent's reach rule: a coordinate may sit at offset (px) from the clicked trapezoid's iff |offset| <= delta_max
    + REACH_TOLERANCE, so that a move exactly to delta_max is allowed whatever the rounding of the offset (the
    readable corrector and the study's kernel share this function)."""
    return abs(offset) <= delta_max + REACH_TOLERANCE


def calibration_loss(v: np.ndarray, target: np.ndarray, image_points: np.ndarray, ground_points: np.ndarray) -> float:
    """Eq. (25): L(v) = mean_i ||H_v(q_i) - g_i||, H_v = homography_from_quads(v.reshape(4, 2), target).

    Args: v (8,) image trapezoid (TL.u, TL.v, TR.u, TR.v, BR.u, BR.v, BL.u, BL.v), pixels; target (4, 2);
    image_points q (N, 2) px; ground_points g (N, 2), target units. +inf if v fails validate_quad, the
    homography cannot be formed, or a calibration point maps beyond the horizon (NaN).
    """
    try:
        H = homography_from_quads(validate_quad(v.reshape(4, 2), "trapezoid"), target)
    except ValueError:
        return math.inf
    mapped = apply_homography(H, image_points)
    if np.isnan(mapped).any():
        return math.inf
    return mean_error(mapped, ground_points)


class DescentCorrector(Corrector):
    """Method 2, trapezoid coordinate optimisation (paper eq. (25) and Section 4.2).

    The variables v (8,) are the IMAGE trapezoid's coordinates, v0 = transformer.source.ravel(); the target
    (ground/map) trapezoid stays fixed. The loss is ``calibration_loss`` (eq. (25)).

    Phase 1 (coarse): the candidates v0 + offsets on coordinates 0, 1 (TL) and 4, 5 (BR), the offsets
      (dTL.u, dTL.v, dBR.u, dBR.v) in itertools.product(grid_offsets, repeat=4) order (625 with the
      defaults, the identity among them); v = the first candidate of smallest loss (np.argmin). Not counted
      in max_evals.
    Phase 2 (fine): L = L(v), step = initial_step, pass_index = 0, evals = 0. Each pass visits the 8
      coordinates k in the order shuffled_order(seed, pass_index) (keyed splitmix64, shared with the
      compiled kernels); for sign in (+1, -1): cand = v with cand[k] += sign step; skipped without
      evaluation unless within_reach(cand[k] - v0[k], delta_max); the whole search stops when evals == max_evals before an
      evaluation; if L(cand) < L it is accepted (and the other sign not tried). After a pass: pass_index
      += 1; if nothing improved, step /= 2, and the search stops once step < min_step. (A pass without
      improvement has tried every allowed move from an unchanged v, so another pass at the same step
      would find nothing either: halving after one such pass is the paper's "no improvement in
      consecutive passes".)
    The identity is a phase-1 candidate and phase 2 only accepts decreases, so the calibration loss never
    ends above its start: calibration_improvement_ >= 0 by construction. It does not follow for other
    points: calibration objects on one line (x = 0) leave the mapping off that line free (Section 6).

    Why these defaults (the paper gives none): the study perturbs 0-3 px per coordinate on top of a hand
    placement residual of about 1-2 px, so delta_max = 8 px covers the worst case with margin while keeping
    the quad far from degenerate; the 5 x 5 grid of 2 px steps on two opposing corners spans +/-4 px, where
    the worst perturbations lie; phase 2 refines from 1 px down to 1/16 px (5 step levels), well below
    detection noise; max_evals = 400 bounds the cost (a few hundred sequential evaluations are typical).

    Args:
        delta_max: largest displacement of any coordinate from v0, pixels (every |grid offset| must be <= it).
        grid_offsets: phase-1 offsets, pixels; must include 0.
        initial_step, min_step: phase-2 step range, pixels.
        max_evals: phase-2 loss evaluation budget.
        seed: uint64 key of the coordinate order.
    Attributes after fit: transformer_ (the ViewTransformer of the optimised trapezoid), loss_initial_
    (= error_before_), loss_final_ (= error_after_), evaluations_ (phase 2), plus those of ``Corrector``.
    """

    method = "descent"
    param_names = ("delta_max", "grid_offsets", "initial_step", "min_step", "max_evals", "seed")

    def __init__(
        self,
        delta_max: float = 8.0,
        grid_offsets: tuple[float, ...] = (-4.0, -2.0, 0.0, 2.0, 4.0),
        initial_step: float = 1.0,
        min_step: float = 0.0625,
        max_evals: int = 400,
        seed: int = 0,
    ) -> None:
        self.delta_max = float(delta_max)
        self.grid_offsets = tuple(float(x) for x in grid_offsets)
        self.initial_step = float(initial_step)
        self.min_step = float(min_step)
        self.max_evals = int(max_evals)
        self.seed = int(seed)
        if not self.delta_max > 0:
            raise ValueError(f"delta_max must be > 0, got {delta_max}")
        if 0.0 not in self.grid_offsets or any(not abs(x) <= self.delta_max for x in self.grid_offsets):
            raise ValueError(
                f"grid_offsets must include 0 (so the initial trapezoid is a candidate and the loss never ends above"
                f" its start) and lie within +/-delta_max={self.delta_max}: got {grid_offsets}"
            )
        if not 0 < self.min_step <= self.initial_step:
            raise ValueError(f"need 0 < min_step <= initial_step, got {min_step} and {initial_step}")
        if self.max_evals < 0 or self.max_evals != max_evals:
            raise ValueError(f"max_evals must be a non-negative integer, got {max_evals}")
        if not 0 <= self.seed < 2**64 or self.seed != seed:
            raise ValueError(f"seed must be an integer in [0, 2**64), got {seed}")

    def _fit(self, q: np.ndarray, p: np.ndarray, g: np.ndarray) -> None:
        target = self.base_transformer_.target
        v0 = self.base_transformer_.source.ravel()

        def loss(v: np.ndarray) -> float:
            return calibration_loss(v, target, q, g)

        self.loss_initial_ = loss(v0)
        v, self.loss_final_, self.evaluations_ = self._coordinate_descent(v0, self._coarse_grid(v0, loss), loss)
        self.transformer_ = ViewTransformer(v.reshape(4, 2), target)

    def _coarse_grid(self, v0: np.ndarray, loss) -> np.ndarray:
        """Phase 1: the first best of the grid over the opposing corners TL (coordinates 0, 1) and BR (4, 5)."""
        candidates = np.repeat(v0[None, :], len(self.grid_offsets) ** 4, axis=0)
        candidates[:, [0, 1, 4, 5]] += np.array(list(itertools.product(self.grid_offsets, repeat=4)))
        return candidates[int(np.argmin([loss(c) for c in candidates]))]

    def _coordinate_descent(self, v0: np.ndarray, v: np.ndarray, loss) -> tuple[np.ndarray, float, int]:
        """Phase 2 from v; returns (v, L(v), evaluations)."""
        from homocal.keyed_rng import shuffled_order  # compiled: numba loads here, not with ``import homocal``

        L, step, pass_index, evals = loss(v), self.initial_step, 0, 0
        order = np.empty(8, dtype=np.int64)
        while True:
            shuffled_order(np.uint64(self.seed), pass_index, order)
            improved = False
            for k in order:
                for sign in (1.0, -1.0):
                    cand = v.copy()
                    cand[k] += sign * step
                    if not within_reach(cand[k] - v0[k], self.delta_max):
                        continue
                    if evals == self.max_evals:
                        return v, L, evals
                    Lc = loss(cand)
                    evals += 1
                    if Lc < L:
                        v, L, improved = cand, Lc, True
                        break
            pass_index += 1
            if not improved:
                step /= 2
                if step < self.min_step:
                    return v, L, evals

    def _transform(self, q: np.ndarray) -> np.ndarray:
        return self.transformer_.transform_points(q)

    def _fitted_state(self) -> dict:
        return {
            "source": self.transformer_.source.tolist(),
            "loss_initial": self.loss_initial_,
            "loss_final": self.loss_final_,
            "evaluations": self.evaluations_,
        }

    def _set_fitted_state(self, state: dict) -> None:
        """Check what fit could have produced: a valid quad within delta_max of the clicked one, finite losses
        0 <= loss_final <= loss_initial, 0 <= evaluations <= max_evals."""
        try:
            self.transformer_ = ViewTransformer(state["source"], self.base_transformer_.target)
        except (TypeError, ValueError) as e:
            raise ValueError(f"field fitted.source: {e}") from None
        moved = float(np.abs(self.transformer_.source - self.base_transformer_.source).max())
        if not within_reach(moved, self.delta_max):
            raise ValueError(f"field fitted.source: a corner moved {moved:g} px from the clicked trapezoid, more than "
                             f"delta_max = {self.delta_max:g}")
        self.loss_initial_ = number(state["loss_initial"], "fitted.loss_initial", minimum=0)
        self.loss_final_ = number(state["loss_final"], "fitted.loss_final", minimum=0)
        if self.loss_final_ > self.loss_initial_:
            raise ValueError(f"field fitted.loss_final: {self.loss_final_} is above loss_initial {self.loss_initial_} "
                             "(descent never ends above its start)")
        self.evaluations_ = integer(state["evaluations"], "fitted.evaluations", 0, self.max_evals)

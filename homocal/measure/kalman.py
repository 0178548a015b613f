"""A constant-velocity Kalman filter on the ground plane and its Rauch-Tung-Striebel smoother, batched over
tracks (each track one row of (n, L) arrays, padded at its end).

State s = (x, y, vx, vy) (metres, metres per second). Between two frames dt seconds apart the velocity takes a
white-noise acceleration of spectral density q (m^2/s^3, ACCEL_PSD: the standard continuous white-noise
acceleration model, Bar-Shalom, Li and Kirubarajan 2001, Section 6.2.2):
    s' = F s + w,  F = [[I, dt I], [0, I]],  Q = q [[dt^3/3 I, dt^2/2 I], [dt^2/2 I, dt I]].
A measurement z (2,) = (x, y) with covariance R (2, 2): the mapping's own per-point covariance
(``Corrector.ground_uncertainty``), so a far point, whose R is large, counts less. A measurement that is NaN
(a foot point on or above the horizon) is skipped: the step only predicts.

A foot point's error correlated over frames (``foot``): the state takes its ground displacement b = (bx, by)
(metres) as two more components, an AR(1) (a first-order Gauss-Markov process) of correlation time tau seconds
and stationary covariance R_b (2, 2), the foot point's own noise through the mapping:
    b' = phi b + w_b,  phi = exp(-dt / tau),  Q_b = (1 - phi^2) R_b,  z = (x, y) + b + white noise (R),
so s = (x, y, vx, vy, bx, by), F and Q block-diagonal (the motion's, the error's), H = [I, 0, I] (Gelb 1974,
Section 4.5: state augmentation for coloured measurement noise).

A heavy-tailed white measurement noise (``dof`` finite): a Student-t of scale R and dof degrees of freedom, a
normal N(0, R / w) whose precision weight w is Gamma(dof / 2, dof / 2) distributed, so that a jump (a nearer
person hides the feet, a box merges or splits) counts little. Each update is the variational Bayes one
(Agamennoni, Nieto and Nebot 2012; Roth, Ozkan and Gustafsson 2013, Section III): the Kalman update with R / w,
    w = (dof + 2) / (dof + tr(R^-1 E[(z - H s)(z - H s)^T])),
the expectation over the updated state (``student_update``); the smoother takes the filtered covariances as the
forward pass weighted them. dof = inf is the normal noise, the Kalman update itself.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import minimize, minimize_scalar
from scipy.special import ndtr

ACCEL_PSD = 0.5
"""q, m^2/s^3: a walker's velocity wanders by sqrt(q T) m/s in T seconds (0.7 m/s in one second, enough for a
person who stops or starts within about two seconds). Chosen from that, not fitted to a benchmark."""
ACCEL_PSD_BOUNDS = (1e-4, 10.0)
"""The range of q, m^2/s^3, that ``fit_accel_psd`` searches: a velocity that wanders by 1 cm/s to 3 m/s in one
second (a walker at constant velocity to a sprinter's turns)."""
ACCEL_PSD_LOG_TOLERANCE = 0.01
"""``fit_accel_psd``'s tolerance on ln q (1 %: far below the estimate's own spread on a few tracks)."""
START_POSITION_SIGMA_M = 100.0
"""A track's first state: position unknown (this sigma, far beyond any error bar; the first measurement sets it)."""
START_SPEED_SIGMA_MPS = 10.0
"""... and velocity 0 with this sigma per axis: all but unknown (a sprinter's 10 m/s is one sigma), so that the
start does not pull a track's first speeds towards 0 (a 2 m/s sigma pulled a walker's first speed 3 % low)."""


def transition(dt: np.ndarray, q: float, foot: tuple[np.ndarray, float] | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
    """F (n, d, d) and Q (n, d, d) of the module docstring for time steps dt (n,) seconds; d = 4, or 6 with
    foot = (R_b (n, 2, 2) metres^2, tau seconds): the correlated foot-point error's block (a NaN R_b: none)."""
    n = len(dt)
    d = 4 if foot is None else 6
    F = np.broadcast_to(np.eye(d), (n, d, d)).copy()
    F[:, 0, 2] = F[:, 1, 3] = dt
    Q = np.zeros((n, d, d))
    for i in range(2):
        Q[:, i, i] = q * dt**3 / 3
        Q[:, i, i + 2] = Q[:, i + 2, i] = q * dt**2 / 2
        Q[:, i + 2, i + 2] = q * dt
    if foot is not None:
        R_b, tau = foot
        phi = np.exp(-dt / tau)
        F[:, 4:, 4:] *= phi[:, None, None]
        Q[:, 4:, 4:] = (1 - phi**2)[:, None, None] * np.nan_to_num(R_b)
    return F, Q


def correlated_noise(R: np.ndarray, tau: float | None) -> tuple[np.ndarray, tuple[np.ndarray, float] | None]:
    """``kalman_filter``'s (R, foot) for a measurement noise R (..., 2, 2) metres^2: white (R, None) when tau is
    None; else all of it correlated with correlation time tau seconds, (0, (R, tau)): no white part (NaN where R
    is NaN: no measurement there)."""
    if tau is None:
        return R, None
    return np.where(np.isfinite(R), 0.0, np.nan), (R, tau)


def measurement_matrix(d: int) -> np.ndarray:
    """H (2, d): the measured foot point's ground position, the state's (x, y) (d = 4) plus its error b (d = 6)."""
    H = np.eye(2, d)
    if d == 6:
        H[:, 4:] = np.eye(2)
    return H


def kalman_filter(t: np.ndarray, z: np.ndarray, R: np.ndarray, q: float = ACCEL_PSD,
                  foot: tuple[np.ndarray, float] | None = None, dof: float = np.inf) -> dict[str, np.ndarray]:
    """Forward pass over tracks: t (n, L) seconds, non-decreasing along each row (a padded step repeats the last
    time and has NaN z), z (n, L, 2) metres, R (n, L, 2, 2) metres^2 (the white part of the measurement
    error); foot None, or (R_b (n, L, 2, 2) metres^2, tau seconds): the part correlated over frames (module
    docstring), d = 6 states; dof: the white part's degrees of freedom (inf: normal; else Student-t of scale R,
    ``update``).

    Returns "x", "P" (the filtered states (n, L, d) and covariances (n, L, d, d)), "x_pred", "P_pred" (the
    predictions before each update) and "F" (n, L, d, d), the transitions into each step (identity at step 0).
    """
    n, L = t.shape
    x, P = start_state(n, None if foot is None else foot[0][:, 0])
    d = x.shape[1]
    out = {k: np.empty((n, L, d)) for k in ("x", "x_pred")} | {k: np.empty((n, L, d, d)) for k in ("P", "P_pred", "F")}
    for k in range(L):
        x, P, F = predict(x, P, t[:, k] - t[:, k - 1] if k else np.zeros(n), q,
                          None if foot is None else (foot[0][:, k], foot[1]))
        out["x_pred"][:, k], out["P_pred"][:, k], out["F"][:, k] = x, P, F
        x, P = update(x, P, z[:, k], R[:, k], dof)
        out["x"][:, k], out["P"][:, k] = x, P
    return out


def innovation_log_likelihood(t: np.ndarray, z: np.ndarray, R: np.ndarray, q: float,
                              foot: tuple[np.ndarray, float] | None = None, dof: float = np.inf) -> float:
    """The prediction-error log-likelihood of tracks under process noise q (arguments as ``kalman_filter``'s):
    the sum over measured steps of ``innovation_log_density`` of nu = z - H x_pred, the innovation, and S = H
    P_pred H^T + R, its covariance (normal: -(ln det S + nu^T S^-1 nu) / 2, the constant 2 pi dropped;
    Bar-Shalom, Li and Kirubarajan 2001, Section 5.2.5; Harvey 1989, Section 3.4)."""
    f = kalman_filter(t, z, R, q, foot, dof)
    H = measurement_matrix(f["x"].shape[-1])
    ok = np.isfinite(z).all(axis=-1) & np.isfinite(R).all(axis=(-2, -1))
    nu = z[ok] - f["x_pred"][ok] @ H.T
    S = H @ f["P_pred"][ok] @ H.T + R[ok]
    return float(innovation_log_density(nu, S, dof).sum())


def fit_accel_psd(t: np.ndarray, z: np.ndarray, R: np.ndarray, foot: tuple[np.ndarray, float] | None = None,
                  dof: float = np.inf) -> float:
    """The maximum-likelihood q, m^2/s^3, of tracks (arguments as ``kalman_filter``'s): the maximum of
    ``innovation_log_likelihood`` over ln q in ln ACCEL_PSD_BOUNDS (Brent's bounded search, to
    ACCEL_PSD_LOG_TOLERANCE)."""
    best = minimize_scalar(lambda s: -innovation_log_likelihood(t, z, R, float(np.exp(s)), foot, dof),
                           bounds=np.log(ACCEL_PSD_BOUNDS), method="bounded",
                           options={"xatol": ACCEL_PSD_LOG_TOLERANCE})
    return float(np.exp(best.x))


def start_state(n: int, R_b: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """n tracks' first states (n, d) and covariances (n, d, d): START_POSITION_SIGMA_M, START_SPEED_SIGMA_MPS;
    with R_b (n, 2, 2) metres^2 (d = 6) the foot-point error b = 0 with its stationary covariance R_b."""
    P = np.diag([START_POSITION_SIGMA_M**2] * 2 + [START_SPEED_SIGMA_MPS**2] * 2)
    if R_b is None:
        return np.zeros((n, 4)), np.broadcast_to(P, (n, 4, 4)).copy()
    P6 = np.zeros((n, 6, 6))
    P6[:, :4, :4], P6[:, 4:, 4:] = P, np.nan_to_num(R_b)
    return np.zeros((n, 6)), P6


def predict(x: np.ndarray, P: np.ndarray, dt: np.ndarray, q: float, foot: tuple[np.ndarray, float] | None = None
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """States (n, d) and covariances (n, d, d) moved on by dt (n,) seconds: F x, F P F^T + Q, and F
    (``transition``; foot as there)."""
    F, Q = transition(dt, q, foot)
    return np.einsum("nij,nj->ni", F, x), F @ P @ F.transpose(0, 2, 1) + Q, F


def gain_update(x: np.ndarray, P: np.ndarray, z: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The Kalman update of states x (m, d), covariances P (m, d, d) by position measurements z (m, 2) with
    covariances R (m, 2, 2), H = ``measurement_matrix(d)``, Joseph form (every row measured)."""
    H = measurement_matrix(x.shape[1])
    HP = H @ P  # (m, 2, d)
    S = HP @ H.T + R
    K = np.linalg.solve(S, HP).transpose(0, 2, 1)  # P H^T S^-1, (m, d, 2); S and P symmetric
    A = np.eye(x.shape[1]) - K @ H
    return x + np.einsum("nij,nj->ni", K, z - x @ H.T), A @ P @ A.transpose(0, 2, 1) + K @ R @ K.transpose(0, 2, 1)


STUDENT_WEIGHT_TOLERANCE = 1e-6
"""``student_update`` iterates until no weight moves by more than this share of itself (far below the weight's
effect on any bar: the state moves by about this share of its update)."""
STUDENT_MAX_ITERATIONS = 100
"""... and at most this many times (the bound on its time; the iteration is a coordinate ascent of the
variational bound, which converges linearly: slowest where a point's weight is far from 1)."""


def student_update(x: np.ndarray, P: np.ndarray, z: np.ndarray, R: np.ndarray, dof: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The variational Bayes update (module docstring) of states x (m, d), covariances P (m, d, d) by
    measurements z (m, 2) of Student-t noise, scale R (m, 2, 2) and dof > 0 degrees of freedom (inf: normal, w
    = 1): ``gain_update`` with R / w, w = (dof + 2) / (dof + tr(R^-1 ((z - H x')(z - H x')^T + H P' H^T))) at
    the updated x', P', from w = 1 to STUDENT_WEIGHT_TOLERANCE (at most STUDENT_MAX_ITERATIONS). Returns x',
    P' and the weights w (m,) (every row measured; each row iterated until its own weight stops)."""
    w = np.ones(len(x))
    xu, Pu = gain_update(x, P, z, R)
    if np.isinf(dof):
        return xu, Pu, w
    H = measurement_matrix(x.shape[1])
    open_ = np.arange(len(x))  # the rows whose weight still moves: each row's result is its own, whatever the batch
    for _ in range(STUDENT_MAX_ITERATIONS):
        e = z[open_] - xu[open_] @ H.T
        spread = e[:, :, None] * e[:, None, :] + H @ Pu[open_] @ H.T  # E[(z - H s)(z - H s)^T], (m, 2, 2)
        w_next = (dof + 2) / (dof + np.trace(np.linalg.solve(R[open_], spread), axis1=1, axis2=2))
        moved = np.abs(w_next - w[open_]) > STUDENT_WEIGHT_TOLERANCE * w[open_]
        w[open_] = w_next
        xu[open_], Pu[open_] = gain_update(x[open_], P[open_], z[open_], R[open_] / w_next[:, None, None])
        open_ = open_[moved]
        if not open_.size:
            break
    return xu, Pu, w


def measured(z: np.ndarray, R: np.ndarray) -> np.ndarray:
    """(n,) bool: the rows whose measurement z (n, 2) and its noise R (n, 2, 2) are finite."""
    return np.isfinite(z).all(axis=1) & np.isfinite(R).all(axis=(1, 2))


def update(x: np.ndarray, P: np.ndarray, z: np.ndarray, R: np.ndarray, dof: float = np.inf
           ) -> tuple[np.ndarray, np.ndarray]:
    """The measurement update of states x (n, d), covariances P (n, d, d) by position measurements z (n, 2) with
    noise R (n, 2, 2): the Kalman update (dof inf) or, for a Student-t noise of scale R and dof degrees of
    freedom, ``student_update``; rows whose z or R is not finite are returned as they are."""
    ok = measured(z, R)
    if not ok.any():
        return x, P
    x, P = x.copy(), P.copy()
    x[ok], P[ok] = student_update(x[ok], P[ok], z[ok], R[ok], dof)[:2]
    return x, P


def innovation_log_density(nu: np.ndarray, S: np.ndarray, dof: float = np.inf) -> np.ndarray:
    """ln p (m,) of innovations nu (m, 2) of scale (covariance when normal) S (m, 2, 2), the constant 2 pi
    dropped: normal (dof inf), -(ln det S + r^2) / 2, r^2 = nu^T S^-1 nu; or Student-t of dof degrees of freedom
    (the measurement noise's, the prediction's normal error taken into its scale),
    ln Gamma((dof + 2) / 2) - ln Gamma(dof / 2) - ln(dof / 2) - ln det S / 2 - (dof + 2) / 2 ln(1 + r^2 / dof),
    whose first three terms cancel in two dimensions (Gamma(a + 1) = a Gamma(a)), and which tends to the
    normal's as dof grows."""
    r2 = np.einsum("ni,ni->n", nu, np.linalg.solve(S, nu[..., None])[..., 0])
    log_det = np.linalg.slogdet(S)[1]
    if np.isinf(dof):
        return -0.5 * (log_det + r2)
    return -0.5 * log_det - (dof + 2) / 2 * np.log1p(r2 / dof)


def rts_smoother(filtered: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Rauch-Tung-Striebel backward pass over ``kalman_filter``'s output: smoothed states (n, L, d) and
    covariances (n, L, d, d), each conditioned on the whole track:
        C_k = P_k F_{k+1}^T P_pred_{k+1}^-1,  x_s,k = x_k + C_k (x_s,k+1 - x_pred,k+1),
        P_s,k = P_k + C_k (P_s,k+1 - P_pred,k+1) C_k^T.
    A step of dt = 0 (a track's padding: no time, no measurement) repeats the state, P_pred,k+1 = P_k: C_k = I
    there, not solved for (P_k is singular after a measurement of zero covariance)."""
    x, P = filtered["x"].copy(), filtered["P"].copy()
    for k in range(x.shape[1] - 2, -1, -1):
        moves = filtered["F"][:, k + 1, 0, 2] > 0  # dt > 0
        C = np.broadcast_to(np.eye(P.shape[-1]), P[:, k].shape).copy()
        if moves.any():
            C[moves] = np.linalg.solve(filtered["P_pred"][moves, k + 1],
                                       filtered["F"][moves, k + 1] @ P[moves, k]).transpose(0, 2, 1)
        x[:, k] += np.einsum("nij,nj->ni", C, x[:, k + 1] - filtered["x_pred"][:, k + 1])
        P[:, k] += C @ (P[:, k + 1] - filtered["P_pred"][:, k + 1]) @ C.transpose(0, 2, 1)
    return x, P


def speed_and_sigma(v: np.ndarray, Pv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Speed |v| (...,) m/s of velocities v (..., 2) and its 1-sigma by the delta method from their covariances
    Pv (..., 2, 2): sigma^2 = v^T Pv v / |v|^2 (the variance along the velocity's direction); at |v| = 0, where
    the speed's derivative is undefined, the sqrt of Pv's largest eigenvalue; NaN for a NaN velocity."""
    speed = np.linalg.norm(v, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        along = np.einsum("...i,...ij,...j->...", v, Pv, v) / speed**2
    largest = np.linalg.eigvalsh(np.nan_to_num(Pv))[..., -1]
    return speed, np.sqrt(np.where(speed > 0, along, np.where(np.isnan(speed), np.nan, largest)))


HALF_WIDTH_TOLERANCE = 1e-3
"""``mixture_half_width``'s bisection stops once its bracket is narrower than this share of the half-width (a
thousandth of the bar, far below the bar's own uncertainty)."""


def mixture_half_width(centre: np.ndarray, w: np.ndarray, means: np.ndarray, sigmas: np.ndarray, k: float = 1.0
                       ) -> np.ndarray:
    """The half-width h (...,) of the interval centre (...,) +- h that holds as much of a mixture of normals,
    weights w (..., M) summing to 1, means and sigmas (..., M), as +- k sigma holds of one normal (68.27 % at
    k = 1, 95.45 % at k = 2): the root of sum_m w_m [Phi((c + h - m_m) / s_m) - Phi((c - h - m_m) / s_m)] =
    Phi(k) - Phi(-k), which grows with h, by a vectorised bisection between k min_m s_m (no component holds
    more than that share within it) and max_m (|c - m_m| + k s_m) (each holds at least that share), to
    HALF_WIDTH_TOLERANCE x h. One component centred on c: k s exactly; a component of sigma 0 is a point mass at
    its mean. NaN where a sigma is NaN."""
    share = ndtr(k) - ndtr(-k)
    c = centre[..., None]
    lo, hi = k * sigmas.min(axis=-1), (np.abs(c - means) + k * sigmas).max(axis=-1)
    lo, hi = np.array(lo, dtype=np.float64, ndmin=1), np.array(hi, dtype=np.float64, ndmin=1)
    c, w, means, sigmas = (np.reshape(a, (len(lo), -1)) for a in np.broadcast_arrays(c, w, means, sigmas))
    open_ = np.flatnonzero(hi - lo > HALF_WIDTH_TOLERANCE * hi)
    while open_.size:
        mid = (lo[open_] + hi[open_]) / 2
        h, m, s = mid[:, None], means[open_], sigmas[open_]
        with np.errstate(divide="ignore", invalid="ignore"):
            below = [np.where(s > 0, ndtr(a / s), a >= 0) for a in (c[open_] + h - m, c[open_] - h - m)]
        held = np.sum(w[open_] * (below[0] - below[1]), axis=1)
        lo[open_], hi[open_] = np.where(held < share, mid, lo[open_]), np.where(held < share, hi[open_], mid)
        open_ = open_[hi[open_] - lo[open_] > HALF_WIDTH_TOLERANCE * hi[open_]]
    return ((lo + hi) / 2).reshape(np.shape(centre))


def mixture_speed(w: np.ndarray, v: np.ndarray, Pv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Speed (...,) m/s of a mixture of velocities, weights w (..., M), means v (..., M, 2), covariances Pv
    (..., M, 2, 2): |sum_m w_m v_m|; and its equivalent 1-sigma (...,) m/s: the ``mixture_half_width`` about it
    holding 68.27 % of the mixture of the models' speed distributions, each normal by ``speed_and_sigma``.
    With one model it is ``speed_and_sigma``'s sigma, exactly."""
    speed = np.linalg.norm(np.einsum("...m,...md->...d", w, v), axis=-1)
    means, sigmas = speed_and_sigma(v, Pv)
    return speed, mixture_half_width(speed, w, means, sigmas)


IMM = "imm"
"""``measure_tracks``' accel_psd (homocal measure --accel-psd) for the two-regime motion model: an interacting
multiple model filter (``imm_filter``) of two constant-velocity models, IMM_ACCEL_PSD, switching at
IMM_SWITCH_PER_S."""
IMM_ACCEL_PSD = (4.4e-4, 10.0)
"""FITTED: the IMM's two q, m^2/s^3: a walker keeping a steady velocity (2 cm/s of wander in one second), one
who turns, starts or stops (at ACCEL_PSD_BOUNDS' top). ``fit_imm`` on simgen's scene1 and scene2, seed 0,
segmentation and rgb boxes pooled, the pedestrians' correction, --foot-noise box-height with one sigma of 0.06 x
the box's height on both coordinates, --feet all (q 0.000442 and 10, rates 0.0239 and 0.931 per s). Not refitted
with the per-axis FOOT_SIGMA_PER_BOX_HEIGHT, under which
``python research/measure_speeds.py DATA/scene1 DATA/scene2 --fit-imm`` prints q 0.000344 and 10, rates 0.0205 and
0.929 per s (docs/measure-accuracy.md, "Two regimes")."""
IMM_SWITCH_PER_S = (0.024, 0.93)
"""FITTED (with IMM_ACCEL_PSD): the IMM's switching rates, per second, steady to manoeuvre and back (a steady
stretch of 42 s on average, a manoeuvre of 1.1 s): over dt seconds a model is left with probability
1 - exp(-rate dt) (a Markov chain in continuous time, so any frame rate and gap)."""


def switching(dt: np.ndarray, rates: tuple[float, ...]) -> np.ndarray:
    """The two-regime Markov chain's transition matrices (n, 2, 2), Pi[i, j] = P(model j now | model i before),
    over dt (n,) seconds at rates (r_01, r_10) per second (one model: the identity (n, 1, 1))."""
    if len(rates) == 0:
        return np.ones((len(dt), 1, 1))
    leave = 1 - np.exp(-np.outer(dt, rates))  # (n, 2)
    return np.stack([np.column_stack([1 - leave[:, 0], leave[:, 0]]),
                     np.column_stack([leave[:, 1], 1 - leave[:, 1]])], axis=1)


def mixture(w: np.ndarray, x: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The moment-matched Gaussian of a mixture: weights w (..., M) (summing to 1), means x (..., M, d),
    covariances P (..., M, d, d): mean (..., d) and covariance (..., d, d), sum w (P + (x - mean)(x - mean)^T)."""
    mean = np.einsum("...m,...md->...d", w, x)
    e = x - mean[..., None, :]
    return mean, np.einsum("...m,...mij->...ij", w, P + e[..., :, None] * e[..., None, :])


def imm_step(x: np.ndarray, P: np.ndarray, mu: np.ndarray, dt: np.ndarray, z: np.ndarray, R: np.ndarray,
             qs: tuple[float, ...], rates: tuple[float, ...], foot: tuple[np.ndarray, float] | None = None,
             dof: float = np.inf) -> dict[str, np.ndarray]:
    """One IMM cycle (Blom and Bar-Shalom 1988; Bar-Shalom, Li and Kirubarajan 2001, Section 11.6.6) of n tracks
    with M = len(qs) models: per-model states x (n, M, d), covariances P (n, M, d, d), model probabilities mu
    (n, M); dt (n,) s; z (n, 2), R (n, 2, 2), dof as ``update``'s (a NaN z: predict only); foot as
    ``transition``'s. Mixing: each model j starts from the mixture of the models' states with weights
    mu_i Pi_ij / c_j, c_j = sum_i mu_i Pi_ij (``switching``); then a prediction by ``transition`` with q_j and
    ``update``; mu_j ~ c_j p(nu_j; S_j) (``innovation_log_density``: normal, or Student-t of dof).

    Returns "x", "P", "mu" (as given, one step on), "c" (n, M) the predicted model probabilities, "F" (n, d, d),
    "Q" (n, M, d, d) each model's process noise, "Pi" (n, M, M) and "loglik" (n,) ln sum_j c_j p(nu_j; S_j)
    (the constant 2 pi dropped as in ``innovation_log_likelihood``; 0 where z is NaN)."""
    Pi = switching(dt, rates)
    c = np.einsum("ni,nij->nj", mu, Pi)
    w = mu[:, :, None] * Pi / np.maximum(c, np.finfo(float).tiny)[:, None, :]  # (n, i, j)
    x0, P0 = mixture(w.transpose(0, 2, 1), x[:, None], P[:, None])  # (n, j, d): each model's start
    out = {"x": np.empty_like(x0), "P": np.empty_like(P0), "Q": np.empty_like(P0), "c": c, "Pi": Pi}
    log_like = np.zeros(c.shape)
    ok = measured(z, R)
    H = measurement_matrix(x.shape[-1])
    for j, q in enumerate(qs):
        F, Q = transition(dt, q, foot)
        out["F"], out["Q"][:, j] = F, Q
        xp, Pp = np.einsum("nij,nj->ni", F, x0[:, j]), F @ P0[:, j] @ F.transpose(0, 2, 1) + Q
        out["x"][:, j], out["P"][:, j] = update(xp, Pp, z, R, dof)
        log_like[ok, j] = innovation_log_density(z[ok] - xp[ok] @ H.T, H @ Pp[ok] @ H.T + R[ok], dof)
    top = log_like.max(axis=1, keepdims=True)
    weighted = c * np.exp(log_like - top)
    out["mu"] = weighted / weighted.sum(axis=1, keepdims=True)
    out["loglik"] = np.where(ok, np.log(weighted.sum(axis=1)) + top[:, 0], 0.0)
    return out


def imm_start(n: int, M: int, rates: tuple[float, ...], R_b: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """n tracks' first states (n, M, d), covariances (n, M, d, d) in each of M models (``start_state``; R_b as
    there) and model probabilities (n, M): the switching chain's stationary ones (r_10, r_01) / (r_01 + r_10)."""
    x, P = start_state(n, R_b)
    mu = np.array([rates[1], rates[0]]) / sum(rates) if M == 2 else np.ones(1)
    return np.repeat(x[:, None], M, axis=1), np.repeat(P[:, None], M, axis=1), np.broadcast_to(mu, (n, M)).copy()


def imm_filter(t: np.ndarray, z: np.ndarray, R: np.ndarray, qs: tuple[float, ...] = IMM_ACCEL_PSD,
               rates: tuple[float, ...] = IMM_SWITCH_PER_S, foot: tuple[np.ndarray, float] | None = None,
               dof: float = np.inf) -> dict[str, np.ndarray]:
    """The IMM forward pass over tracks (arguments as ``kalman_filter``'s; qs, rates as ``imm_step``'s), starting
    in every model from ``start_state`` with the chain's stationary probabilities. Returns ``imm_step``'s "x"
    (n, L, M, d), "P" (n, L, M, d, d), "mu", "c" (n, L, M), "F" (n, L, d, d), "Q" (n, L, M, d, d), "Pi"
    (n, L, M, M) per step, and "loglik", the tracks' summed log-likelihood (a float)."""
    n, L = t.shape
    x, P, mu = imm_start(n, len(qs), rates, None if foot is None else foot[0][:, 0])
    out: dict = {}
    loglik = 0.0
    for k in range(L):
        step = imm_step(x, P, mu, t[:, k] - t[:, k - 1] if k else np.zeros(n), z[:, k], R[:, k], qs, rates,
                        None if foot is None else (foot[0][:, k], foot[1]), dof)
        x, P, mu = step["x"], step["P"], step["mu"]
        loglik += float(step.pop("loglik").sum())
        for key, value in step.items():
            out.setdefault(key, np.empty((n, L) + value.shape[1:]))[:, k] = value
    return out | {"loglik": loglik}


def imm_smoother(filtered: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Kim's fixed-interval IMM smoother (Kim 1994, Section 2.2; Bar-Shalom, Li and Kirubarajan 2001, Section
    11.6) over ``imm_filter``'s output: per-model smoothed states (n, L, M, d), covariances (n, L, M, d, d) and
    model probabilities (n, L, M). Backward from the last step, with Pi, c of step k+1:
        mu_s,k(i) = sum_j b_ij,  b_ij = mu_k(i) Pi_ij mu_s,k+1(j) / c_k+1(j);
    model i's state under model j's step: ``rts_smoother``'s gain with model j's prediction of model i's filtered
    state, C = P_k(i) F^T (F P_k(i) F^T + Q_j)^-1 (C = I on a step of dt = 0), and the smoothed state the
    ``mixture`` over j with weights b_ij / mu_s,k(i). With one model (or equal q) it is ``rts_smoother``."""
    x, P, mu = filtered["x"].copy(), filtered["P"].copy(), filtered["mu"].copy()
    n, L, M, d = x.shape
    tiny = np.finfo(float).tiny
    for k in range(L - 2, -1, -1):
        F, Q, Pi, c = filtered["F"][:, k + 1], filtered["Q"][:, k + 1], filtered["Pi"][:, k + 1], filtered["c"][:, k + 1]
        b = filtered["mu"][:, k, :, None] * Pi * (mu[:, k + 1] / np.maximum(c, tiny))[:, None, :]  # (n, i, j)
        mu_s = b.sum(axis=2)
        moves = F[:, 0, 2] > 0
        xs, Ps = np.empty((n, M, M, d)), np.empty((n, M, M, d, d))
        for i in range(M):
            xi, Pf = filtered["x"][:, k, i], filtered["P"][:, k, i]
            x_pred, FPF = np.einsum("nij,nj->ni", F, xi), F @ Pf @ F.transpose(0, 2, 1)  # the same under every model j
            for j in range(M):
                P_pred = FPF + Q[:, j]
                C = np.broadcast_to(np.eye(d), (n, d, d)).copy()
                if moves.any():
                    C[moves] = np.linalg.solve(P_pred[moves], F[moves] @ Pf[moves]).transpose(0, 2, 1)
                xs[:, i, j] = xi + np.einsum("nij,nj->ni", C, x[:, k + 1, j] - x_pred)
                Ps[:, i, j] = Pf + C @ (P[:, k + 1, j] - P_pred) @ C.transpose(0, 2, 1)
        weights = b / np.maximum(mu_s, tiny)[:, :, None]
        x[:, k], P[:, k] = mixture(weights, xs, Ps)
        mu[:, k] = mu_s
    return x, P, mu


IMM_FIT_LOG_TOLERANCE = 0.1
"""``fit_imm``'s tolerance on the logs of its four constants (10 %: each likelihood is seconds of filtering)."""
IMM_FIT_LOGLIK_TOLERANCE = 0.5
"""``fit_imm``'s tolerance on the log-likelihood (half a unit: one standard error of one constant moves it so)."""


IMM_SWITCH_BOUNDS_PER_S = (0.01, 10.0)
"""The range of the switching rates ``fit_imm`` searches, per second: a regime that lasts 0.1 s to 100 s on
average. Unbounded, on simgen's people the likelihood runs off to q 1e-19 and 1e6 m^2/s^3 (straight walks and
velocity jumps, or the foot points' outliers), no walker's motion."""


def summed_log_likelihood(inputs: list[tuple], qs: tuple[float, ...], rates: tuple[float, ...],
                          noise_scale2: float = 1.0, dof: float = np.inf) -> float:
    """The summed ``imm_filter`` log-likelihood of sets of tracks, inputs a list of ``kalman_filter``'s (t, z, R,
    foot), under the motion model (qs, rates), with the measurement noise (R and the correlated part's R_b) times
    noise_scale2 (the scale's square), the white part normal (dof inf) or Student-t of dof degrees of freedom."""
    return sum(imm_filter(t, z, noise_scale2 * R, qs, rates, None if foot is None else (noise_scale2 * foot[0], foot[1]),
                          dof)["loglik"] for t, z, R, foot in inputs)


def fit_imm(inputs: list[tuple]) -> tuple[tuple[float, float], tuple[float, float]]:
    """The maximum-likelihood IMM constants (IMM_ACCEL_PSD's two q, m^2/s^3, and IMM_SWITCH_PER_S's two rates,
    1/s) of sets of tracks, inputs a list of ``kalman_filter``'s (t, z, R, foot): the maximum of the summed
    ``imm_filter`` log-likelihood over their logs within ACCEL_PSD_BOUNDS and IMM_SWITCH_BOUNDS_PER_S
    (Nelder-Mead from IMM_ACCEL_PSD, IMM_SWITCH_PER_S, to IMM_FIT_LOG_TOLERANCE, IMM_FIT_LOGLIK_TOLERANCE), the
    q's ordered steady first."""
    def cost(s: np.ndarray) -> float:
        e = np.exp(s)
        return -summed_log_likelihood(inputs, (e[0], e[1]), (e[2], e[3]))

    best = minimize(cost, np.log([*IMM_ACCEL_PSD, *IMM_SWITCH_PER_S]), method="Nelder-Mead",
                    bounds=np.log([ACCEL_PSD_BOUNDS] * 2 + [IMM_SWITCH_BOUNDS_PER_S] * 2), options={"xatol": IMM_FIT_LOG_TOLERANCE, "fatol": IMM_FIT_LOGLIK_TOLERANCE})
    q, r = np.exp(best.x[:2]), np.exp(best.x[2:])
    order = np.argsort(q)
    return tuple(float(v) for v in q[order]), tuple(float(v) for v in r[order])


NOISE_SCALE_BOUNDS = (0.05, 5.0)
"""The range of the measurement noise's scale c (R -> c^2 R) ``fit_noise_scale`` searches: a twentieth to five
times the foot noise the model states."""
NOISE_SCALE_LOG_TOLERANCE = 0.01
"""``fit_noise_scale``'s tolerance on ln c (1 %, far below the scale's spread between detectors and box sizes)."""


def fit_noise_scale(inputs: list[tuple], qs: tuple[float, ...] = IMM_ACCEL_PSD,
                    rates: tuple[float, ...] = IMM_SWITCH_PER_S) -> float:
    """The maximum-likelihood scale c of the measurement noise (R -> c^2 R, and the correlated part's R_b
    alike) of sets of tracks, inputs a list of ``kalman_filter``'s (t, z, R, foot), under the motion model
    (qs, rates) as ``imm_filter``'s (one q and no rates: the Kalman filter): the maximum of the summed
    ``imm_filter`` log-likelihood over ln c within NOISE_SCALE_BOUNDS (Brent's bounded search, to
    NOISE_SCALE_LOG_TOLERANCE)."""
    best = minimize_scalar(lambda s: -summed_log_likelihood(inputs, qs, rates, float(np.exp(2 * s))),
                           bounds=np.log(NOISE_SCALE_BOUNDS), method="bounded",
                           options={"xatol": NOISE_SCALE_LOG_TOLERANCE})
    return float(np.exp(best.x))


STUDENT_DOF_BOUNDS = (0.5, 1000.0)
"""The range of the Student-t foot noise's degrees of freedom ``fit_student_noise`` searches: tails heavier than
a Cauchy's to all but normal."""


def fit_student_noise(inputs: list[tuple], qs: tuple[float, ...] = IMM_ACCEL_PSD,
                      rates: tuple[float, ...] = IMM_SWITCH_PER_S) -> tuple[float, float]:
    """The maximum-likelihood Student-t measurement noise of sets of tracks (inputs, qs, rates as
    ``fit_noise_scale``'s): its scale c (R -> c^2 R) and degrees of freedom dof, the maximum of the summed
    ``imm_filter`` log-likelihood (each innovation Student-t, ``innovation_log_density``) over (ln c, ln dof)
    within NOISE_SCALE_BOUNDS, STUDENT_DOF_BOUNDS (Nelder-Mead from c = 1, dof = 4, its first simplex halving
    each, to NOISE_SCALE_LOG_TOLERANCE on both logs and IMM_FIT_LOGLIK_TOLERANCE; scipy's own first simplex, 5 %
    of a coordinate and 0.00025 for ln c = 0, crawls)."""
    start = np.log([1.0, 4.0])
    best = minimize(lambda s: -summed_log_likelihood(inputs, qs, rates, float(np.exp(2 * s[0])), float(np.exp(s[1]))),
                    start, method="Nelder-Mead", bounds=np.log([NOISE_SCALE_BOUNDS, STUDENT_DOF_BOUNDS]),
                    options={"xatol": NOISE_SCALE_LOG_TOLERANCE, "fatol": IMM_FIT_LOGLIK_TOLERANCE,
                             "initial_simplex": start + np.log([[1.0, 1.0], [0.5, 1.0], [1.0, 0.5]])})
    c, dof = np.exp(best.x)
    return float(c), float(dof)


def motion_model(accel_psd: float | str) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """``imm_step``'s (qs, rates) of a process noise: a q alone (one model, no switching: the Kalman filter) or
    IMM's fitted two models; ValueError for a word that is not IMM."""
    if isinstance(accel_psd, str) and accel_psd != IMM:
        raise ValueError(f"accel_psd: expected a number (m^2/s^3) or {IMM!r}, got {accel_psd!r}")
    return (IMM_ACCEL_PSD, IMM_SWITCH_PER_S) if accel_psd == IMM else ((float(accel_psd),), ())


def track_states(t: np.ndarray, z: np.ndarray, R: np.ndarray, accel_psd: float | str, smooth: bool,
                 foot: tuple[np.ndarray, float] | None = None, dof: float = np.inf
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The models' probabilities (n, L, M), states (n, L, M, d) and covariances (n, L, M, d, d) of tracks
    (arguments as ``kalman_filter``'s) under a process noise q (one model: ``kalman_filter``, with smooth
    ``rts_smoother``) or IMM (two: ``imm_filter``, with smooth ``imm_smoother``); ``mixture`` gives their
    moment-matched state, ``mixture_speed`` the speed and its bars."""
    if accel_psd != IMM:
        filtered = kalman_filter(t, z, R, accel_psd, foot, dof)
        x, P = rts_smoother(filtered) if smooth else (filtered["x"], filtered["P"])
        return np.ones(t.shape + (1,)), x[:, :, None], P[:, :, None]
    filtered = imm_filter(t, z, R, *motion_model(IMM), foot, dof)
    x, P, mu = imm_smoother(filtered) if smooth else (filtered["x"], filtered["P"], filtered["mu"])
    return mu, x, P

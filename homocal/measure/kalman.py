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
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import minimize_scalar

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
                  foot: tuple[np.ndarray, float] | None = None) -> dict[str, np.ndarray]:
    """Forward pass over tracks: t (n, L) seconds, non-decreasing along each row (a padded step repeats the last
    time and has NaN z), z (n, L, 2) metres, R (n, L, 2, 2) metres^2 (the white part of the measurement
    error); foot None, or (R_b (n, L, 2, 2) metres^2, tau seconds): the part correlated over frames (module
    docstring), d = 6 states.

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
        x, P = update(x, P, z[:, k], R[:, k])
        out["x"][:, k], out["P"][:, k] = x, P
    return out


def innovation_log_likelihood(t: np.ndarray, z: np.ndarray, R: np.ndarray, q: float,
                              foot: tuple[np.ndarray, float] | None = None) -> float:
    """The prediction-error log-likelihood of tracks under process noise q (arguments as ``kalman_filter``'s):
    the sum over measured steps of -(ln det S + nu^T S^-1 nu) / 2, nu = z - H x_pred the innovation and
    S = H P_pred H^T + R its covariance (the constant 2 pi dropped; Bar-Shalom, Li and Kirubarajan 2001,
    Section 5.2.5; Harvey 1989, Section 3.4)."""
    f = kalman_filter(t, z, R, q, foot)
    H = measurement_matrix(f["x"].shape[-1])
    ok = np.isfinite(z).all(axis=-1) & np.isfinite(R).all(axis=(-2, -1))
    nu = z[ok] - f["x_pred"][ok] @ H.T
    S = H @ f["P_pred"][ok] @ H.T + R[ok]
    return float(-0.5 * (np.linalg.slogdet(S)[1].sum() + np.einsum("ni,ni->", nu, np.linalg.solve(S, nu[..., None])[..., 0])))


def fit_accel_psd(t: np.ndarray, z: np.ndarray, R: np.ndarray, foot: tuple[np.ndarray, float] | None = None
                  ) -> float:
    """The maximum-likelihood q, m^2/s^3, of tracks (arguments as ``kalman_filter``'s): the maximum of
    ``innovation_log_likelihood`` over ln q in ln ACCEL_PSD_BOUNDS (Brent's bounded search, to
    ACCEL_PSD_LOG_TOLERANCE)."""
    best = minimize_scalar(lambda s: -innovation_log_likelihood(t, z, R, float(np.exp(s)), foot),
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


def update(x: np.ndarray, P: np.ndarray, z: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The Kalman update of states x (n, d), covariances P (n, d, d) by position measurements z (n, 2) with
    covariances R (n, 2, 2), H = ``measurement_matrix(d)``, Joseph form; rows whose z or R is not finite are
    returned as they are."""
    ok = np.isfinite(z).all(axis=1) & np.isfinite(R).all(axis=(1, 2))
    if not ok.any():
        return x, P
    x, P = x.copy(), P.copy()
    xo, Po, zo, Ro = x[ok], P[ok], z[ok], R[ok]
    H = measurement_matrix(x.shape[1])
    HP = H @ Po  # (m, 2, d)
    S = HP @ H.T + Ro
    K = np.linalg.solve(S, HP).transpose(0, 2, 1)  # P H^T S^-1, (m, d, 2); S and P symmetric
    x[ok] = xo + np.einsum("nij,nj->ni", K, zo - xo @ H.T)
    A = np.eye(x.shape[1]) - K @ H
    P[ok] = A @ Po @ A.transpose(0, 2, 1) + K @ Ro @ K.transpose(0, 2, 1)
    return x, P


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

"""People's tracks measured on the ground: per track and frame the mapped foot point with its error bar, the
smoothed position and velocity and the speed with its error bar; per track its path, mean speed and time
stationary; per frame the distances between the people in view.

Memory is bounded by design: tracks are filtered in batches of at most BATCH_CELLS (tracks x longest track's
frames), distances in chunks of frames of at most BATCH_CELLS boxes, and a frame holds at most
MAX_PEOPLE_PER_FRAME people for distances.
"""
from __future__ import annotations

from collections.abc import Iterator
from typing import Protocol

import numpy as np

from homocal.geometry import Lens, ViewTransformer
from homocal.geometry.boxes import cut_edges, hidden_feet, short_boxes
from homocal.measure.kalman import (ACCEL_PSD, correlated_noise, fit_accel_psd, mixture, mixture_speed,
                                   track_states)
from homocal.uncertainty import STEP, click_jacobian, ground_uncertainty, point_jacobian, sigma_radius

COLUMNS = ("frame", "t", "track_id", "u", "v", "x", "y", "sigma_m", "x_smooth", "y_smooth", "vx", "vy", "speed_mps",
           "speed_sigma_mps", "foot")
"""homocal measure's table, one row per track and frame (docs/measure.md has their units)."""
SUMMARY_COLUMNS = ("track_id", "frames", "first_frame", "last_frame", "duration_s", "path_length_m",
                   "mean_speed_mps", "stationary_s")
PAIR_COLUMNS = ("frame", "t", "track_a", "track_b", "distance_m", "distance_sigma_m")
BATCH_CELLS = 2**16
"""Cells (tracks x frames, padded) filtered at once, and boxes mapped at once for distances: about 85 floats a
cell (the filter's states, predictions, covariances and transitions, the smoother's copies), some 45 MB; about
twice that with the correlated foot error's six states; with the IMM's two models (``kalman.imm_filter``: each
model's states, covariances and process noise, the smoother's copies) about 140 floats a cell (72 MB), 290 with
six states (150 MB)."""
MAX_TRACK_FRAMES = BATCH_CELLS
"""The longest track measured (a batch of its own; 36 minutes at 30 fps): homocal measure refuses longer ones."""
MAX_PEOPLE_PER_FRAME = 500
"""People in one frame for --pairs (at most 124,750 distances a frame); more is refused."""
STATIONARY_MPS = 0.3
"""A track is stationary while its smoothed speed is under this (a slow walk is 0.8 m/s; a standing person's
foot point sways by a few centimetres)."""
MIN_TRACK_FRAMES = 2
"""A track needs this many frames for a speed; shorter ones are left out (and counted)."""


class Mapping(Protocol):
    """What homocal measure maps with: a fitted Corrector, or a ViewTransformer in ``TrapezoidMapping``."""

    def transform_points(self, image_points: np.ndarray) -> np.ndarray: ...

    def ground_uncertainty(self, image_points: np.ndarray, click_sigma_px: float = 1.5,
                           point_sigma_px: float = 1.0) -> np.ndarray: ...


class TrapezoidMapping:
    """A clicked trapezoid's mapping with a Corrector's interface (no correction): its transform_points and
    homocal.ground_uncertainty. transformer maps undistorted pixels; lens (or None) is the camera's, as a
    Corrector's ``lens_``: the clicks and the feet err on its distorted frame."""

    def __init__(self, transformer: ViewTransformer, lens: Lens | None = None) -> None:
        if not isinstance(transformer, ViewTransformer):
            raise TypeError(f"transformer: expected a homocal.ViewTransformer, got {type(transformer).__name__}")
        self.mapping = self.base_transformer_ = transformer
        self.lens_ = None if lens is None or lens.is_identity else lens

    def transform_points(self, image_points: np.ndarray) -> np.ndarray:
        return self.mapping.transform_points(image_points)

    def ground_uncertainty(self, image_points: np.ndarray, click_sigma_px: float = 1.5,
                           point_sigma_px: float = 1.0) -> np.ndarray:
        return ground_uncertainty(self.mapping, image_points, click_sigma_px, point_sigma_px, lens=self.lens_)


def as_mapping(mapping) -> Mapping:
    """A Corrector as it is, a ViewTransformer as a TrapezoidMapping."""
    return TrapezoidMapping(mapping) if isinstance(mapping, ViewTransformer) else mapping


def box_margin_of(mapping) -> float:
    """The box margin, px, that a mapping's correction was fitted with (a PedestrianCorrector's box_margin_px), 0
    for any other (a ViewTransformer, a TrapezoidMapping, a correction of reference points)."""
    return float(getattr(mapping, "box_margin_px", 0.0))


def map_points(mapping: Mapping, feet: np.ndarray, click_sigma_px: float, point_sigma_px
               ) -> tuple[np.ndarray, np.ndarray]:
    """Ground points (N, 2) metres and their covariances (N, 2, 2) metres^2 of foot points (N, 2) px, point_sigma_px
    px one number for both coordinates of every point, or (N, 2) one (u, v) pair a foot point (``point_noise``)."""
    if np.ndim(point_sigma_px) == 0:
        return mapping.transform_points(feet), mapping.ground_uncertainty(feet, click_sigma_px=click_sigma_px,
                                                                         point_sigma_px=point_sigma_px)
    shared = mapping.ground_uncertainty(feet, click_sigma_px=click_sigma_px, point_sigma_px=0.0)
    return mapping.transform_points(feet), shared + point_noise(mapping, feet, point_sigma_px)


def point_noise(mapping: Mapping, feet: np.ndarray, point_sigma_px) -> np.ndarray:
    """The part (N, 2, 2) metres^2 of the ground covariances of foot points (N, 2) px that is independent from
    frame to frame: the foot point's own error, independent on its two coordinates of 1-sigma point_sigma_px px
    (``check_point_sigma``: a number for both, or (N, 2) (u, v) a point), J diag(s_u^2, s_v^2) J^T with J the
    mapping's derivative at the point (homocal.uncertainty.point_jacobian of its transformer and lens: the
    sigmas on the camera's distorted frame, as ground_uncertainty's), not the shared mapping error (clicking, a
    fitted horizon), which is the same in every frame of a track. NaN on or above the horizon."""
    sigma = np.broadcast_to(check_point_sigma(point_sigma_px, len(feet)), (len(feet), 2))
    J = point_jacobian(mapping.mapping, feet, getattr(mapping, "lens_", None)) * sigma[:, None, :]
    return J @ J.transpose(0, 2, 1)


def check_point_sigma(point_sigma_px, n: int) -> float | np.ndarray:
    """A foot point sigma as given (a number, px, for both coordinates) or as a float (n, 2) array (u, v) px of n
    foot points; ValueError for another shape."""
    if np.ndim(point_sigma_px) == 0:
        return point_sigma_px
    sigma = np.asarray(point_sigma_px, dtype=np.float64)
    if sigma.shape != (n, 2):
        raise ValueError(f"point_sigma_px: expected a number or (N, 2) px, (u, v) for each of the {n} foot points, "
                         f"got shape {sigma.shape}")
    return sigma


FOOT_SIGMA_PER_BOX_HEIGHT = (0.086, 0.032)
"""FITTED: a foot point's 1-sigma across (u) and along (v), px, per px of its box's height (sigma_u = 0.086 x box
height, sigma_v = 0.032 x box height): each coordinate's pure ratio fitted by research/foot_noise.py ("u alone",
"v alone") to the robust sigmas of the foot-point errors against the truth on simgen's scene1 and scene2, seed 0,
every box, the mean of the segmentation and the rgb boxes' (u 0.084 and 0.088, v 0.029 and 0.035; on the soles
u 0.086 and 0.083, v 0.025 and 0.034; an intercept fits negative). The error is not white: its autocorrelation
one frame apart (20 fps) is 0.93-0.97."""


FOOT_CORRELATION_S = 0.16
"""FITTED: the correlation time tau, seconds, of the foot point's error taken as an AR(1) (homocal.measure.kalman:
rho = exp(-dt / tau) between frames dt apart): research/foot_noise.py's least-squares fit to the autocorrelation
at lags 1-5 frames (20 fps) of the error over its box's height, the unit process that FOOT_SIGMA_PER_BOX_HEIGHT
scales, on simgen's scene1 and scene2, seed 0 (0.13 s segmentation, 0.19 s rgb boxes, u and v together; the
error in pixels, where the large boxes weigh most, gives 0.55-0.59 s)."""


FOOT = ("used", "hidden", "border", "short")
"""homocal measure's foot column: the box's foot point measured ("used"), or not, the filter predicting through
that frame and the smoother filling it in, as its bottom edge may not be the sole: a nearer person's box may hide
the feet ("hidden": geometry.boxes.hidden_feet) or the image border cuts the box's bottom or a side edge, which
moves the bottom edge's centre ("border": geometry.boxes.cut_edges; a cut top edge leaves the feet as they are),
or the box is no taller than the box margin, which leaves it no person ("short": geometry.boxes.short_boxes)."""
FEET = ("all", "soles")
"""The foot points measured (homocal measure --feet, GroundTracker's feet): all, every box's; soles, only those
``foot_status`` finds "used"."""


def foot_status(edges: np.ndarray, frames: np.ndarray, image_size: tuple[int, int] | None) -> np.ndarray:
    """(N,) str, one of FOOT, for box edges (N, 4) homocal px in the camera's raw pixels, of video frames (N,) int,
    in an image of image_size (width, height) px (None: unknown, no box on the border): "border" before
    "hidden" (the border's cut is certain, a nearer box's may not hide the feet)."""
    status = np.full(len(edges), FOOT[0], dtype=f"<U{max(map(len, FOOT))}")
    status[hidden_feet(edges, frames)] = FOOT[1]
    if image_size is not None:
        status[cut_edges(edges, image_size)[:, [0, 2, 3]].any(axis=1)] = FOOT[2]
    return status


def measured_feet(edges: np.ndarray, frames: np.ndarray, image_size: tuple[int, int] | None, feet: str,
                  margin_px: float) -> np.ndarray:
    """(N,) str, one of FOOT, for box edges (N, 4) homocal px in the camera's raw pixels as detected, of video
    frames (N,) int: with feet "soles" (one of FEET) foot_status's, else "used"; whatever feet, "short" for a box
    that the box margin margin_px leaves with no height (geometry.boxes.short_boxes)."""
    status = (foot_status(edges, frames, image_size) if feet == "soles"
              else np.full(len(edges), FOOT[0], dtype=f"<U{max(map(len, FOOT))}"))
    status[short_boxes(edges, margin_px)] = FOOT[3]
    return status


def box_height_sigma_px(xyxy: np.ndarray) -> np.ndarray:
    """Foot points' 1-sigma (N, 2) px, (u, v), of boxes xyxy (N, 4) px: FOOT_SIGMA_PER_BOX_HEIGHT x the box's
    height."""
    return np.abs(xyxy[:, 3] - xyxy[:, 1])[:, None] * np.asarray(FOOT_SIGMA_PER_BOX_HEIGHT)


FOOT_NOISE = ("fixed", "box-height", "correlated")
"""The foot point's noise models (homocal measure --foot-noise, GroundTracker's foot_noise; docs/measure.md):
fixed, one sigma for every point and the whole covariance the filter's white measurement noise; box-height,
``box_height_sigma_px`` white and the shared mapping error in the speed's sigma (split_mapping_error);
correlated, box-height's with the foot error an AR(1) of FOOT_CORRELATION_S in the filter's state."""


FOOT_TAILS = ("normal", "student")
"""The foot point's noise distribution (homocal measure --foot-noise-tails, GroundTracker's foot_tails): normal;
student, heavy tailed, a Student-t of STUDENT_FOOT_NOISE's scale and degrees of freedom for the FOOT_NOISE model,
each update weighted by how far its foot point lies (homocal.measure.kalman.student_update); with the models
STUDENT_FOOT_NOISE has (correlated has no white part to weight)."""
STUDENT_FOOT_NOISE = {"fixed": (0.163, 3.55)}
"""FITTED: per FOOT_NOISE model that has one (fixed; box-height's fit is not made), the Student-t foot noise's
scale c on the filter's measurement noise R (R -> c^2 R) and its degrees of freedom:
homocal.measure.kalman.fit_student_noise under the IMM (IMM_ACCEL_PSD, IMM_SWITCH_PER_S) on simgen's scene1 and
scene2, seed 0, segmentation and rgb boxes pooled, the pedestrians' correction, --feet all: ``python
research/measure_speeds.py DATA/scene1 DATA/scene2 --fit-foot-tails`` (c 0.163, dof 3.55: a core a sixth of
the fixed model's sigma, and heavy tails)."""


def foot_noise_options(foot_noise: str, xyxy: np.ndarray, point_sigma_px: float, foot_tails: str = FOOT_TAILS[0],
                       names: tuple[str, str] = ("foot_noise", "foot_tails")) -> dict:
    """``measure_tracks``'s point_sigma_px, split_mapping_error, foot_correlation_s, noise_scale and student_dof
    for a FOOT_NOISE model, a FOOT_TAILS distribution and boxes xyxy (N, 4) px (point_sigma_px: fixed's sigma,
    px); ValueError for another name, or student tails with correlated, naming the two as ``names`` (a caller's
    flags)."""
    noise_name, tails_name = names
    if foot_noise not in FOOT_NOISE:
        raise ValueError(f"{noise_name}: expected one of {', '.join(FOOT_NOISE)}, got {foot_noise!r}")
    if foot_tails not in FOOT_TAILS:
        raise ValueError(f"{tails_name}: expected one of {', '.join(FOOT_TAILS)}, got {foot_tails!r}")
    if foot_tails == "student" and foot_noise not in STUDENT_FOOT_NOISE:
        raise ValueError(f"{tails_name} student: needs {noise_name} {' or '.join(STUDENT_FOOT_NOISE)}, not {foot_noise} "
                         "(box-height has no fitted constants, correlated no white part to weight)")
    scale, dof = STUDENT_FOOT_NOISE[foot_noise] if foot_tails == "student" else (1.0, None)
    tails = {"noise_scale": scale, "student_dof": dof}
    if foot_noise == "fixed":
        return {"point_sigma_px": point_sigma_px, "split_mapping_error": False, "foot_correlation_s": None} | tails
    return {"point_sigma_px": box_height_sigma_px(np.asarray(xyxy, dtype=np.float64)), "split_mapping_error": True,
            "foot_correlation_s": FOOT_CORRELATION_S if foot_noise == "correlated" else None} | tails


def mapping_modes(mapping: Mapping, feet: np.ndarray, click_sigma_px: float) -> tuple[np.ndarray, np.ndarray]:
    """The shared mapping error at foot points (N, 2) px as J (N, 2, k), the ground points' derivative along k
    error parameters, and their covariance C (k, k), so that J C J^T is ground_uncertainty at point_sigma_px = 0:
    the 8 clicked corner coordinates (``homocal.uncertainty.click_jacobian``, click_sigma_px each) and a
    PedestrianCorrector's fitted tilt and roll (its ``angle_modes``)."""
    J, C = click_jacobian(mapping.mapping, feet, getattr(mapping, "lens_", None)), click_sigma_px**2 * np.eye(8)
    if hasattr(mapping, "angle_modes"):
        Ja, Ca = mapping.angle_modes(feet)
        J, C = np.concatenate([J, Ja], axis=2), np.block([[C, np.zeros((8, 2))], [np.zeros((2, 8)), Ca]])
    return J, C


def mapping_velocity_covariance(mapping: Mapping, feet: np.ndarray, v: np.ndarray, click_sigma_px: float
                                ) -> np.ndarray:
    """Covariance (N, 2, 2) (m/s)^2 of ground velocities v (N, 2) m/s at foot points (N, 2) px under the shared
    mapping error: a perturbation e of the mapping moves a ground point by J(q) e (``mapping_modes``), the same
    in every frame up to J's change along the track, so it moves the velocity by D e, D = dJ/dt = (dJ/dq) q',
    with q' = (d mapping / dq)^-1 v the foot point's image velocity (px/s); D C D^T. Derivatives by central
    differences: the mapping's over STEP px, J's over 1 px along q'. NaN where a foot point is NaN."""
    d = np.stack([(mapping.transform_points(feet + STEP * e) - mapping.transform_points(feet - STEP * e))
                  / (2 * STEP) for e in np.eye(2)], axis=-1)  # (N, 2, 2): d(x, y) / d(u, v)
    q_dot = np.linalg.solve(d, v[..., None])[..., 0]
    rate = np.linalg.norm(q_dot, axis=1)
    e = q_dot / np.where(rate > 0, rate, 1.0)[:, None]  # unit image direction (0 where the point stands)
    J_ahead, C = mapping_modes(mapping, feet + e, click_sigma_px)
    J_behind, _ = mapping_modes(mapping, feet - e, click_sigma_px)
    D = (J_ahead - J_behind) * (rate / 2)[:, None, None]
    return D @ C @ D.transpose(0, 2, 1)


def state_speed(mapping: Mapping, feet: np.ndarray, mu: np.ndarray, x: np.ndarray, P: np.ndarray,
                click_sigma_px: float | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The moment-matched state (N, d) of the filter's models (probabilities mu (N, M), states x (N, M, d),
    covariances P (N, M, d, d); ``kalman.mixture``), its speed (N,) m/s and the speed's 1-sigma (N,) m/s
    (``kalman.mixture_speed`` of the models' velocity blocks: with one model the delta-method sigma, with more
    the half-width that holds 68.27 % of their mixture), at foot points (N, 2) px; unless click_sigma_px is None
    each model's velocity covariance takes the shared mapping error's share (``mapping_velocity_covariance`` at
    the mixture's velocity, click_sigma_px)."""
    mean = mixture(mu, x, P)[0]
    Pv = P[..., 2:4, 2:4]
    if click_sigma_px is not None:
        Pv = Pv + mapping_velocity_covariance(mapping, feet, mean[:, 2:4], click_sigma_px)[:, None]
    return (mean,) + mixture_speed(mu, x[..., 2:4], Pv)


def measurement_dof(student_dof: float | None) -> float:
    """kalman's dof of ``measure_tracks``' student_dof (None: normal, inf); ValueError unless None or > 0."""
    if student_dof is None:
        return np.inf
    if isinstance(student_dof, bool) or not isinstance(student_dof, (int, float, np.number)) or not student_dof > 0:
        raise ValueError(f"student_dof: expected None or a number > 0 (degrees of freedom), got {student_dof!r}")
    return float(student_dof)


def check_tracks(frames: np.ndarray, track_ids: np.ndarray) -> None:
    """ValueError for a track whose rows (in the given order) go back in frame or repeat one: the rows of a
    track must come in increasing frame order, one box per track and frame."""
    order = np.lexsort((np.arange(len(frames)), track_ids))  # by track, then as given
    f, k = frames[order], track_ids[order]
    same = k[1:] == k[:-1]
    for bad, what in ((same & (f[1:] == f[:-1]), "has two boxes in frame {b}"),
                      (same & (f[1:] < f[:-1]), "goes back from frame {a} to frame {b}")):
        i = np.flatnonzero(bad)
        if i.size:
            i = i[np.argmin(order[i + 1])]
            raise ValueError(f"track {k[i]} " + what.format(a=f[i], b=f[i + 1]) + " (row "
                             f"{order[i + 1]}, from 0): one box per track and frame, in increasing frame order")


def track_batches(track_ids: np.ndarray, frames: np.ndarray) -> Iterator[list[np.ndarray]]:
    """The rows of each track (index arrays, in frame order), tracks in increasing id, grouped into batches of
    at most BATCH_CELLS cells (tracks x the longest track's rows; a track of up to MAX_TRACK_FRAMES rows)."""
    order = np.lexsort((frames, track_ids))
    _, starts = np.unique(track_ids[order], return_index=True)
    batch, longest = [], 0
    for rows in np.split(order, starts[1:]):
        if batch and (len(batch) + 1) * max(longest, len(rows)) > BATCH_CELLS:
            yield batch
            batch, longest = [], 0
        batch.append(rows)
        longest = max(longest, len(rows))
    if batch:
        yield batch


def filter_inputs(mapping: Mapping, frames: np.ndarray, feet: np.ndarray, fps: float, batch: list[np.ndarray],
                  click_sigma_px: float, point_sigma_px: float | np.ndarray, split_mapping_error: bool,
                  foot_correlation_s: float | None, foot: np.ndarray | None = None, noise_scale: float = 1.0
                  ) -> tuple[np.ndarray, np.ndarray, tuple]:
    """A batch of tracks (``track_batches``' row indices) as the filter takes it: the mapped points xy (N, 2) m
    and their covariances (N, 2, 2) m^2 (rows in the batch's order), and kalman_filter's (t, z, R, foot), padded
    to the longest track (arguments as ``measure_tracks``'; frames (N,), feet (N, 2) px of all rows); z is NaN
    (no measurement, R kept for the correlated error's process) where foot is not "used"; R is the measurement
    noise times noise_scale^2."""
    rows = np.concatenate(batch)
    sigma = point_sigma_px if np.ndim(point_sigma_px) == 0 else point_sigma_px[rows]
    xy, cov = map_points(mapping, feet[rows], click_sigma_px, sigma)
    noise = point_noise(mapping, feet[rows], sigma) if split_mapping_error else cov
    n, L = len(batch), max(map(len, batch))
    t, z, R = np.empty((n, L)), np.full((n, L, 2), np.nan), np.full((n, L, 2, 2), np.nan)
    at = np.concatenate([[0], np.cumsum([len(r) for r in batch])])
    for i, r in enumerate(batch):
        m = len(r)
        t[i, :m], t[i, m:] = frames[r] / fps, frames[r[-1]] / fps
        z[i, :m], R[i, :m] = xy[at[i]:at[i + 1]], noise[at[i]:at[i + 1]]
        if foot is not None:
            z[i, :m][foot[r] != FOOT[0]] = np.nan
    return xy, cov, (t, z, *correlated_noise(noise_scale**2 * R, foot_correlation_s))


def fit_tracks_accel_psd(mapping, frames: np.ndarray, feet: np.ndarray, track_ids: np.ndarray, fps: float, *,
                         click_sigma_px: float = 1.5, point_sigma_px: float | np.ndarray = 1.0,
                         split_mapping_error: bool = False, foot_correlation_s: float | None = None,
                         foot: np.ndarray | None = None, noise_scale: float = 1.0, student_dof: float | None = None
                         ) -> float:
    """The filter's process noise q, m^2/s^3, fitted to the tracks by maximum likelihood of its innovations
    (``kalman.fit_accel_psd``; arguments as ``measure_tracks``'): no ground truth, the people's own motion
    under the measurement noise model. Its cost is bounded: the tracks of ``track_batches``' first batch
    (tracks in increasing id, at most BATCH_CELLS cells), each likelihood one forward filter over them."""
    return fit_accel_psd(*first_batch_inputs(mapping, frames, feet, track_ids, fps, click_sigma_px=click_sigma_px,
                                             point_sigma_px=point_sigma_px, split_mapping_error=split_mapping_error,
                                             foot_correlation_s=foot_correlation_s, foot=foot,
                                             noise_scale=noise_scale), dof=measurement_dof(student_dof))


def first_batch_inputs(mapping, frames: np.ndarray, feet: np.ndarray, track_ids: np.ndarray, fps: float, *,
                       click_sigma_px: float = 1.5, point_sigma_px: float | np.ndarray = 1.0,
                       split_mapping_error: bool = False, foot_correlation_s: float | None = None,
                       foot: np.ndarray | None = None, noise_scale: float = 1.0) -> tuple:
    """kalman_filter's (t, z, R, foot) of ``track_batches``' first batch of the tracks (arguments as
    ``measure_tracks``'): what the process noise is fitted on."""
    mapping = as_mapping(mapping)
    frames, track_ids = np.asarray(frames, dtype=np.int64), np.asarray(track_ids, dtype=np.int64)
    point_sigma_px = check_point_sigma(point_sigma_px, len(frames))
    batch = next(track_batches(track_ids, frames))
    return filter_inputs(mapping, frames, np.asarray(feet, dtype=np.float64), fps, batch, click_sigma_px,
                         point_sigma_px, split_mapping_error, foot_correlation_s, foot, noise_scale)[2]


def measure_tracks(mapping, frames: np.ndarray, feet: np.ndarray, track_ids: np.ndarray, fps: float, *,
                   accel_psd: float | str = ACCEL_PSD, smooth: bool = True, click_sigma_px: float = 1.5,
                   point_sigma_px: float | np.ndarray = 1.0, split_mapping_error: bool = False,
                   foot_correlation_s: float | None = None, foot: np.ndarray | None = None, noise_scale: float = 1.0,
                   student_dof: float | None = None) -> Iterator[dict[str, np.ndarray]]:
    """homocal measure's table in batches of whole tracks (dicts of COLUMNS, each (rows,)), tracks in
    increasing id, each in frame order.

    Args:
        mapping: a fitted Corrector or a ViewTransformer.
        frames: (N,) int video frames (t = frame / fps seconds); track_ids (N,) int, one box per track and
            frame (``check_tracks``); feet (N, 2) foot points, px; point_sigma_px px a number for both
            coordinates of every foot point, or (N, 2) a (u, v) pair each (``box_height_sigma_px``).
        accel_psd: the filter's process noise q, m^2/s^3, or kalman.IMM: two constant-velocity models, a steady
            walker's and a manoeuvre's, switching (homocal.measure.kalman).
        smooth: True: the RTS (or IMM) smoother's states (each conditioned on the whole track); False: the forward
            filter's (each on the frames up to it: what a live system has).
        split_mapping_error: the filter's measurement noise the foot point's own (``point_noise``) and the shared
            mapping error in the speed's sigma (``mapping_velocity_covariance``); False: the whole covariance.
        foot_correlation_s: None: the measurement noise white; tau seconds (FOOT_CORRELATION_S): the foot
            point's own noise correlated over frames, an AR(1) of this correlation time in the filter's state
            (homocal.measure.kalman; with split_mapping_error).
        foot: (N,) FOOT values (``foot_status``), None: all "used": a foot point not "used" is no measurement
            (the filter predicts through its frame); the states and speeds are NaN where no foot point is
            measured yet (filter) or in the whole track (smoother).
        noise_scale: the filter's measurement noise (white and correlated) times its square
            (kalman.fit_noise_scale); the points' sigma_m stay the mapping's.
        student_dof: None: the white measurement noise normal; a number > 0: Student-t of these degrees of
            freedom (its scale the measurement noise; STUDENT_FOOT_NOISE), each update weighted by its foot
            point's distance (kalman.student_update); not with foot_correlation_s.
    x, y are the mapped foot points, sigma_m their 1-sigma radius (homocal.sigma_radius of the mapping's
    ground_uncertainty at click_sigma_px, point_sigma_px: the filter's measurement noise); x_smooth, y_smooth,
    vx, vy the filter's state (with IMM its models' moment-matched mixture); speed_mps = |(vx, vy)| and
    speed_sigma_mps its 1-sigma (``state_speed``): the delta method on the state's velocity covariance
    (kalman.speed_and_sigma), with IMM the half-width about speed_mps holding 68.27 % of the models' mixture of
    speeds (kalman.mixture_speed).
    """
    if foot_correlation_s is not None and not (split_mapping_error and foot_correlation_s > 0):
        raise ValueError(f"foot_correlation_s: expected > 0 with split_mapping_error=True, got {foot_correlation_s!r}")
    if not (np.isfinite(noise_scale) and noise_scale > 0):
        raise ValueError(f"noise_scale: expected a finite number > 0, got {noise_scale!r}")
    if student_dof is not None and foot_correlation_s is not None:
        raise ValueError("student_dof: a Student-t white noise needs foot_correlation_s None (no white part with it)")
    dof = measurement_dof(student_dof)
    mapping = as_mapping(mapping)
    frames, track_ids = np.asarray(frames, dtype=np.int64), np.asarray(track_ids, dtype=np.int64)
    feet = np.asarray(feet, dtype=np.float64)
    point_sigma_px = check_point_sigma(point_sigma_px, len(frames))
    foot = np.full(len(frames), FOOT[0]) if foot is None else np.asarray(foot)
    for batch in track_batches(track_ids, frames):
        rows = np.concatenate(batch)
        xy, cov, (t, z, R, correlated) = filter_inputs(mapping, frames, feet, fps, batch, click_sigma_px,
                                                       point_sigma_px, split_mapping_error, foot_correlation_s, foot,
                                                       noise_scale)
        mu, x, P = track_states(t, z, R, accel_psd, smooth, correlated, dof)
        seen = np.isfinite(z).all(axis=2)  # (n, L): the steps measured
        x[np.broadcast_to(~seen.any(axis=1, keepdims=True) if smooth else np.cumsum(seen, axis=1) == 0, seen.shape)] = np.nan
        L = t.shape[1]
        used = np.concatenate([np.arange(len(r)) + i * L for i, r in enumerate(batch)])
        M, d = x.shape[-2:]
        x, speed, speed_sigma = state_speed(mapping, feet[rows], mu.reshape(-1, M)[used], x.reshape(-1, M, d)[used],
                                            P.reshape(-1, M, d, d)[used], click_sigma_px if split_mapping_error else None)
        yield {"frame": frames[rows], "t": frames[rows] / fps, "track_id": track_ids[rows], "u": feet[rows, 0],
               "v": feet[rows, 1], "x": xy[:, 0], "y": xy[:, 1], "sigma_m": sigma_radius(cov), "x_smooth": x[:, 0],
               "y_smooth": x[:, 1], "vx": x[:, 2], "vy": x[:, 3], "speed_mps": speed, "speed_sigma_mps": speed_sigma,
               "foot": foot[rows]}


def summarise(batch: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per track of a ``measure_tracks`` batch (SUMMARY_COLUMNS): frames, first and last frame, duration_s
    (last t - first t), path_length_m (the smoothed path's length: the sum of its steps), mean_speed_mps
    (path / duration) and stationary_s (the time, summed over steps, whose starting speed_mps is under
    STATIONARY_MPS)."""
    ids, starts, counts = np.unique(batch["track_id"], return_index=True, return_counts=True)
    ends = starts + counts - 1
    step = np.hypot(np.diff(batch["x_smooth"]), np.diff(batch["y_smooth"]))
    dt = np.diff(batch["t"])
    inside = batch["track_id"][1:] == batch["track_id"][:-1]  # steps within a track
    still = inside & (batch["speed_mps"][:-1] < STATIONARY_MPS)
    per_track = lambda values: np.add.reduceat(np.concatenate([values, [0.0]]), starts)  # noqa: E731  sums from each start
    path = per_track(np.where(inside, step, 0.0))
    duration = batch["t"][ends] - batch["t"][starts]
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_speed = path / duration
    return {"track_id": ids, "frames": counts.astype(np.int64), "first_frame": batch["frame"][starts],
            "last_frame": batch["frame"][ends], "duration_s": duration, "path_length_m": path,
            "mean_speed_mps": mean_speed, "stationary_s": per_track(np.where(still, dt, 0.0))}


def frame_chunks(frames: np.ndarray) -> Iterator[np.ndarray]:
    """Row indices of whole frames, in frame order, at most BATCH_CELLS rows a chunk (a frame holds at most
    MAX_PEOPLE_PER_FRAME < BATCH_CELLS: ``pair_distances`` checks it first)."""
    order = np.argsort(frames, kind="stable")
    _, starts = np.unique(frames[order], return_index=True)
    bounds = np.append(starts, len(order))
    first = 0
    for i in range(1, len(bounds)):
        if i == len(bounds) - 1 or bounds[i + 1] - bounds[first] > BATCH_CELLS:
            yield order[bounds[first]:bounds[i]]
            first = i


def check_people_per_frame(frames: np.ndarray) -> None:
    """ValueError for a frame with more than MAX_PEOPLE_PER_FRAME boxes (frames (N,) int)."""
    numbers, counts = np.unique(frames, return_counts=True)
    if counts.max() > MAX_PEOPLE_PER_FRAME:
        raise ValueError(f"frame {numbers[np.argmax(counts)]} has {counts.max()} people: at most "
                         f"{MAX_PEOPLE_PER_FRAME} a frame for distances (MAX_PEOPLE_PER_FRAME)")


def pair_distances(mapping, frames: np.ndarray, feet: np.ndarray, track_ids: np.ndarray, fps: float, *,
                   click_sigma_px: float = 1.5, point_sigma_px: float | np.ndarray = 1.0
                   ) -> Iterator[dict[str, np.ndarray]]:
    """The ground distance between every two people in the same frame (PAIR_COLUMNS; track_a < track_b), in
    chunks of frames (``frame_chunks``), from the mapped foot points; distance_sigma_m = sqrt(e^T (C_a + C_b) e)
    (delta method, e the unit vector from a to b, C the points' covariances taken as independent: the part of
    the mapping's error the two share, which moves both points alike, is counted twice and the bar errs
    wide). Pairs with a point on or above the horizon have NaN distance. ValueError for a frame with more than
    MAX_PEOPLE_PER_FRAME people."""
    mapping = as_mapping(mapping)
    frames, track_ids = np.asarray(frames, dtype=np.int64), np.asarray(track_ids, dtype=np.int64)
    check_people_per_frame(frames)
    point_sigma_px = check_point_sigma(point_sigma_px, len(frames))
    for rows in frame_chunks(frames):
        rows = rows[np.lexsort((track_ids[rows], frames[rows]))]
        sigma = point_sigma_px if np.ndim(point_sigma_px) == 0 else point_sigma_px[rows]
        xy, cov = map_points(mapping, np.asarray(feet, dtype=np.float64)[rows], click_sigma_px, sigma)
        f, k = frames[rows], track_ids[rows]
        _, starts, n = np.unique(f, return_index=True, return_counts=True)
        a, b = [], []
        for s, m in zip(starts, n):
            i, j = np.triu_indices(m, 1)
            a.append(s + i)
            b.append(s + j)
        a, b = np.concatenate(a).astype(np.int64), np.concatenate(b).astype(np.int64)
        d = xy[b] - xy[a]
        dist = np.hypot(d[:, 0], d[:, 1])
        with np.errstate(invalid="ignore", divide="ignore"):
            e = d / dist[:, None]
        sigma = np.sqrt(np.einsum("ni,nij,nj->n", e, cov[a] + cov[b], e))
        yield {"frame": f[a], "t": f[a] / fps, "track_a": k[a], "track_b": k[b], "distance_m": dist,
               "distance_sigma_m": sigma}

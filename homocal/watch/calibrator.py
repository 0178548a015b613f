"""Watch a camera for moves from the people in view, and keep its horizon calibrated (``OnlineCalibrator``).

Per box (homocal's pixel edges, y1 the head row, y2 the foot row), with the intrinsics K and the camera height
h_c: the horizon row at which a person of the prior's mean height spans that box
(``homocal.correctors.pedestrians.implied_horizon_rows``, the inverse of the pedestrians' implied heights), and
its 1-sigma spread sigma = |dv/dH| sqrt(sd^2 + (mu BOX_SIGMA_PX / p)^2) (the people's height spread sd and a
box edge error of BOX_SIGMA_PX on a box p px tall, as a height error); a box cut by the image border (tested in
the camera's pixels, as PedestrianCorrector.fit does, before a lens's undistortion) is not used, nor a box whose
feet a nearer person's box of the same frame may hide (``homocal.geometry.boxes.hidden_feet``, on all the frame's
boxes, in the camera's pixels): its bottom edge is then the nearer person's outline, above the sole, and its implied
horizon row far below the camera's, by many sigmas (a far person's 2-3 px sigma against an error of 10-25 px). Boxes are linked
into people (tracks: given, or ``TrackLinker``); a person is one observation, the median of its first PERSON_BOXES
boxes' rows with the sigma, column and roll regressor (below) of the median box, given once (one person, one
height: their boxes are not independent).

Roll: a camera rolled by phi (camera.json's sign, as PedestrianCorrector's: > 0 lowers its right side) sees the
unrolled camera's image turned by -phi about the principal point (``pedestrians.derolled_rows``): a point x = u -
cx px right of the principal column is tan(phi) x px higher than the unrolled camera would see it (and its row
scaled by 1 / cos(phi) about cy: second order). A person's foot and head are at different columns x_f and x_t
(a vertical runs to the verticals' vanishing point, row cy + f^2 / (cy - v_h) on the principal column:
x_t / x_f = (that row - v_t) / (that row - v_f)), the box's middle column at (x_f + x_t) / 2. The box's implied
row (computed as if roll 0) is then v = v_0 - tan(phi) w, w = a_f x_f + a_t x_t, to first order in phi, where
v_0 is the horizon's row at the principal column and a_f, a_t the implied row's change per pixel of the foot and
the head row (central differences of implied_horizon_rows): 0.02 sd off per squared degree on people 6 m ahead
of a 4 m camera (tests/watch/test_watch.py), where the horizon line's own slope through the box's middle (w = x)
is more than 0.1 sd off per degree. With lens distortion, the columns and rows are the undistorted box's.

Estimate (``robust_line``): over the last WINDOW_PEOPLE people of the current stretch, the Huber M-estimate of
the line (v_0, tan phi) (psi clipping standardised residuals at +-CLIP) with a scale s (the median absolute
standardised residual / 0.6745, at least 1: a prior sd too small or extra pixel noise is absorbed) and its
sandwich 2x2 covariance; the roll only with estimate_roll and when the people's columns spread over ROLL_SPREAD of
the image width (PedestrianCorrector's rule), else v_0 alone with phi = 0. Its outliers: the people whose implied
row is beyond OUTLIER_SIGMAS of their own sigma from it (PedestrianCorrector.fit's, whose implied heights are beyond
OUTLIER_SIGMAS prior sds at the fitted tilt); where they are more than MAX_OUTLIER_SHARE of its people, the boxes are
not people standing on the ground (a background subtractor's on a moving camera: docs/moving-camera.md) and the
stretch's correction is refused as fit refuses (``stretch_correction``); the estimate and the tests go on.

Change tests: two two-sided CUSUMs (Page 1954) on each new person's standardised residual against the estimate
at the person's column, z = (v - v_0 + tan(phi) w) / sqrt(s^2 sigma^2 + var), var the estimate's variance there,
clipped at +-CLIP (the estimate's own psi) and scaled to unit variance under the normal (u = psi(z) /
SD_CLIPPED). The row test: S+ = max(0, S+ + u - k), S- = max(0, S- - u - k), k = CUSUM_K (the optimal
reference for a shift of 2k = 1 sd per person). The roll test: the same on u g / g_rms, g = w / sqrt(s^2
sigma^2 + var) the person's standardised roll regressor and g_rms its root mean square over the estimate's
people (so the increments have unit variance on a steady camera, and a roll change moves them in proportion to
the person's leverage on the roll: the score of a roll change), with k = tan(ROLL_REF_DEG) g_rms / 2, the optimal
reference for a roll change of ROLL_REF_DEG; it runs with estimate_roll and rests (its statistics 0) while
the roll is not fitted. The row
test sees a change of v_0 (a tilt); the roll test a turn of the horizon about the principal column, which moves
the people on either side oppositely and leaves the row test's mean unchanged. A third, the drift test
(``homocal.watch.drift``), sees a move from the people already in view: each person's implied row along their
walk. A move is declared when a
one-sided statistic exceeds its h, where h gives a mean of (the tests run) x ``arl0_people`` people (the row
test, the roll test with estimate_roll, the drift test unless drift_test=False; the drift test's converted to its
residuals) between false alarms of the test on a steady camera, by Siegmund's
approximation of a one-sided CUSUM's run length (Siegmund 1985, "Sequential analysis"; two sides: half of it):
ARL0 = (exp(theta b) - theta b - 1) / (theta k) / 2, b = h + 1.166 sd (``cusum_threshold``), theta the
increments' tilt, the root of E exp(theta (u - k)) = 1, and sd their root mean square: for normal increments of
unit variance theta = 2 k, sd = 1 and ARL0 = (exp(2 k b) - 2 k b - 1) / (2 k^2) / 2 (Siegmund's own case; the
1.166 is its overshoot, sd-fold for increments sd times as wide). Each side's tilt and sd are those of its
increments on the estimate's own people, about their mean (``Line.increments``: each person's u, or u g / g_rms
for the roll; the sample mean for the expectation: ``tilt``), and its h the larger of theirs and the normal
increments' (the floor keeps the model's, as the scale s keeps 1); h is set so while the statistic is at 0 and
held while it climbs (a move's first people, and the estimate they pull, would widen the tail it measures). A
heavy tail has a smaller tilt: the scale s, from the median absolute residual, does not see it, and the normal's
h would give a false alarm every fifth (at 200 people) or eighth (at 1,000) of ``arl0_people`` people on
residuals of Student's t with 3 degrees of freedom (tests/watch/test_watch.py simulates it), as the rgb detector's
boxes have (research/watch_residuals.py), and sooner on a heavier side (theirs: the horizon above the estimate,
tilt 0.50 against 0.89 below). The tests together then alarm every ``arl0_people``
people or a little less often (1 / ARL0 adds up over independent tests; a run from 0 must first climb, and the
row and roll tests share each person's |z|, which lengthens their joint run: tests/watch/test_watch.py simulates
it). Each person is tested against the estimate of
the people before it, then joins it (a self-starting CUSUM, as Hawkins 1987). A person tells of a roll by
tan(phi) w / sigma sd: a lateral offset X m at a person of height H under a camera h_c high gives about tan(phi)
a X H / (h_c sd), 0.09 sd per metre of X per degree of roll on a 4 m camera (people 1.7 +- 0.09 m), against 1-3
sd per degree of tilt: a roll takes many more people to notice than a tilt (docs/moving-camera.md measures it). At a move, the people since the alarming statistic's last 0 (its change point
estimate; for the row's, averaged over where among them the change is, ``after_change``) give the move's horizon
after (the drift test's: the horizon before plus the step the people in view tell a block
after its alarm, ``DriftTest.alarm``), and the new stretch (from that change point on) starts from their estimate; then
every live track is re-armed: each person in view gives a new observation from their boxes after the
detection, so the stretch fills at once from the people in view, not only from newcomers. The new stretch
holds only such observations (re-armed or new people): the people before the detection are dropped from it,
those who straddle the change point and all others, because the change point is only an estimate (on a
step it is early or late by several people, so some of them saw the camera before the move, and a straddling
person's median is from whichever pose most of their boxes saw), while every box after the detection
saw the moved camera (after a step; a ramp may go on); those still in view give their new observation anyway (one person, one observation),
only those gone are lost. The test re-arms at MIN_PEOPLE people. Memory: the last WINDOW_PEOPLE people of the
stretch, the live tracks of the last LINK_GAP frames (at most MAX_TRACKS, each at most PERSON_BOXES rows) and the
drift test's per live track (an open block and 19 numbers, homocal.watch.drift): bounded whatever the stream's
length; work per box is constant (a move re-arms the live tracks once, and its horizon after is averaged over
at most WINDOW_PEOPLE change points, a line of at most WINDOW_PEOPLE people each: 0.22 s for 200 on a shared 2-core machine, once per move).

A gap in the stream longer than LINK_GAP frames ends every track (a person seen again is a new person): a gap
is a gap, the estimate and the test go on; a move during a gap is found from the people after it.
"""
from __future__ import annotations

import dataclasses
import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from homocal.correctors.pedestrians import (
    DEFAULT_HEIGHT_MEAN_M,
    DEFAULT_HEIGHT_SD_M,
    LINK_GAP,
    MAX_ROLL_DEG,
    OUTLIER_SIGMAS,
    ROLL_SPREAD,
    PedestrianCorrector,
    camera_height_from_homography,
    implied_horizon_rows,
    intrinsics,
    upright_columns,
)
from homocal.boxes import MAX_FPS
from homocal.geometry import ViewTransformer
from homocal.geometry.boxes import (MAX_BOXES_PER_FRAME, TrackLinker, hidden_feet, on_border, short_boxes, trim_boxes,
                                    undistort_boxes)
from homocal.geometry.lens import Lens

WINDOW_PEOPLE = 200  # people in the sliding estimate: the memory bound
MIN_PEOPLE = 20  # people a stretch needs before its estimate is tested
PERSON_BOXES = 5  # a person's observation: the median of its first this many usable boxes
BOX_SIGMA_PX = 1.0  # a box edge's error, px (the per-box sigma's pixel term)
CUSUM_K = 0.5  # the CUSUM's reference value, sd: optimal for a shift of 2 k = 1 sd per person
DEFAULT_ARL0_PEOPLE = 20_000  # mean people between false alarms (about 14 h at scene1's 1,400 people an hour)
CLIP = OUTLIER_SIGMAS  # sd: Huber's psi of the estimate and the test clips standardised residuals here
MAX_TRACKS = 10_000  # live tracks with given ids at most (a stream naming more at once is refused)
TESTS = ("row", "roll", "drift")  # the change tests (module docstring; drift: homocal.watch.drift), each a two-sided CUSUM at (tests run) times arl0_people
ROLL_REF_DEG = 1.0  # degrees: the roll test's reference value is optimal for a roll change of this size


def _clipped_sd(c: float) -> float:
    """The standard deviation of the normal clipped at +-c: E min(Z^2, c^2) = P(|Z| < c) - 2 c phi(c) + 2 c^2 (1 - Phi(c))."""
    inside = math.erf(c / math.sqrt(2))
    phi = math.exp(-c * c / 2) / math.sqrt(2 * math.pi)
    return math.sqrt(inside - 2 * c * phi + c * c * (1 - inside))


SD_CLIPPED = _clipped_sd(CLIP)


def cusum_arl0(h: float, k: float = CUSUM_K, theta: float | None = None, sd: float = 1.0) -> float:
    """Siegmund's approximation of a two-sided CUSUM's mean run length (people) on a steady camera at
    threshold h and reference k, each side's increments (mean 0) of tilt theta (``tilt``; None: 2 k, normal
    increments of unit variance) and root mean square sd (module docstring)."""
    theta = 2 * k if theta is None else theta
    b = theta * (h + 1.166 * sd)
    return (math.exp(b) - b - 1) / (theta * k) / 2 if b < 700 else math.inf  # exp(700): past any arl0_people


def cusum_threshold(arl0_people: float, k: float = CUSUM_K, theta: float | None = None, sd: float = 1.0) -> float:
    """The threshold h at which cusum_arl0(h, k, theta, sd) = arl0_people (bisection on [0, hi], hi doubled from
    100 until it is above it), k > 0."""
    lo, hi = 0.0, 100.0
    while cusum_arl0(hi, k, theta, sd) < arl0_people:
        hi *= 2
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if cusum_arl0(mid, k, theta, sd) < arl0_people else (lo, mid)
    return 0.5 * (lo + hi)


def tilt(x: np.ndarray, k: float) -> float:
    """The tilt of a one-sided CUSUM's increments x (n,) at reference k: the root theta > 0 of mean exp(theta (x - k))
    = 1 (by bisection; 2 k for N(0, 1) increments, 2 k / var for N(0, var)); NaN when there is none (mean x >= k or
    every x <= k)."""
    d = np.asarray(x, dtype=np.float64) - k
    if not d.mean() < 0 < d.max():
        return math.nan
    lo, hi, n = 0.0, 1.0, len(d)
    while np.exp(hi * d).sum() < n:
        lo, hi = hi, 2 * hi
    for _ in range(30):  # to 2^-30 of the bracket
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if np.exp(mid * d).sum() < n else (lo, mid)
    return 0.5 * (lo + hi)


def side_threshold(arl0: float, k: float, x: np.ndarray | None = None) -> float:
    """A one-sided CUSUM's h for a two-sided ARL0 of arl0 at reference k: the normal increments' (cusum_threshold),
    or, where its increments x (n,) (about mean 0; None: none yet) have a tail heavier than the normal's (their tilt
    below 2 k), the larger of that and the h at their tilt and root mean square (module docstring)."""
    h = cusum_threshold(arl0, k)
    theta = math.nan if x is None else tilt(x, k)
    if theta < 2 * k:  # a lighter tail, or NaN, leaves the normal's h the larger
        h = max(h, cusum_threshold(arl0, k, theta, float(np.sqrt(np.mean(x * x)))))
    return h


@dataclass(frozen=True)
class Move:
    """A detected move: t_s the change point estimate (the first person of the new stretch), detected_s when
    the test fired (the drift test: when the step it alarmed on was measured, a block or two later), the horizon row before and after (px, at the principal column) with their 1-sigma, the
    CUSUM statistic and threshold at the alarm, direction +1 (the horizon went down the image; for the roll
    test: on the image's right side) or -1, n_before the people of the estimate before; test, the test that
    fired (one of TESTS); the roll before and after (degrees, camera.json's sign) with their 1-sigma (0 and NaN
    where not fitted: ``robust_line``); n_outliers_before, the people of the estimate before beyond OUTLIER_SIGMAS of
    it (``Line.n_outliers``)."""

    t_s: float
    detected_s: float
    horizon_before: float
    sigma_before: float
    horizon_after: float
    sigma_after: float
    statistic: float
    threshold: float
    direction: int
    n_before: int
    test: str
    roll_before_deg: float
    roll_sigma_before_deg: float
    roll_after_deg: float
    roll_sigma_after_deg: float
    n_outliers_before: int = 0

    def to_dict(self) -> dict:
        """The fields, floats rounded to 6 decimals, a number that is not finite (a roll not fitted) None."""
        return {k: (round(v, 6) if math.isfinite(v) else None) if isinstance(v, float) else v for k, v in self.__dict__.items()}


@dataclass(frozen=True)
class State:
    """The calibrator after an update: t_s (the frame's time), the current stretch's start, the horizon row
    at the principal column and its 1-sigma (px; NaN before any person), the people in its estimate, the row
    test's CUSUM statistics S+ and S- and threshold (the larger of its sides'; NaN while the stretch has fewer than
    MIN_PEOPLE), and the move detected at this update, if any. person_rows / person_sigmas / person_columns: the people observed at
    this update (their implied horizon rows, px, and the column of their box's middle, px). hidden_boxes: how
    many of the boxes measured at this update (of tracks yet to give their person) may have hidden feet (not
    used). roll_deg, roll_sigma_deg: the estimate's roll (degrees, camera.json's sign: the horizon's slope in the
    image is -tan(roll)) and its 1-sigma (0 and NaN where not fitted); cusum_roll_up, cusum_roll_down,
    roll_threshold: the roll test's statistics and threshold (the larger of its sides'; NaN as the row's, and
    while the roll is not fitted).
    person_z: each person's standardised residual z against the estimate before it (module docstring, Change
    tests; NaN while the stretch has fewer than MIN_PEOPLE). cusum_drift_up, cusum_drift_down, drift_threshold: the
    drift test's (homocal.watch.drift; NaN as the row's, and while it has too few residuals). n_outliers: the
    estimate's people beyond OUTLIER_SIGMAS of it (``Line.n_outliers``: beyond MAX_OUTLIER_SHARE of n_people, its
    correction is refused)."""

    t_s: float
    stretch_start_s: float
    horizon_row: float
    horizon_sigma_px: float
    n_people: int
    cusum_up: float
    cusum_down: float
    threshold: float
    move: Move | None
    person_rows: tuple = ()
    person_sigmas: tuple = ()
    hidden_boxes: int = 0
    person_columns: tuple = ()
    roll_deg: float = 0.0
    roll_sigma_deg: float = math.nan
    cusum_roll_up: float = math.nan
    cusum_roll_down: float = math.nan
    roll_threshold: float = math.nan
    person_z: tuple = ()
    cusum_drift_up: float = math.nan
    cusum_drift_down: float = math.nan
    drift_threshold: float = math.nan
    n_outliers: int = 0


def implied_line_terms(boxes: np.ndarray, K: np.ndarray, camera_height_m: float, height_m: float, roll: bool = True):
    """Per box (N, 4) homocal's pixel edges (undistorted), of a person height_m metres tall under a camera with
    intrinsics K (3, 3) camera_height_m metres high: the implied horizon row (N,) px (roll 0:
    pedestrians.implied_horizon_rows) and its change per metre of the person's height (N,) px/m, the roll
    regressor w (N,) px (the row is v_0 - tan(roll) w: module docstring, Roll; NaN without ``roll``) and the box
    middle's column from the principal point (N,) px."""
    f, cy = K[1, 1], K[1, 2]
    rows, slope = implied_horizon_rows(boxes[:, 3], boxes[:, 1], f, cy, camera_height_m, height_m)
    columns = (boxes[:, 0] + boxes[:, 2]) / 2 - K[0, 2]
    if not roll:
        return rows, slope, np.full(len(rows), math.nan), columns
    partial = [implied_horizon_rows(boxes[:, 3] + df, boxes[:, 1] + dt, f, cy, camera_height_m, height_m)[0]
               for df, dt in ((0.5, 0), (-0.5, 0), (0, 0.5), (0, -0.5))]  # the row's change per px of each edge
    foot, head = (x - K[0, 2] for x in upright_columns((boxes[:, 0] + boxes[:, 2]) / 2, boxes[:, 3], boxes[:, 1],
                                                         np.arctan((cy - rows) / f), 0.0, f, (K[0, 2], cy)))
    return rows, slope, (partial[0] - partial[1]) * foot + (partial[2] - partial[3]) * head, columns


@dataclass(frozen=True)
class Line:
    """A stretch's horizon (``robust_line``): row, the horizon's row at the principal column (px), tan_roll (its
    slope in the image is -tan_roll: tan of the roll, camera.json's sign), their covariance cov (2, 2) (px^2, px, 1; only
    cov[0, 0] where the roll is not fitted: tan_roll 0, the rest NaN), scale the robust scale s, roll_rms the
    root mean square of the people's standardised roll regressors w_i / (s sigma_i) (NaN where the roll is not
    fitted: the roll test then rests), increments the change tests' increments on the people (n, 2): the row
    test's u_i = psi(r_i) / SD_CLIPPED and the roll test's u_i g_i / g_rms (NaN where the roll is not fitted;
    None before MIN_PEOPLE; module docstring), n_outliers the people whose implied row is beyond OUTLIER_SIGMAS of
    their own sigma (the prior's, not scaled by s) from the line: PedestrianCorrector.fit's outliers, as the people's
    implied heights beyond OUTLIER_SIGMAS sd of the prior at this horizon."""

    row: float
    tan_roll: float
    cov: np.ndarray
    scale: float
    roll_rms: float = math.nan
    increments: np.ndarray | None = None
    n_outliers: int = 0

    @property
    def roll_k(self) -> float:
        """The roll test's reference value: optimal for a roll change of ROLL_REF_DEG (module docstring)."""
        return 0.5 * math.tan(math.radians(ROLL_REF_DEG)) * self.roll_rms

    @property
    def sigma(self) -> float:
        """The row's 1-sigma, px."""
        return math.sqrt(self.cov[0, 0])

    @property
    def roll_deg(self) -> float:
        return math.degrees(math.atan(self.tan_roll))

    @property
    def roll_sigma_deg(self) -> float:
        """The roll's 1-sigma, degrees (NaN where not fitted)."""
        return math.degrees(math.sqrt(self.cov[1, 1]) / (1 + self.tan_roll ** 2))

    def predicted(self, w: float) -> tuple[float, float]:
        """(implied row, its variance px^2) of a person whose roll regressor is w (px; module docstring)."""
        if not math.isfinite(self.cov[1, 1]):  # no roll fitted: the row, whatever w
            return self.row, self.cov[0, 0]
        return self.row - self.tan_roll * w, self.cov[0, 0] - 2 * w * self.cov[0, 1] + w * w * self.cov[1, 1]


NO_LINE = Line(math.nan, 0.0, np.full((2, 2), math.nan), 1.0)  # before any person


class OnlineCalibrator:
    """The camera's horizon from a stream of people's boxes, its moves, and a correction per stretch
    (module docstring).

    Args:
        K: (3, 3) intrinsics (fx = fy). camera_height_m: the optical centre's height, metres.
        fps: frames per second of the stream (time = frame / fps).
        image_size: (width, height) px; boxes at the border are not used (None: all used, and no roll fitted:
            ROLL_SPREAD is a share of the width). Boxes whose feet a
            nearer person's box may hide are not used either (module docstring).
        height_mean_m, height_sd_m: the prior of people's heights (PedestrianCorrector's).
        arl0_people: the mean number of people between false alarms on a steady camera (the thresholds follow).
        estimate_roll: estimate the roll with the row, and test it (module docstring), when the people spread over
            ROLL_SPREAD of the width (image_size given); otherwise, and by default (PedestrianCorrector's), the
            row alone, roll 0, and the row test alone at arl0_people.
        lens: the camera's lens (homocal.geometry.Lens, the same K and image size: ValueError naming both
            otherwise, Lens.check_matches): update takes the camera's
            pixels, tests the border there (PedestrianCorrector.fit(lens=)'s rule) and then undistorts the boxes
            (undistort_boxes); the horizon rows are then the undistorted image's. None: a pinhole.
        drift_test: run the drift test (homocal.watch.drift: the people already in view; default True) with
            the row test, each at its share of arl0_people; False: the row test (and the roll's) alone.
        box_margin_px: how much taller than their people the boxes are, px in the camera's pixels
            (PedestrianCorrector's box_margin_px, kept in each stretch's correction): half off each box's top and
            bottom edge after the border and hidden-feet tests, before the undistortion; a box no taller is not
            measured.
    """

    def __init__(self, K, camera_height_m: float, fps: float, image_size: tuple[int, int] | None = None,
                 height_mean_m: float = DEFAULT_HEIGHT_MEAN_M, height_sd_m: float = DEFAULT_HEIGHT_SD_M,
                 arl0_people: float = DEFAULT_ARL0_PEOPLE, lens: Lens | None = None, estimate_roll: bool = False,
                 drift_test: bool = True, box_margin_px: float = 0.0) -> None:
        checked = PedestrianCorrector(height_mean_m, height_sd_m, estimate_roll=estimate_roll, box_margin_px=box_margin_px)
        self.estimate_roll, self.box_margin_px = checked.estimate_roll, checked.box_margin_px
        K = intrinsics(None, None, K)
        if not (isinstance(camera_height_m, (int, float)) and 0 < camera_height_m <= 100):
            raise ValueError(f"camera_height_m must be in (0, 100] m, got {camera_height_m!r}")
        if not (isinstance(fps, (int, float)) and 0 < fps <= MAX_FPS):
            raise ValueError(f"fps must be in (0, {MAX_FPS:g}], got {fps!r}")
        if not (isinstance(arl0_people, (int, float)) and 10 <= arl0_people <= 1e9):
            raise ValueError(f"arl0_people must be in [10, 1e9] people, got {arl0_people!r}")
        if not isinstance(drift_test, bool):
            raise ValueError(f"drift_test must be True or False, got {drift_test!r}")
        self.K, self.camera_height_m, self.fps, self.image_size = K, float(camera_height_m), float(fps), image_size
        self.lens = None if lens is None else lens.check_matches(K, image_size)
        self.height_mean_m, self.height_sd_m = float(height_mean_m), float(height_sd_m)
        self.drift_test = drift_test
        self._tests = 1 + self.estimate_roll + drift_test  # the tests run (TESTS): each at this many times arl0_people
        self.arl0_people, self.threshold = float(arl0_people), cusum_threshold(self._tests * arl0_people)
        self._roll_width = ROLL_SPREAD * image_size[0] if self.estimate_roll and image_size is not None else None
        self._linker = TrackLinker(max_gap=LINK_GAP)
        self._tracks: dict[int, list] = {}  # live track id -> [last frame, rows, sigmas, ws, columns] until it gives its person
        self._last_frame: int | None = None
        self._people: deque = deque(maxlen=WINDOW_PEOPLE)  # (t_s, row, sigma, w, column) of the current stretch
        self._since_zero = [0] * 2 * len(TESTS)  # people since each one-sided statistic was last 0
        self._cusum = [0.0] * 2 * len(TESTS)  # row S+, S-, roll S+, S-
        self.stretch_start_s = 0.0
        self.estimate = NO_LINE
        self._h = [self.threshold] * 2 + [math.nan] * 2  # each one-sided statistic's threshold (_threshold)
        self.n_people = 0  # the people behind the estimate
        from homocal.watch.drift import DriftTest  # not at the top: drift imports this module's CUSUM (a cycle)
        self._drift = DriftTest(K, self.camera_height_m, self.fps, self.height_mean_m, self.height_sd_m) if drift_test else None

    # ---- boxes -> people ------------------------------------------------------------------------
    def update(self, frame: int, boxes: np.ndarray, track_ids: np.ndarray | None = None) -> State:
        """Take the boxes (N, 4) homocal's pixel edges (x1, y1, x2, y2) of video frame ``frame`` (int, not before
        the last one; 0 <= N <= MAX_BOXES_PER_FRAME; the camera's pixels) with their track ids (N,) int or None
        (linked by overlap); return the State. ValueError for a frame going backwards, too many boxes, a box not
        finite or upside down, or, in a frame where a box is measured (with the drift test: every frame), beyond
        the lens's fold."""
        if self._last_frame is not None and frame < self._last_frame:
            raise ValueError(f"frame {frame} after frame {self._last_frame}: boxes must come in time order")
        boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
        if len(boxes) > MAX_BOXES_PER_FRAME:
            raise ValueError(f"frame {frame}: {len(boxes):,} boxes, more than {MAX_BOXES_PER_FRAME:,} (the most per "
                             "frame homocal reads)")
        bad = np.flatnonzero(~(np.isfinite(boxes).all(axis=1) & (boxes[:, 3] > boxes[:, 1]) & (boxes[:, 2] > boxes[:, 0])))
        if bad.size:
            raise ValueError(f"frame {frame}: box {boxes[bad[0]].tolist()} is not finite or is upside down or empty")
        if self._last_frame is not None and frame - self._last_frame > LINK_GAP:
            self._tracks.clear()  # a gap ends every track
        self._last_frame = frame
        t = frame / self.fps
        ids = self._linker.link(frame, boxes) if track_ids is None else np.asarray(track_ids, dtype=np.int64)
        tracks = self._tracks
        for key in ids.tolist():  # every box keeps its track alive; only tracks yet to give a person are measured
            tracks.setdefault(key, [frame, [], [], [], []])[0] = frame
        short = short_boxes(boxes, self.box_margin_px)  # no person left in it: not measured
        todo = np.array([i for i, key in enumerate(ids.tolist()) if tracks[key][1] is not None and not short[i]],
                        dtype=np.int64)
        # the people's edges, undistorted where a box is measured: the drift test's every box, else todo's (the
        # lens's cost is mostly per call)
        undistorted = trim_boxes(boxes, self.box_margin_px)
        if self.lens is not None and (self._drift is not None or len(todo)):
            try:
                undistorted = undistort_boxes(undistorted, self.lens)
            except ValueError as e:
                raise ValueError(f"frame {frame}: {e}") from None
        b = undistorted[todo]  # only the boxes still measured: a track's later boxes are skipped
        rows, slope, ws, columns = implied_line_terms(b, self.K, self.camera_height_m, self.height_mean_m,
                                                      self.estimate_roll)
        sigmas = np.abs(slope) * np.hypot(self.height_sd_m, self.height_mean_m * BOX_SIGMA_PX / (b[:, 3] - b[:, 1]))
        usable = np.isfinite(rows) & np.isfinite(sigmas) & (sigmas > 0) & (np.isfinite(ws) | (not self.estimate_roll))
        if self.image_size is not None:  # cut by the frame: in the camera's pixels
            usable &= ~on_border(boxes[todo], self.image_size)
        hidden_all = hidden_feet(boxes, np.zeros(len(boxes), np.int64))
        hidden = hidden_all[todo]
        usable &= ~hidden
        people = []
        for i in np.flatnonzero(usable):
            track = tracks[int(ids[todo[i]])]
            if track[1] is None:  # a second box of the same track in this frame gave it
                continue
            for values, k in ((rows, 1), (sigmas, 2), (ws, 3), (columns, 4)):
                track[k].append(values[i])
            if len(track[1]) == PERSON_BOXES:
                middle = np.argsort(track[1])[PERSON_BOXES // 2]
                people.append((t, *(float(track[k][middle]) for k in (1, 2, 3, 4))))
                track[1:] = [None] * 4  # given: its later boxes are skipped
        for key in [k for k, v in self._tracks.items() if frame - v[0] > LINK_GAP]:
            del self._tracks[key]
        if len(self._tracks) > MAX_TRACKS:
            raise ValueError(f"frame {frame}: more than {MAX_TRACKS} people (tracks) at once")
        move, observed, zs = None, [], []
        if self._drift is not None:
            usable_all = ~hidden_all & ~short
            if self.image_size is not None:  # cut by the frame: in the camera's pixels
                usable_all &= ~on_border(boxes, self.image_size)
            move = self._drift_update(t, frame, ids, undistorted, usable_all, len(people))
        for person in people if move is None else ():
            observed.append(person)
            move, z = self._observe(person)
            zs.append(z)
            if move:  # the tracks are re-armed: this frame's other people give new observations later
                break
        line = self.estimate
        armed = len(self._people) >= MIN_PEOPLE
        stats = self._cusum if armed else [math.nan] * len(self._cusum)
        h = [max(self._h[:2]), max(self._h[2:])]  # each test's: the larger of its sides'
        roll = stats[2:4] + [h[1]] if armed and math.isfinite(h[1]) else [math.nan] * 3
        drift_h = math.nan if self._drift is None else max(self._drift.h)
        drift = stats[4:] + [drift_h] if armed and math.isfinite(drift_h) else [math.nan] * 3
        cx = float(self.K[0, 2])
        return State(t, self.stretch_start_s, line.row, line.sigma, self.n_people, *stats[:2],
                     h[0] if armed else math.nan, move, tuple(p[1] for p in observed),
                     tuple(p[2] for p in observed), int(hidden.sum()), tuple(cx + p[4] for p in observed),
                     line.roll_deg, line.roll_sigma_deg, *roll, tuple(zs), *drift, line.n_outliers)

    def _drift_update(self, t: float, frame: int, ids: np.ndarray, boxes: np.ndarray, usable: np.ndarray,
                      people: int) -> Move | None:
        """The drift test on the frame's boxes (undistorted; usable (N,) bool) at its share of the budget, armed with
        the row test, and its move once its alarm's step is measured (homocal.watch.drift)."""
        drift = self._drift
        drift.people += people
        armed = len(self._people) >= MIN_PEOPLE
        drift.update(t, frame, ids, boxes, usable,
                     self._tests * self.arl0_people * drift.residuals / max(drift.people, 1) if armed else None)
        self._cusum[4:] = drift.cusum
        if drift.alarm is None:
            return None
        i, shift, sigma = drift.alarm
        self._since_zero[4 + i] = max(1, sum(p[0] >= drift.since_zero_s[i] for p in self._people))  # one at least
        move = self._move(4 + i, t, tuple(self._h) + tuple(drift.h))
        if not math.isfinite(shift):  # no one in view told the step: the people since the change point do
            return move
        # the horizon after: the people in view's step (the people since the change point may be few, or one)
        row, sigma = move.horizon_before + shift, math.hypot(move.sigma_before, sigma)
        self.estimate = dataclasses.replace(self.estimate, row=row, tan_roll=0.0, cov=np.diag([sigma ** 2, math.nan]))
        return dataclasses.replace(move, horizon_after=row, sigma_after=sigma)

    # ---- people -> estimate and test ------------------------------------------------------------
    def _observe(self, person: tuple) -> tuple[Move | None, float]:
        """Test the person against the stretch's estimate, then add it (module docstring); the move, if any, and
        the person's standardised residual z (NaN while unarmed)."""
        people = self._people
        armed, z = len(people) >= MIN_PEOPLE, math.nan
        thresholds = tuple(self._h)
        if armed:
            line = self.estimate
            row, var = line.predicted(person[3])
            spread = math.sqrt((line.scale * person[2]) ** 2 + var)
            z = (person[1] - row) / spread
            u = max(-CLIP, min(CLIP, z)) / SD_CLIPPED
            roll = person[3] / spread / line.roll_rms  # NaN while the roll is not fitted: its test rests
            k = (CUSUM_K,) * 2 + (line.roll_k,) * 2
            for i, step in enumerate((u, -u, roll * u, -roll * u)):  # row S+, S-; roll S+, S-
                if math.isfinite(step):
                    self._cusum[i] = max(0.0, self._cusum[i] + step - k[i])
                    self._since_zero[i] = 0 if self._cusum[i] == 0.0 else self._since_zero[i] + 1
        people.append(person)
        over = [i for i in range(len(thresholds)) if self._cusum[i] > thresholds[i]]
        if armed and over:
            return self._move(max(over, key=lambda i: self._cusum[i] / thresholds[i]), person[0], thresholds), z
        line = self.estimate = robust_line(people, self._roll_width)
        self.n_people = len(people)
        if not (math.isfinite(line.roll_rms) and line.roll_rms > 0):  # the roll not fitted: its test rests
            self._cusum[2:4], self._since_zero[2:4] = [0.0, 0.0], [0, 0]
        for i in range(len(self._h)):
            if self._cusum[i] == 0.0:  # held while the statistic climbs
                self._h[i] = self._threshold(i)
        return None, z

    def _threshold(self, i: int) -> float:
        """One-sided statistic i's h (row S+, S-, roll S+, S-; NaN for the roll's while it is not fitted): Siegmund's
        for len(tests) x arl0_people at its test's reference, the larger of the normal increments' and that at the
        tilt and root mean square of its increments on the estimate's people, about their mean (module docstring)."""
        line, test, sign = self.estimate, i // 2, 1 - 2 * (i % 2)
        k = CUSUM_K if test == 0 else line.roll_k
        if not math.isfinite(k):
            return math.nan
        x = None if line.increments is None else sign * (line.increments[:, test] - line.increments[:, test].mean())
        return side_threshold(self._tests * self.arl0_people, k, x)

    def _move(self, i: int, now: float, thresholds: tuple) -> Move:
        """Split the stretch at the alarming statistic's (i) last 0, whose people give the new stretch's first
        estimate; empty the stretch and re-arm every live track (module docstring)."""
        people = list(self._people)
        start = len(people) - min(self._since_zero[i], len(people) - 1)
        before = robust_line(people[:start], self._roll_width)
        first, after = start, robust_line(people[start:], self._roll_width)
        if TESTS[i // 2] != "roll":  # a shift of the row (a roll's moves the people on either side oppositely)
            first, after = after_change(people, start, before, self._roll_width, 1 if i % 2 == 0 else -1)
        move = Move(people[first][0], now, before.row, before.sigma, after.row, after.sigma, self._cusum[i],
                    thresholds[i], 1 if i % 2 == 0 else -1, start, TESTS[i // 2], before.roll_deg,
                    before.roll_sigma_deg, after.roll_deg, after.roll_sigma_deg, before.n_outliers)
        self._people = deque(maxlen=WINDOW_PEOPLE)
        for track in self._tracks.values():
            track[1:] = [[] for _ in range(4)]
        self._since_zero, self._cusum = [0] * len(self._cusum), [0.0] * len(self._cusum)
        self.stretch_start_s, self.estimate, self.n_people = people[first][0], after, len(people) - first
        self._h = [self.threshold] * 2 + [math.nan] * 2  # re-armed at MIN_PEOPLE people (thresholds then)
        if self._drift is not None:
            self._drift.rearm()
        return move

    # ---- corrections ---------------------------------------------------------------------------
    def correction(self, transformer: ViewTransformer, camera_origin=(0.0, 0.0)) -> PedestrianCorrector:
        """The current stretch's correction of a clicked mapping (``stretch_correction`` of the current estimate).
        ValueError before any person."""
        line = self.estimate
        if not math.isfinite(line.row):
            raise ValueError("no person seen yet: no horizon to correct with")
        return stretch_correction(transformer, self, line.row, line.sigma, line.roll_deg, line.roll_sigma_deg,
                                  self.n_people, camera_origin, line.n_outliers)


def stretch_correction(transformer: ViewTransformer, calibrator: OnlineCalibrator, row: float, sigma: float,
                       roll_deg: float, roll_sigma_deg: float, n_people: int, camera_origin=(0.0, 0.0),
                       n_outliers: int = 0) -> PedestrianCorrector:
    """A stretch's correction of a clicked mapping: a PedestrianCorrector (model "camera", the calibrator's prior,
    K and camera height) whose horizon is the row (px at the principal column, 1-sigma sigma; NaN: 0) and,
    where fitted (roll_sigma_deg finite), the roll (degrees) of the stretch's estimate
    (``PedestrianCorrector.from_horizon``); ValueError, as fit refuses, when more than MAX_OUTLIER_SHARE of its
    n_people are outliers (n_outliers: ``Line.n_outliers``)."""
    fitted = math.isfinite(roll_sigma_deg)
    return PedestrianCorrector(calibrator.height_mean_m, calibrator.height_sd_m,
                               box_margin_px=calibrator.box_margin_px).from_horizon(
        transformer, row, sigma if math.isfinite(sigma) else 0.0, calibrator.K, calibrator.camera_height_m,
        n_people, camera_origin, roll_deg if fitted else None, roll_sigma_deg if fitted else 0.0, n_outliers)


def after_change(people, start: int, before: Line, roll_width: float | None, direction: int) -> tuple[int, Line]:
    """The horizon after a change among the people [(t_s, row, sigma_i, w_i, column_i), ...] since the alarming
    statistic's last 0 (0 < start < len(people)), whose change point that 0 only estimates (early by a few people
    who saw the camera before the move, or late): averaged over the change point m >= start, each weighted by the
    likelihood of a common shift of the people from m on in the alarm's direction (+1: down the image) against
    ``before`` (the line of the people before start), exp(L_m / 2), L_m = (sum_i>=m r_i / s_i^2)^2 / sum_i>=m
    1 / s_i^2 where that sum is of the direction's sign (else 0), r_i the person's residual against before and
    s_i^2 = (scale sigma_i)^2 + its variance there: the row the weighted mean of the lines of the people from
    each m (robust_line), its variance the weighted mean of theirs plus their spread about it. (the likeliest m,
    that line with this row and variance; the roll as that line's.) The people since the last 0 alone pull the
    row toward the one before where the 0 is early; the likeliest m alone overshoots on a small step (its own
    people are those who looked shifted): tests/watch/test_watch.py, tests/watch/test_drift.py."""
    r, w = np.zeros(len(people) - start), np.zeros(len(people) - start)
    for k, p in enumerate(people[start:]):
        row, var = before.predicted(p[3])
        r[k], w[k] = direction * (p[1] - row), 1 / ((before.scale * p[2]) ** 2 + var)
    tails, weights = (np.cumsum(x[::-1])[::-1] for x in (w * r, w))  # sums from each person on
    llr = np.maximum(tails, 0.0) ** 2 / weights
    odds = np.exp((llr - llr.max()) / 2)
    odds /= odds.sum()
    lines = [robust_line(people[start + m:], roll_width) for m in range(len(odds))]
    rows, variances = np.array([x.row for x in lines]), np.array([x.cov[0, 0] for x in lines])
    row = float(odds @ rows)
    likeliest = int(np.argmax(odds))
    cov = lines[likeliest].cov.copy()
    cov[0, 0] = float(odds @ (variances + (rows - row) ** 2))
    return start + likeliest, dataclasses.replace(lines[likeliest], row=row, cov=cov)


def robust_line(people, roll_width: float | None = None) -> Line:
    """The horizon line of the people [(t_s, row, sigma_i, w_i, column_i), ...] (module docstring: the implied
    rows v_i = row - tan_roll w_i): the Huber M-estimate whose score is the change tests',
    sum psi(r_i) x_i = 0, r_i = (v_i - x_i . beta) / (s sigma_i), x_i = (1, -w_i), beta = (row, tan_roll), so the
    row test's increments have mean 0 on a steady camera whatever the residuals' skew; by iteratively reweighted
    least squares (20 rounds from the median; a person's weight psi(r) / r / sigma_i). The roll is fitted where
    roll_width (px) is given and the people's columns' interquartile range spans it (PedestrianCorrector's
    ROLL_SPREAD rule), and then believed up to MAX_ROLL_DEG (beyond: not fitted); otherwise tan_roll is 0. From
    MIN_PEOPLE people on, the scale s is the median absolute standardised residual / 0.6745, at least 1 (a sigma
    model that overstates some people's spread, such as the pixel term of boxes without pixel noise, would
    otherwise shrink s and overstate the others' residuals: false alarms), taken at the median start and, with the
    roll, again at the first fit (the start's residuals hold the roll), and the covariance the sandwich
    s^2 B^-1 (sum psi^2 x x^T) B^-1, B = sum psi' x x^T / sigma_i; before, s = 1 (the prior's) and psi(r) = r."""
    v, s, w, col = (np.array([p[k] for p in people]) for k in (1, 2, 3, 4))
    n = len(v)
    roll = roll_width is not None and n >= 3 and np.subtract(*np.percentile(col, [75, 25])) >= roll_width
    X = np.column_stack([np.ones(n), -w]) if roll else np.ones((n, 1))
    beta = np.zeros(X.shape[1])
    beta[0] = float(np.median(v))
    robust, scale = n >= MIN_PEOPLE, 1.0
    for _ in range(1 + roll):
        if robust:
            scale = max(float(np.median(np.abs(v - X @ beta) / s)) / 0.6745, 1.0)
        for _ in range(20):
            r = np.abs(v - X @ beta) / (scale * s)
            weight = np.minimum(1.0, CLIP / np.maximum(r, 1e-12)) / s
            beta = np.linalg.lstsq((X * weight[:, None]).T @ X, (X * weight[:, None]).T @ v, rcond=None)[0]
    if roll and abs(math.degrees(math.atan(beta[1]))) > MAX_ROLL_DEG:
        return robust_line(people)
    r = (v - X @ beta) / (scale * s)
    psi, dpsi = (np.clip(r, -CLIP, CLIP), (np.abs(r) <= CLIP).astype(float)) if robust else (r, np.ones(n))
    bread = (X * (dpsi / s)[:, None]).T @ X
    meat = (X * (psi * psi if robust else np.ones(n))[:, None]).T @ X
    cov = np.full((2, 2), math.nan)
    if np.linalg.matrix_rank(bread) == len(bread):
        inv = np.linalg.inv(bread)
        cov[:len(bread), :len(bread)] = scale ** 2 * inv @ meat @ inv
    else:
        cov[0, 0] = math.inf
    g = w / (scale * s)  # the standardised roll regressors
    line = Line(float(beta[0]), float(beta[1]) if roll else 0.0, cov, scale, float(np.sqrt(np.mean(g ** 2))) if roll else math.nan,
                n_outliers=int(np.sum(np.abs(r) * scale > OUTLIER_SIGMAS)))
    if not robust:
        return line
    u = psi / SD_CLIPPED  # the change tests' increments on these people (OnlineCalibrator._observe)
    return dataclasses.replace(line, increments=np.column_stack([u, u * g / line.roll_rms if roll else np.full(n, math.nan)]))


def camera_of(transformer: ViewTransformer, image_size: tuple[int, int] | None, K=None,
              camera_height_m: float | None = None) -> tuple[np.ndarray, float]:
    """(K (3, 3), camera height m) a watch uses: those given, else from the clicked mapping: the principal point at
    the centre of image_size (px) and the focal length of the mapping (pedestrians.intrinsics), the height of
    ``camera_height_from_homography``. ValueError when neither K nor image_size is given."""
    K = intrinsics(transformer.m, image_size, K)
    return K, camera_height_m if camera_height_m is not None else camera_height_from_homography(transformer.m, K)


def by_frame(frames: np.ndarray, xyxy: np.ndarray, track_ids: np.ndarray | None = None, name: str = "boxes"):
    """Yield (frame, xyxy (n, 4), track ids (n,) or None) per frame of boxes (frames (N,) int, xyxy (N, 4), track_ids
    (N,) or None) in time order, as OnlineCalibrator.update takes them; ValueError naming ``name`` before the first
    frame if a frame goes backwards."""
    back = np.flatnonzero(np.diff(frames) < 0)
    if back.size:
        i = int(back[0]) + 1
        raise ValueError(f"{name}: box {i} (from 0) is in frame {frames[i]} after frame {frames[i - 1]}: boxes out of "
                         "time order (sort them by frame)")

    def frames_():
        starts = np.flatnonzero(np.diff(frames, prepend=-1) != 0)
        for a, b in zip(starts, list(starts[1:]) + [len(frames)]):
            yield int(frames[a]), xyxy[a:b], None if track_ids is None else track_ids[a:b]
    return frames_()

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
boxes' rows with the sigma of the median box, given once (one person, one height: their boxes are not independent).

Estimate: over the last WINDOW_PEOPLE people of the current stretch, the Huber M-estimate of the horizon row
(psi clipping standardised residuals at +-CLIP) with a scale s (the median absolute standardised residual /
0.6745, at least 1: a prior sd too small or extra pixel noise is absorbed) and its sandwich 1-sigma
(``robust_location``).

Change test: a two-sided CUSUM (Page 1954) on each new person's standardised residual against the estimate,
z = (v - mu) / sqrt(s^2 sigma^2 + sigma_mu^2), clipped at +-CLIP (the estimate's own psi) and scaled to
unit variance under the normal (u = psi(z) / SD_CLIPPED): S+ = max(0, S+ + u - k), S- = max(0, S- - u - k),
k = CUSUM_K (the optimal reference for a shift of 2k = 1 sd per person). A move is declared when S+ or S- exceeds h, where h
gives a mean of ``arl0_people`` people between false alarms on a steady camera by Siegmund's approximation
of a one-sided CUSUM's run length (normal increments; Siegmund 1985, "Sequential analysis"; two sides:
half of it): ARL0 = (exp(2 k b) - 2 k b - 1) / (2 k^2) / 2, b = h + 1.166 (``cusum_threshold``).
Each person is tested against the estimate of the people before it, then joins it (a self-starting CUSUM,
as Hawkins 1987). At a move, the people since the alarming statistic's last 0 (its change point estimate) give
the move's horizon after, and the new stretch (from that change point on) starts from their estimate; then
every live track is re-armed: each person in view gives a new observation from their boxes after the
detection, so the stretch fills at once from the people in view, not only from newcomers. The new stretch
holds only such observations (re-armed or new people): the people before the detection are dropped from it,
those who straddle the change point and all others, because the change point is only an estimate (on a
step it is early or late by several people, so some of them saw the camera before the move, and a straddling
person's median is from whichever pose most of their boxes saw), while every box after the detection
saw the moved camera (after a step; a ramp may go on); those still in view give their new observation anyway (one person, one observation),
only those gone are lost. The test re-arms at MIN_PEOPLE people. Memory: the last WINDOW_PEOPLE people of the
stretch and the live tracks of the last LINK_GAP frames (at most MAX_TRACKS, each at most PERSON_BOXES rows):
bounded whatever the stream's length; work per box is constant (a move re-arms the live tracks once).

A gap in the stream longer than LINK_GAP frames ends every track (a person seen again is a new person): a gap
is a gap, the estimate and the test go on; a move during a gap is found from the people after it.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from homocal.correctors.pedestrians import (
    DEFAULT_HEIGHT_MEAN_M,
    DEFAULT_HEIGHT_SD_M,
    LINK_GAP,
    OUTLIER_SIGMAS,
    PedestrianCorrector,
    camera_height_from_homography,
    implied_horizon_rows,
    intrinsics,
)
from homocal.boxes import MAX_FPS
from homocal.geometry import ViewTransformer
from homocal.geometry.boxes import MAX_BOXES_PER_FRAME, TrackLinker, hidden_feet, on_border, undistort_boxes
from homocal.geometry.lens import Lens

WINDOW_PEOPLE = 200  # people in the sliding estimate: the memory bound
MIN_PEOPLE = 20  # people a stretch needs before its estimate is tested
PERSON_BOXES = 5  # a person's observation: the median of its first this many usable boxes
BOX_SIGMA_PX = 1.0  # a box edge's error, px (the per-box sigma's pixel term)
CUSUM_K = 0.5  # the CUSUM's reference value, sd: optimal for a shift of 2 k = 1 sd per person
DEFAULT_ARL0_PEOPLE = 20_000  # mean people between false alarms (about 14 h at scene1's 1,400 people an hour)
CLIP = OUTLIER_SIGMAS  # sd: Huber's psi of the estimate and the test clips standardised residuals here
MAX_TRACKS = 10_000  # live tracks with given ids at most (a stream naming more at once is refused)


def _clipped_sd(c: float) -> float:
    """The standard deviation of the normal clipped at +-c: E min(Z^2, c^2) = P(|Z| < c) - 2 c phi(c) + 2 c^2 (1 - Phi(c))."""
    inside = math.erf(c / math.sqrt(2))
    phi = math.exp(-c * c / 2) / math.sqrt(2 * math.pi)
    return math.sqrt(inside - 2 * c * phi + c * c * (1 - inside))


SD_CLIPPED = _clipped_sd(CLIP)


def cusum_arl0(h: float, k: float = CUSUM_K) -> float:
    """Siegmund's approximation of a two-sided CUSUM's mean run length (people) on a steady camera at
    threshold h and reference k (module docstring)."""
    b = 2 * k * (h + 1.166)
    return (math.exp(b) - b - 1) / (2 * k * k) / 2


def cusum_threshold(arl0_people: float, k: float = CUSUM_K) -> float:
    """The threshold h at which cusum_arl0(h, k) = arl0_people (bisection on [0, 100])."""
    lo, hi = 0.0, 100.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if cusum_arl0(mid, k) < arl0_people else (lo, mid)
    return 0.5 * (lo + hi)


@dataclass(frozen=True)
class Move:
    """A detected move: t_s the change point estimate (the first person of the new stretch), detected_s when
    the test fired, the horizon row before and after (px) with their 1-sigma, the CUSUM statistic and
    threshold at the alarm, direction +1 (the horizon went down the image) or -1, n_before the people of the
    estimate before."""

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

    def to_dict(self) -> dict:
        return {k: (round(v, 6) if isinstance(v, float) else v) for k, v in self.__dict__.items()}


@dataclass(frozen=True)
class State:
    """The calibrator after an update: t_s (the frame's time), the current stretch's start, the horizon row
    and its 1-sigma (px; NaN before any person), the people in its estimate, the CUSUM statistics S+ and S-
    and threshold (NaN while the stretch has fewer than MIN_PEOPLE), and the move detected at this update, if
    any. person_rows / person_sigmas: the people observed at this update (their implied horizon rows, px).
    hidden_boxes: how many of the boxes measured at this update (of tracks yet to give their person) may have
    hidden feet (not used)."""

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


class OnlineCalibrator:
    """The camera's horizon from a stream of people's boxes, its moves, and a correction per stretch
    (module docstring).

    Args:
        K: (3, 3) intrinsics (fx = fy). camera_height_m: the optical centre's height, metres.
        fps: frames per second of the stream (time = frame / fps).
        image_size: (width, height) px; boxes at the border are not used (None: all used). Boxes whose feet a
            nearer person's box may hide are not used either (module docstring).
        height_mean_m, height_sd_m: the prior of people's heights (PedestrianCorrector's).
        arl0_people: the mean number of people between false alarms on a steady camera (the threshold follows).
        lens: the camera's lens (homocal.geometry.Lens, the same K and image size: ValueError naming both
            otherwise, Lens.check_matches): update takes the camera's
            pixels, tests the border there (PedestrianCorrector.fit(lens=)'s rule) and then undistorts the boxes
            (undistort_boxes); the horizon rows are then the undistorted image's. None: a pinhole.
    """

    def __init__(self, K, camera_height_m: float, fps: float, image_size: tuple[int, int] | None = None,
                 height_mean_m: float = DEFAULT_HEIGHT_MEAN_M, height_sd_m: float = DEFAULT_HEIGHT_SD_M,
                 arl0_people: float = DEFAULT_ARL0_PEOPLE, lens: Lens | None = None) -> None:
        PedestrianCorrector(height_mean_m, height_sd_m)  # the prior's checks
        K = intrinsics(None, None, K)
        if not (isinstance(camera_height_m, (int, float)) and 0 < camera_height_m <= 100):
            raise ValueError(f"camera_height_m must be in (0, 100] m, got {camera_height_m!r}")
        if not (isinstance(fps, (int, float)) and 0 < fps <= MAX_FPS):
            raise ValueError(f"fps must be in (0, {MAX_FPS:g}], got {fps!r}")
        if not (isinstance(arl0_people, (int, float)) and 10 <= arl0_people <= 1e9):
            raise ValueError(f"arl0_people must be in [10, 1e9] people, got {arl0_people!r}")
        self.K, self.camera_height_m, self.fps, self.image_size = K, float(camera_height_m), float(fps), image_size
        self.lens = None if lens is None else lens.check_matches(K, image_size)
        self.height_mean_m, self.height_sd_m = float(height_mean_m), float(height_sd_m)
        self.arl0_people, self.threshold = float(arl0_people), cusum_threshold(arl0_people)
        self._linker = TrackLinker(max_gap=LINK_GAP)
        self._tracks: dict[int, list] = {}  # live track id -> [last frame, rows, sigmas] until it gives its person
        self._last_frame: int | None = None
        self._people: deque = deque(maxlen=WINDOW_PEOPLE)  # (t_s, row, sigma) of the current stretch
        self._since_zero = [0, 0]  # people since S+, S- were last 0
        self._cusum = [0.0, 0.0]
        self.stretch_start_s = 0.0
        self.estimate = (math.nan, math.nan, 1.0)  # horizon row, sigma, scale s
        self.n_people = 0  # the people behind the estimate

    # ---- boxes -> people ------------------------------------------------------------------------
    def update(self, frame: int, boxes: np.ndarray, track_ids: np.ndarray | None = None) -> State:
        """Take the boxes (N, 4) homocal's pixel edges (x1, y1, x2, y2) of video frame ``frame`` (int, not before
        the last one; 0 <= N <= MAX_BOXES_PER_FRAME; the camera's pixels) with their track ids (N,) int or None
        (linked by overlap); return the State. ValueError for a frame going backwards, too many boxes, a box not
        finite or upside down, or beyond the lens's fold."""
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
            tracks.setdefault(key, [frame, [], []])[0] = frame
        todo = np.array([i for i, key in enumerate(ids.tolist()) if tracks[key][1] is not None], dtype=np.int64)
        try:  # only the boxes still measured: a track's later boxes are skipped, undistorted or not
            b = boxes[todo] if self.lens is None else undistort_boxes(boxes[todo], self.lens)
        except ValueError as e:
            raise ValueError(f"frame {frame}: {e}") from None
        rows, slope = implied_horizon_rows(b[:, 3], b[:, 1], self.K[1, 1], self.K[1, 2], self.camera_height_m,
                                           self.height_mean_m)
        sigmas = np.abs(slope) * np.hypot(self.height_sd_m, self.height_mean_m * BOX_SIGMA_PX / (b[:, 3] - b[:, 1]))
        usable = np.isfinite(rows) & np.isfinite(sigmas) & (sigmas > 0)
        if self.image_size is not None:  # cut by the frame: in the camera's pixels
            usable &= ~on_border(boxes[todo], self.image_size)
        hidden = hidden_feet(boxes, np.zeros(len(boxes), np.int64))[todo] if todo.size else np.zeros(0, bool)
        usable &= ~hidden
        people = []
        for i in np.flatnonzero(usable):
            track = tracks[int(ids[todo[i]])]
            if track[1] is None:  # a second box of the same track in this frame gave it
                continue
            track[1].append(rows[i])
            track[2].append(sigmas[i])
            if len(track[1]) == PERSON_BOXES:
                middle = np.argsort(track[1])[PERSON_BOXES // 2]
                people.append((t, float(track[1][middle]), float(track[2][middle])))
                track[1] = track[2] = None  # given: its later boxes are skipped
        for key in [k for k, v in self._tracks.items() if frame - v[0] > LINK_GAP]:
            del self._tracks[key]
        if len(self._tracks) > MAX_TRACKS:
            raise ValueError(f"frame {frame}: more than {MAX_TRACKS} people (tracks) at once")
        move, observed = None, []
        for person in people:
            observed.append(person)
            move = self._observe(person)
            if move:  # the tracks are re-armed: this frame's other people give new observations later
                break
        row, sigma, _ = self.estimate
        armed = len(self._people) >= MIN_PEOPLE
        return State(t, self.stretch_start_s, row, sigma, self.n_people,
                     *(self._cusum if armed else (math.nan, math.nan)), self.threshold if armed else math.nan, move,
                     tuple(p[1] for p in observed), tuple(p[2] for p in observed), int(hidden.sum()))

    # ---- people -> estimate and test ------------------------------------------------------------
    def _observe(self, person: tuple[float, float, float]) -> Move | None:
        """Test the person against the stretch's estimate, then add it (module docstring)."""
        people = self._people
        armed = len(people) >= MIN_PEOPLE
        if armed:
            row, sigma, scale = self.estimate
            z = (person[1] - row) / math.hypot(scale * person[2], sigma)
            u = max(-CLIP, min(CLIP, z)) / SD_CLIPPED
            for side, step in enumerate((u, -u)):
                self._cusum[side] = max(0.0, self._cusum[side] + step - CUSUM_K)
                self._since_zero[side] = 0 if self._cusum[side] == 0.0 else self._since_zero[side] + 1
        people.append(person)
        side = int(np.argmax(self._cusum))
        if armed and self._cusum[side] > self.threshold:
            return self._move(side, person[0])
        self.estimate, self.n_people = robust_location(people), len(people)
        return None

    def _move(self, side: int, now: float) -> Move:
        """Split the stretch at the alarming statistic's last 0, whose people give the new stretch's first estimate;
        empty the stretch and re-arm every live track (module docstring)."""
        people = list(self._people)
        start = len(people) - min(self._since_zero[side], len(people) - 1)
        before, after = robust_location(people[:start]), robust_location(people[start:])
        move = Move(people[start][0], now, before[0], before[1], after[0], after[1], self._cusum[side], self.threshold,
                    1 if side == 0 else -1, start)
        self._people = deque(maxlen=WINDOW_PEOPLE)
        for track in self._tracks.values():
            track[1], track[2] = [], []
        self._since_zero, self._cusum = [0, 0], [0.0, 0.0]
        self.stretch_start_s, self.estimate, self.n_people = people[start][0], after, len(people) - start
        return move

    # ---- corrections ---------------------------------------------------------------------------
    def correction(self, transformer: ViewTransformer, camera_origin=(0.0, 0.0)) -> PedestrianCorrector:
        """The current stretch's correction of a clicked mapping: a PedestrianCorrector (model "camera") whose
        horizon is the current estimate (``PedestrianCorrector.from_horizon``). ValueError before any person."""
        row, sigma, _ = self.estimate
        if not math.isfinite(row):
            raise ValueError("no person seen yet: no horizon to correct with")
        return PedestrianCorrector(self.height_mean_m, self.height_sd_m).from_horizon(
            transformer, row, sigma, self.K, self.camera_height_m, self.n_people, camera_origin)


def robust_location(people) -> tuple[float, float, float]:
    """(row, 1-sigma, scale) of the people [(t_s, row, sigma_i), ...]: the Huber M-estimate whose score is the
    change test's, sum psi((v_i - row) / (s sigma_i)) = 0 (so the test's increments have mean 0 on a steady
    camera whatever the residuals' skew), by iteratively reweighted least squares (20 rounds from the median; a
    person's weight psi(r) / r / sigma_i). From MIN_PEOPLE people on, the scale s is the median absolute
    standardised residual / 0.6745, at least 1 (a sigma model that overstates some people's spread, such as
    the pixel term of boxes without pixel noise, would otherwise shrink s and overstate the others' residuals:
    false alarms), and the 1-sigma the sandwich s sqrt(sum psi^2) / sum (psi' / sigma_i); before, s = 1 (the
    prior's) and the 1-sigma sqrt(n) / sum (1 / sigma_i)."""
    v = np.array([p[1] for p in people])
    s = np.array([p[2] for p in people])
    mu = float(np.median(v))
    scale = max(float(np.median(np.abs(v - mu) / s)) / 0.6745, 1.0) if len(v) >= MIN_PEOPLE else 1.0
    for _ in range(20):
        r = np.abs(v - mu) / (scale * s)
        weight = np.minimum(1.0, CLIP / np.maximum(r, 1e-12)) / s
        mu = float(np.sum(weight * v) / np.sum(weight))
    if len(v) < MIN_PEOPLE:  # too few for the sandwich: the model's own sigma
        return mu, math.sqrt(len(v)) / float(np.sum(1.0 / s)), scale
    r = (v - mu) / (scale * s)
    psi, dpsi = np.clip(r, -CLIP, CLIP), (np.abs(r) <= CLIP).astype(float)
    bread = float(np.sum(dpsi / s))
    return mu, (scale * math.sqrt(float(np.sum(psi * psi))) / bread if bread > 0 else math.inf), scale


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

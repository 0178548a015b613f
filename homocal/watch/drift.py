"""The within-person change test (``DriftTest``): a move seen by the people already in view.

A person's implied horizon row (the row at which a person of the prior's height spans the box,
``pedestrians.implied_horizon_rows``) is off the camera's horizon by their own height's error dH times the row's
change per metre of height, x = dv/dH, which grows with the person's distance: along a walk toward or away from the
camera it drifts (a person 0.09 m off the prior drifts by 0.09 (x_far - x_near) px: several times the boxes' own
noise, research/watch_drift.py), so a person's blocks are fitted with their own height: m_j = c + x_j dH, c the
horizon row the person sees, dH ~ N(0, height_sd^2) the prior (c flat). A move shifts c.

Per live track, its usable boxes (the calibrator's: not cut by the border, feet not hidden) are taken in blocks
of BLOCK_S seconds (at most MAX_BLOCK_BOXES boxes); a block of fewer than half its frames' boxes is dropped. A
block j gives m_j, x_j and g_j, the medians of its boxes' implied rows, their slopes and their edge gains
(``edge_gains``: px of implied row per px of both box edges' error, the root sum of squares of the row's change
per px of the foot and of the head row). Its sd is s g_j, s the blocks' edge noise (px), one for the stream.
Block k >= 2's recursive residual (Hawkins 1987's self-starting residual; the predictive one of a regression
with a prior) against the weighted least squares fit of the person's earlier blocks (weights 1 / g_j^2, rows
(1, x_j)) with the prior's precision s^2 / height_sd^2 on dH is

    e_k = (m_k - (1, x_k) beta) / sqrt(g_k^2 + (1, x_k) A^-1 (1, x_k)^T),  A = sum_j<k (1, x_j)^T (1, x_j) / g_j^2
          + diag(0, s^2 / height_sd^2),  beta = A^-1 sum_j<k (1, x_j)^T m_j / g_j^2,

in units of s: under no change and independent blocks of normal noise the e_k / s are independent unit normals
(the person's height is fitted; the prior makes the second block's residual exist), and after a step of D px of
horizon every person in view gives residuals of about D / (s g_k). A track keeps its last frame, its open block
(at most MAX_BLOCK_BOXES boxes' three numbers), six numbers (A's three, the two sums of m, its block count), the
same six for each side as they stood when the side's statistic was last 0 (its blocks before the change point
estimate: those whose place in the stream, their residual's, is not after the last 0, which may fall between two
residuals of one frame) and its last block's place: bounded memory.

s is the stream's own: the median absolute e over the last WINDOW residuals / 0.6745, at least BOX_SIGMA_PX (the
calibrator's box edge error; as its scale is at least the model's: the segmentation boxes' median residual is
a fifth of a pixel, their pixel quantisation, which a walk's slow changes exceed, research/watch_drift.py). The test: a two-sided CUSUM (Page 1954) on u = psi(e / s) / SD_CLIPPED (clipped at +-CLIP, unit variance
under the normal), the row test's, with its reference CUSUM_K; each side's h by Siegmund's general form at the
tilt and root mean square of that side's increments over the window (``calibrator.side_threshold``), set while
the side's statistic is at 0 (at most every REFRESH residuals: the work) and held while it climbs. Its false-alarm budget is the row test's in people: it
runs at n_tests x arl0_people people, converted to its own residuals by the stream's residuals per person
(counted on the stream: ``people`` is the calibrator's count), so that the tests together alarm every arl0_people people (1 / ARL0 adds over the
tests). Its statistic runs from the first residual (at the scale of the residuals so far), so that its last 0 dates
a change that came before the test was armed (the fits before it are then the people's before the change, not
before the arming: tests/watch/test_drift.py); it is armed, its h set and an alarm possible, once the window holds
MIN_RESIDUALS residuals and the stretch MIN_PEOPLE people; at a move
(any test's) every track's blocks are forgotten (the calibrator's re-arming), the window and counts kept.

The step's size (``alarm``): when a side's statistic exceeds its h at t_a, every track's open block is dropped and
a new one starts; the move is declared once these close (BLOCK_S later: the step is then told by blocks that saw
only the moved camera; once each person in view has told it or gone, 2 BLOCK_S at most), each giving one
prediction error: their first block after t_a against the
fit of their blocks before the side's statistic last left 0 (the change point estimate), r = D + s' q N(0, 1)
for a step of D px, s' the window's spread (s without its floor: the CUSUM's scale keeps at least the model's
BOX_SIGMA_PX, which would overstate the step's sigma where the blocks' noise is below it). The step is their
weighted mean (weights 1 / (s' q)^2), its sigma that of the mean, widened by
the square root of their chi-square per degree of freedom where it exceeds 1 (Birge's ratio: people who disagree
more than their noise allows). Neither the blocks that close while the statistic climbs (they may straddle the
step: a block half before it tells half of it) nor a person's later blocks (their fit has absorbed part of the
step) enter it: each would bias the step short (tests/watch/test_drift.py). The statistics rest meanwhile.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from homocal.correctors.pedestrians import implied_horizon_rows
from homocal.watch.calibrator import BOX_SIGMA_PX, CLIP, CUSUM_K, SD_CLIPPED, side_threshold

BLOCK_S = 2.0  # seconds of a track's boxes in one block (research/watch_drift.py)
MAX_BLOCK_BOXES = 64  # boxes in one block at most: a block closes at BLOCK_S or at this many boxes
WINDOW = 400  # the last residuals giving the scale s and the threshold's tilt
MIN_RESIDUALS = 100  # residuals in the window before the test is armed
REFRESH = 20  # a side's h is recomputed at 0 once this many residuals have joined the window since (the work)


def edge_gains(boxes: np.ndarray, K: np.ndarray, camera_height_m: float, height_m: float):
    """Per box (N, 4) homocal's pixel edges (undistorted): the implied horizon row (N,) px (roll 0:
    pedestrians.implied_horizon_rows), its change per metre of the person's height x (N,) px/m, and its edge
    gain (N,): the root sum of squares of its change per px of the foot and of the head row (central
    differences), px per px."""
    f, cy = K[1, 1], K[1, 2]
    rows, slopes = implied_horizon_rows(boxes[:, 3], boxes[:, 1], f, cy, camera_height_m, height_m)
    foot, head = (implied_horizon_rows(boxes[:, 3] + df, boxes[:, 1] + dt, f, cy, camera_height_m, height_m)[0]
                  - implied_horizon_rows(boxes[:, 3] - df, boxes[:, 1] - dt, f, cy, camera_height_m, height_m)[0]
                  for df, dt in ((0.5, 0.0), (0.0, 0.5)))
    return rows, slopes, np.hypot(foot, head)


def block_residual(sums: np.ndarray, m: float, x: float, g: float, prior: float) -> tuple[float, float] | None:
    """A person's block (implied row m px, its slope x px/m, edge gain g) against the fit of their earlier blocks:
    (r, q), the prediction error r = m - (1, x) beta px and its sd in units of s, q = sqrt(g^2 + (1, x) A^-1 (1,
    x)^T), whose ratio is the recursive residual e (module docstring; None for their first block), prior the
    precision s^2 / height_sd^2 on dH; then the block joins the fit's sums (6,): (sum w, sum w x, sum w x^2, sum w
    m, sum w x m, blocks), w = 1 / g^2, updated in place."""
    e = None
    if sums[5]:
        inv = np.linalg.inv(np.array([[sums[0], sums[1]], [sums[1], sums[2] + prior]]))
        v = np.array([1.0, x])
        e = (float(m - v @ inv @ sums[3:5]), math.sqrt(g * g + v @ inv @ v))
    w = 1 / g ** 2
    sums += (w, w * x, w * x * x, w * m, w * x * m, 1.0)
    return e


@dataclass
class _Track:
    """A live track's state: bounded (an open block and 19 numbers)."""

    last_frame: int
    block_start_s: float
    last_block_at: int  # DriftTest.residuals when its last block closed
    block: list = field(default_factory=list)  # the open block's (m, x, g), at most MAX_BLOCK_BOXES
    sums: np.ndarray = field(default_factory=lambda: np.zeros(6))  # the fit of its closed blocks (block_residual)
    sums_at_zero: np.ndarray = field(default_factory=lambda: np.zeros((2, 6)))  # sums as at each side's last 0

    def keep_sums_before(self, side: int, zero: int, before: np.ndarray | None = None, before_at: int = 0) -> None:
        """Hold the fit as the side's change point estimate (its last 0, a place in the stream) sees it: the fit of
        every block so far if the last is before it, else (before: the sums before the last block, which closed
        in this frame, the one before it at before_at) the fit without the last block if that is."""
        if self.last_block_at <= zero:
            self.sums_at_zero[side] = self.sums
        elif before is not None and before_at <= zero:
            self.sums_at_zero[side] = before


@dataclass
class _Alarm:
    """A side's alarm at t_s while its step is measured: the people's weighted prediction errors' sums."""

    side: int
    t_s: float
    w: float = 0.0
    wr: float = 0.0
    wrr: float = 0.0
    people: int = 0

    def add(self, r: float, w: float) -> None:
        self.w, self.wr, self.wrr, self.people = self.w + w, self.wr + w * r, self.wrr + w * r * r, self.people + 1

    def step(self) -> tuple[int, float, float]:
        """(side, the step px: the weighted mean, its sigma widened by Birge's ratio where above 1); NaN for none."""
        if not self.people:
            return self.side, math.nan, math.nan
        step = self.wr / self.w
        birge = (self.wrr - step * self.wr) / (self.people - 1) if self.people > 1 else 1.0
        return self.side, step, math.sqrt(max(1.0, birge) / self.w)


class DriftTest:
    """The within-person change test (module docstring) of a stream at fps frames per second, under a camera of
    intrinsics K (3, 3) camera_height_m high, people's heights height_mean_m +- height_sd_m (the calibrator's)."""

    def __init__(self, K: np.ndarray, camera_height_m: float, fps: float, height_mean_m: float, height_sd_m: float,
                 block_s: float = BLOCK_S) -> None:
        self.K, self.camera_height_m, self.height_mean_m = K, camera_height_m, height_mean_m
        self.fps, self.block_s, self.height_sd_m = float(fps), float(block_s), float(height_sd_m)
        self._least = max(1, math.ceil(block_s * fps / 2))  # boxes a block needs
        self._tracks: dict[int, _Track] = {}
        self.window: deque = deque(maxlen=WINDOW)  # the last residuals e (units of s)
        self.residuals = self.people = 0  # the stream's residuals and people (the budget's conversion)
        self.rearm()

    def rearm(self) -> None:
        """Forget every track's blocks and the statistics (at a move); the window and the counts stay."""
        self._tracks.clear()
        self.cusum, self.h = [0.0, 0.0], [math.nan, math.nan]  # S+, S- and their thresholds
        self._set = [-REFRESH, -REFRESH]  # self.residuals when each h was last set
        self.since_zero_s = [math.nan, math.nan]  # the time each side last left 0
        self._zero = [self.residuals] * 2  # self.residuals when each side was last 0
        self._alarm: _Alarm | None = None  # while the step is measured
        self.alarm: tuple[int, float, float] | None = None  # (side, step px, its sigma) once measured

    @property
    def spread(self) -> float:
        """The window's median absolute residual / 0.6745 (px; NaN while empty): the blocks' edge noise."""
        return float(np.median(np.abs(self.window))) / 0.6745 if self.window else math.nan

    @property
    def scale(self) -> float:
        """s: the spread, at least BOX_SIGMA_PX (px; that while empty)."""
        return max(self.spread, BOX_SIGMA_PX) if self.window else BOX_SIGMA_PX

    def update(self, t: float, frame: int, ids, boxes: np.ndarray, usable: np.ndarray,
               arl0: float | None) -> list[tuple[int, float]]:
        """Take a frame's boxes (N, 4) (homocal's pixel edges, undistorted; track ids (N,), usable (N,) bool) at
        time t s; advance the CUSUM on each closed block's residual when armed (arl0: the test's ARL0 in
        residuals; None: unarmed) and return those residuals (``e``, units of s) with their track ids. After an
        alarm, ``alarm`` is set once its step is measured (module docstring)."""
        out, closed = [], []
        rows, slopes, gains = edge_gains(boxes, self.K, self.camera_height_m, self.height_mean_m)
        ok = usable & np.isfinite(rows) & np.isfinite(slopes) & np.isfinite(gains) & (gains > 0)
        for i in np.flatnonzero(ok):
            key = int(ids[i])
            track = self._tracks.setdefault(key, _Track(frame, t, self.residuals))
            if t - track.block_start_s >= self.block_s or len(track.block) >= MAX_BLOCK_BOXES:
                if self._alarm is None:
                    before = track.sums.copy()
                    rq = self._close(track)
                    if rq is not None:
                        out.append((key, *rq))
                    closed.append((track, before, self.residuals + len(out)))  # its place: after its residual
                elif self._told(track):  # the step: its first block after the alarm, once
                    self._measure(track)
                track.block_start_s, track.block = t, []
            track.last_frame = frame
            track.block.append((rows[i], slopes[i], gains[i]))
        for key in [k for k, v in self._tracks.items() if frame - v.last_frame > self.fps * self.block_s]:
            del self._tracks[key]  # gone (or hidden) for a block's time
        for _, r, q in out:
            self._step(t, r, q, arl0)
        for track, before, place in closed:  # the statistic may have last been 0 between its blocks
            before_at, track.last_block_at = track.last_block_at, place
            for side in (0, 1):
                track.keep_sums_before(side, self._zero[side], before, before_at)
        if self._alarm is None:
            over = [i for i in (0, 1) if self.cusum[i] > self.h[i]]
            if over:  # every track's next block starts after the alarm
                self._alarm = _Alarm(max(over, key=lambda i: self.cusum[i] / self.h[i]), t)
                for track in self._tracks.values():
                    track.keep_sums_before(self._alarm.side, self._zero[self._alarm.side])
                    track.block_start_s, track.block = t, []
        elif self.alarm is None and (t - self._alarm.t_s >= 2 * self.block_s
                                     or not any(self._told(track) for track in self._tracks.values())):
            self.alarm = self._alarm.step()
        return [(key, r / q) for key, r, q in out]

    def _told(self, track: _Track) -> bool:
        """Whether the track has yet to tell the alarm's step: it has blocks before the change point estimate."""
        return bool(track.sums_at_zero[self._alarm.side][5])

    def _close(self, track: _Track) -> tuple[float, float] | None:
        """Close the track's open block (None for a block too thin): ``block_residual`` of its medians."""
        if len(track.block) < self._least:
            return None
        return block_residual(track.sums, *np.median(np.array(track.block), axis=0), (self.scale / self.height_sd_m) ** 2)

    def _measure(self, track: _Track) -> None:
        """The step from the track's first block after the alarm: its prediction error r against its blocks
        before the alarming side's last 0 (the fit's sums then, left unchanged), weight 1 / (spread q)^2."""
        base = track.sums_at_zero[self._alarm.side]
        if len(track.block) < self._least:
            return
        r, q = block_residual(base.copy(), *np.median(np.array(track.block), axis=0), (self.scale / self.height_sd_m) ** 2)
        self._alarm.add(r, 1 / (self.spread * q) ** 2)
        base[:] = 0.0  # once

    def _step(self, t: float, r: float, q: float, arl0: float | None) -> None:
        """One residual e = r / q: standardise by the window's scale, advance the CUSUM (its h set once armed: arl0
        not None and the window full to MIN_RESIDUALS), then join the window."""
        e, s = r / q, self.scale
        u = max(-CLIP, min(CLIP, e / s)) / SD_CLIPPED
        armed = arl0 is not None and len(self.window) >= MIN_RESIDUALS
        for i, step in enumerate((u, -u)):
            if self.cusum[i] == 0.0:
                self.since_zero_s[i] = t
            # h: set at arming, then while at 0 (every REFRESH residuals), held while it climbs
            if armed and (math.isnan(self.h[i]) or self.cusum[i] == 0.0 and not self.residuals - self._set[i] < REFRESH):
                x = np.clip(np.array(self.window) / s, -CLIP, CLIP) / SD_CLIPPED
                self.h[i], self._set[i] = side_threshold(arl0, CUSUM_K, (1 - 2 * i) * (x - x.mean())), self.residuals
            self.cusum[i] = max(0.0, self.cusum[i] + step - CUSUM_K)
        self.window.append(e)
        self.residuals += 1
        for i in (0, 1):
            if self.cusum[i] == 0.0:
                self._zero[i] = self.residuals

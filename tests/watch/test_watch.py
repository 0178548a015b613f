"""homocal.watch: the per-box implied horizon, the CUSUM's threshold, OnlineCalibrator on synthetic streams from a
PinholeCamera whose tilt or roll changes, and the homocal watch / apply --at commands."""
import dataclasses
import io
import json
import math

import numpy as np
import pyarrow.parquet as pq
import pytest
from cli_run import homocal_main
from scipy import integrate, optimize, stats

from homocal.correctors.base import load_corrector
from homocal.correctors.pedestrians import implied_heights, implied_horizon_rows
from homocal.geometry import PinholeCamera
from homocal.geometry.boxes import TrackLinker, link_tracks
from homocal.geometry.lens import Lens
from homocal.watch import OnlineCalibrator
from homocal.watch.calibrator import (
    CLIP,
    CUSUM_K,
    MIN_PEOPLE,
    SD_CLIPPED,
    TESTS,
    WINDOW_PEOPLE,
    after_change,
    cusum_arl0,
    cusum_threshold,
    implied_line_terms,
    robust_line,
    tilt,
)

CAM = PinholeCamera()  # 1280x720, 95 degrees, 4 m high, tilted 15 degrees down
FPS = 5
GROUND = np.array([[-3.5, 30.0], [3.5, 30.0], [3.5, 8.0], [-3.5, 8.0]])


def stream(seconds, tilt=lambda t: 0.0, rate=1.5, seed=0, noise_px=0.3, roll=lambda t: 0.0, side=6.0, dof=None,
           heights=None):
    """Frames (frame, xyxy (N, 4) homocal edges, track ids) of people 1.70 +- 0.07 m tall (normal; with dof, 1.70
    m plus 0.07 m times Student's t of dof degrees of freedom; heights(rng, n): theirs) standing 1 s each at random places 8-45 m ahead and
    up to ``side`` m to either side, arriving at ``rate`` a second, seen by CAM tilted tilt(t) degrees further down
    and rolled by roll(t) degrees; their foot and head points projected exactly, the box spanning both columns,
    each box edge plus normal noise of noise_px."""
    rng = np.random.default_rng(seed)
    n = int(seconds * rate)
    start = np.sort(rng.uniform(0, seconds - 1, n))
    xy = np.column_stack([rng.uniform(-side, side, n), rng.uniform(8, 45, n)])
    height = 1.70 + 0.07 * (rng.standard_normal(n) if dof is None else rng.standard_t(dof, n))
    height = height if heights is None else heights(rng, n)
    for frame in range(int(seconds * FPS)):
        t = frame / FPS
        cam = dataclasses.replace(CAM, tilt_deg=CAM.tilt_deg + tilt(t), roll_deg=roll(t))
        on = np.flatnonzero((start <= t) & (t < start + 1))
        foot = cam.project(np.column_stack([xy[on], np.zeros(len(on))]))
        head = cam.project(np.column_stack([xy[on], height[on]]))
        half = 0.25 * cam.focal_px / xy[on, 1]
        boxes = np.column_stack([np.minimum(foot[:, 0], head[:, 0]) - half, head[:, 1],
                                 np.maximum(foot[:, 0], head[:, 0]) + half, foot[:, 1]])
        yield frame, boxes + rng.normal(0, noise_px, boxes.shape), on


def horizon(tilt_deg, roll_deg=0.0):
    """The horizon's row at the principal column (px) of CAM tilted tilt_deg further down and rolled roll_deg
    (its horizon line a u + b v + c = 0)."""
    a, b, c = dataclasses.replace(CAM, tilt_deg=CAM.tilt_deg + tilt_deg, roll_deg=roll_deg).horizon
    return -(a * CAM.K[0, 2] + c) / b


def run(frames, **kwargs):
    cal = OnlineCalibrator(CAM.K, 4.0, FPS, (CAM.width, CAM.height), 1.70, 0.07, **kwargs)
    states = [cal.update(f, b, i) for f, b, i in frames]
    return cal, states


def test_implied_horizon_rows_inverts_implied_heights():
    rng = np.random.default_rng(1)
    for tilt_deg in (5.0, 15.0, 40.0):
        cam = dataclasses.replace(CAM, tilt_deg=tilt_deg)
        xy = np.column_stack([rng.uniform(-5, 5, 50), rng.uniform(6, 60, 50)])
        h = rng.uniform(1.4, 2.0, 50)
        foot, head = (cam.project(np.column_stack([xy, z])) for z in (np.zeros(50), h))
        rows, slope = implied_horizon_rows(foot[:, 1], head[:, 1], cam.focal_px, cam.K[1, 2], 4.0, h)
        assert np.allclose(rows, cam.horizon_row, atol=1e-6)
        tilt = np.arctan((cam.K[1, 2] - rows) / cam.focal_px)  # the rows' tilts give the heights back
        back = [implied_heights(foot[i:i + 1, 1], head[i:i + 1, 1], tilt[i], cam.focal_px, cam.K[1, 2], 4.0)[0]
                for i in range(50)]
        assert np.allclose(back, h, rtol=1e-9)
        up, _ = implied_horizon_rows(foot[:, 1], head[:, 1], cam.focal_px, cam.K[1, 2], 4.0, h + 1e-5)
        assert np.allclose(slope, (up - rows) / 1e-5, rtol=1e-3)
    # a box from row 10 to row 700 is a person of more than 1.7 m under a 4 m camera at every tilt
    assert np.isnan(implied_horizon_rows(np.array([700.0]), np.array([10.0]), CAM.focal_px, CAM.K[1, 2], 4.0, 1.7)).all()


def test_a_rolled_camera_puts_the_implied_rows_on_its_horizon_line():
    """People 6-45 m ahead seen by CAM rolled 1 and -2 degrees, each box spanning its foot and head points: each box's
    implied row is v_0 - tan(roll) w (implied_line_terms, calibrator docstring), v_0 and the roll from PinholeCamera's
    horizon line; the model is first order in the roll: within 0.025 roll^2 sd (0.018 measured, on the nearest
    people), where the horizon line's own slope through the box's middle is off by more than 0.1 |roll| sd."""
    rng = np.random.default_rng(4)
    xy = np.column_stack([rng.uniform(-12, 12, 200), rng.uniform(6, 45, 200)])
    for roll in (1.0, -2.0):
        cam = dataclasses.replace(CAM, roll_deg=roll)
        foot, head = (cam.project(np.column_stack([xy, z])) for z in (np.zeros(200), np.full(200, 1.7)))
        inside = (foot[:, 0] > 0) & (foot[:, 0] < cam.width) & (foot[:, 1] < cam.height)
        foot, head = foot[inside], head[inside]
        boxes = np.column_stack([np.minimum(foot[:, 0], head[:, 0]) - 5, head[:, 1], np.maximum(foot[:, 0], head[:, 0]) + 5,
                                 foot[:, 1]])
        rows, slope, w, x = implied_line_terms(boxes, CAM.K, 4.0, 1.7)
        sd = np.abs(slope) * 0.09
        tan = math.tan(math.radians(roll))
        assert (np.abs(rows - (horizon(0.0, roll) - tan * w)) / sd).max() < 0.025 * roll ** 2
        assert (np.abs(rows - (horizon(0.0, roll) - tan * x)) / sd).max() > 0.1 * abs(roll)


def test_track_linker_keeps_only_live_tracks():
    linker = TrackLinker(max_gap=5)
    box = np.array([[0.0, 0.0, 10.0, 20.0]])
    ids = [int(linker.link(f, box + [3 * f, 0, 3 * f, 0])[0]) for f in range(10)]  # one walker
    assert ids == [0] * 10
    for f in range(10, 1000):  # a new person every frame, far apart: all but the last 6 frames' dropped
        linker.link(f, box + [100 * f, 0, 100 * f, 0])
    assert len(linker._ids) <= 6
    frames = np.repeat(np.arange(50), 2)
    xyxy = np.tile(box, (100, 1)) + np.column_stack([frames * 2.0, np.tile([0, 500], 50), frames * 2.0, np.tile([0, 500], 50)])
    assert list(link_tracks(frames, xyxy)[:4]) == [0, 1, 0, 1]


def test_clipped_sd_is_the_clipped_normal_sd():
    z = np.linspace(-12, 12, 240_001)
    density = np.exp(-z * z / 2) / math.sqrt(2 * math.pi)
    assert math.isclose(SD_CLIPPED ** 2, float(np.sum(np.minimum(z * z, CLIP ** 2) * density) * (z[1] - z[0])), rel_tol=1e-6)


@pytest.mark.parametrize("arl0", [50, 1000, 20_000])
def test_cusum_threshold_inverts_siegmund(arl0):
    assert math.isclose(cusum_arl0(cusum_threshold(arl0)), arl0, rel_tol=1e-9)


def clipped_tilt(pdf, cdf, k: float = CUSUM_K, scale: float = 1.0) -> float:
    """The tilt of increments u = clip(z / scale, +-CLIP) / SD_CLIPPED, z of density pdf and distribution function cdf:
    the root theta > 0 of E exp(theta (u - k)) = 1, by quadrature (scipy) and brentq, independent of the code under
    test."""
    c = CLIP * scale

    def mgf(theta):
        g = lambda x: math.exp(theta * (min(max(x / scale, -CLIP), CLIP) / SD_CLIPPED - k))  # noqa: E731
        inside = integrate.quad(lambda x: g(x) * pdf(x), -c, c, limit=200)[0]
        return inside + g(c) * (1 - cdf(c)) + g(-c) * cdf(-c) - 1

    hi = 0.5
    while mgf(hi) < 0:
        hi *= 2
    return optimize.brentq(mgf, 1e-6, hi, xtol=1e-10)


def skewed_pdf(x):
    """A mixture with a heavy left tail (mean 0): N(0.2, 1) with weight 0.9, N(-1.8, 3^2) with weight 0.1."""
    return 0.9 * stats.norm.pdf(x, 0.2, 1) + 0.1 * stats.norm.pdf(x, -1.8, 3)


def skewed_cdf(x):
    return 0.9 * stats.norm.cdf(x, 0.2, 1) + 0.1 * stats.norm.cdf(x, -1.8, 3)


def skewed_draw(rng, n):
    heavy = rng.random(n) < 0.1
    return np.where(heavy, rng.normal(-1.8, 3, n), rng.normal(0.2, 1, n))


def cusum_run_lengths(draw, h, h_down=None, runs=4000, seed=3):
    """The run lengths of the two-sided CUSUM (reference CUSUM_K, thresholds h for S+ and h_down for S-, None: h)
    on increments draw(rng, runs)."""
    h_down = h if h_down is None else h_down
    rng = np.random.default_rng(seed)
    up, down, alive, length = np.zeros(runs), np.zeros(runs), np.ones(runs, bool), np.zeros(runs)
    for step in range(1, 100_000):
        u = draw(rng, runs)
        up, down = np.maximum(0, up + u - CUSUM_K), np.maximum(0, down - u - CUSUM_K)
        fired = alive & ((up > h) | (down > h_down))
        length[fired], alive = step, alive & ~fired
        if not alive.any():
            return length
    raise AssertionError("runs did not end")


def test_siegmund_arl_against_simulation():
    """The two-sided CUSUM on N(0, 1) increments runs cusum_arl0(h) steps on average (Monte Carlo, 4000 runs:
    the mean's standard error is about 1.6 %; Siegmund's approximation is within a few % at these h)."""
    length = cusum_run_lengths(lambda rng, n: rng.standard_normal(n), cusum_threshold(200))
    assert abs(length.mean() / 200 - 1) < 0.1


def test_tilt_of_normal_increments():
    """tilt on 200,000 N(0, sd^2) increments: 2 k / sd^2 (E exp(theta (x - k)) = exp(theta^2 sd^2 / 2 - theta k)),
    within 4 of its standard errors (about 0.5 % here); no root (NaN) when the mean is at least k."""
    rng = np.random.default_rng(2)
    for sd in (1.0, 1.4):
        assert abs(tilt(rng.normal(0, sd, 200_000), CUSUM_K) / (2 * CUSUM_K / sd ** 2) - 1) < 0.02
    assert math.isnan(tilt(rng.normal(0.6, 1, 1000), CUSUM_K))


@pytest.mark.parametrize("name, draw, pdf, cdf", [
    ("t3", lambda rng, n: rng.standard_t(3, n), lambda x: stats.t.pdf(x, 3), lambda x: stats.t.cdf(x, 3)),
    ("skewed", skewed_draw, skewed_pdf, skewed_cdf),
])  # fmt: skip
def test_siegmunds_run_length_with_the_increments_tilt(name, draw, pdf, cdf):
    """Residuals with Student's t tails (3 degrees of freedom: the rgb boxes' share over 2, 3 and 4 sd,
    research/watch_residuals.py) or a heavy left tail (skewed_pdf), clipped at CLIP and divided by SD_CLIPPED (the
    calibrator's increments): with each side's threshold from cusum_threshold at that side's tilt (by quadrature:
    clipped_tilt) and the increments' root mean square, the two-sided CUSUM runs ARL0 = 200 steps on average (4000
    runs: the mean's standard error about 1.6 %; Siegmund's approximation within a few % here: 0.99 and 1.00 of
    it); with both at the larger of the two (as OnlineCalibrator does), at least that (0.99, 1.13); with the normal's
    threshold, at most half of it (0.20, 0.28)."""
    theta = [clipped_tilt(pdf, cdf), clipped_tilt(lambda x: pdf(-x), lambda x: 1 - cdf(-x))]  # S+ on u, S- on -u
    assert max(theta) < 2 * CUSUM_K  # heavier than the normal's on both sides
    rng = np.random.default_rng(4)
    sd = float(np.sqrt(np.mean((np.clip(draw(rng, 1_000_000), -CLIP, CLIP) / SD_CLIPPED) ** 2)))
    up, down = (cusum_threshold(200, CUSUM_K, t, sd) for t in theta)

    def increments(rng, n):
        return np.clip(draw(rng, n), -CLIP, CLIP) / SD_CLIPPED

    assert abs(cusum_run_lengths(increments, up, down).mean() / 200 - 1) < 0.1
    assert cusum_run_lengths(increments, max(up, down)).mean() / 200 > 0.95
    assert cusum_run_lengths(increments, cusum_threshold(200), runs=1000).mean() / 200 < 0.5


def test_robust_line_gives_its_peoples_increments():
    """robust_line's row increments on 4000 people whose residuals are Student's t with 3 degrees of freedom (sigma
    1-4 px) have the tilt of clip(z / s, +-CLIP) / SD_CLIPPED by quadrature (s the median absolute residual /
    0.6745: 0.7649 / 0.6745 for t with 3; the sample's tilt within a few % of it) on either side; no roll: the roll
    test's increments NaN."""
    rng = np.random.default_rng(7)
    sigma, z = rng.uniform(1, 4, 4000), rng.standard_t(3, 4000)
    x = robust_line([(0.0, 200 + e * si, si, math.nan, 0.0) for e, si in zip(z, sigma)]).increments
    expected = clipped_tilt(lambda v: stats.t.pdf(v, 3), lambda v: stats.t.cdf(v, 3), scale=stats.t.ppf(0.75, 3) / 0.6745)
    assert x.shape == (4000, 2) and np.isnan(x[:, 1]).all()
    for side in (x[:, 0], -x[:, 0]):
        assert abs(tilt(side, CUSUM_K) / expected - 1) < 0.06


def test_robust_line_counts_its_outliers_in_the_priors_sigma():
    """Line.n_outliers: the people beyond OUTLIER_SIGMAS (3) of their own sigma from the line, whatever the robust
    scale s. People placed symmetrically about row 200 (so the M-estimate is 200 by symmetry): 40 at +-0.5 sigma,
    N at +-5 sigma; s is 1 while they are under half (the median |z| 0.5), and grows past them once they are
    not; the count is the 2 N placed beyond 3 either way."""
    for far in (4, 12, 24):
        z = np.concatenate([np.tile([0.5, -0.5], 20), np.tile([5.0, -5.0], far)])
        sigma = np.linspace(1.0, 3.0, len(z))
        line = robust_line([(0.0, 200 + e * si, si, math.nan, 0.0) for e, si in zip(z, sigma)])
        assert abs(line.row - 200) < 1e-9 and line.n_outliers == 2 * far
    assert line.scale > 3.0  # 48 of 88 at 5 sigma: the median |z| is 5, the count still in the prior's sigma


def test_heavy_tailed_people_raise_the_row_tests_threshold():
    """A steady camera whose people's heights have Student's t tails (3 degrees of freedom; the prior says normal):
    once armed, the row test's threshold is mostly above the normal increments' (cusum_threshold(arl0_people)), its
    estimate's increments' tilt below theirs (2 k); with normal heights it stays the normal's once the window is
    full (earlier a side's tilt on a few people may be below 2 k: a higher threshold)."""
    cal, states = run(stream(120, rate=4.0, seed=6, dof=3))
    armed = [s.threshold for s in states if np.isfinite(s.threshold)]
    assert tilt(-cal.estimate.increments[:, 0], CUSUM_K) < 2 * CUSUM_K
    assert len(armed) > 100 and np.mean(np.array(armed) > cal.threshold + 1) > 0.5
    cal, states = run(stream(120, rate=4.0, seed=6))
    assert {s.threshold for s in states if s.n_people == WINDOW_PEOPLE} == {cal.threshold}


@pytest.mark.parametrize("k_roll", [None, 0.15, 0.3])
def test_the_change_tests_together_alarm_at_the_stated_rate(k_roll):
    """The one-sided CUSUMs of a steady camera, each test at its Siegmund threshold for (tests run) x ARL0, alarm
    every ARL0 people or a little less often, in the mean (Monte Carlo, 4000 runs at ARL0 200: the mean's standard error is 1.6 %): the
    row test's on u, the clipped standardised normal, one a person; the drift test's on its own residuals, RATE
    independent clipped standardised normals a person, at its threshold for RATE x (tests run) x ARL0 residuals;
    with the roll (k_roll, sd), the roll test's on u g at k = k_roll (tan(ROLL_REF_DEG) g_rms / 2), g the people's
    roll regressors, here uniform with unit RMS. Siegmund's approximation is within a few % of one test's run
    (+4 % here); a CUSUM's run from 0 is not memoryless (it must climb to h first), so the first alarm of several
    tests comes later than 1 / (sum of 1 / ARL0) says, and the row and roll tests share each person's |u|: the
    split budget is conservative (measured: +23 % with the row and drift tests, +21 % and +13 % with the roll)."""
    arl0, runs, rate = 200, 4000, 3
    tests = len(TESTS) - (k_roll is None)
    h = np.array([cusum_threshold(tests * arl0)] * 2 + [cusum_threshold(tests * arl0 * rate)] * 2
                 + ([] if k_roll is None else [cusum_threshold(tests * arl0, k_roll)] * 2))[:, None]
    k = np.array([CUSUM_K] * 4 + ([] if k_roll is None else [k_roll] * 2))[:, None]
    rng = np.random.default_rng(5)
    stats, alive, length = np.zeros((len(h), runs)), np.ones(runs, bool), np.zeros(runs)
    for step in range(1, 100_000):
        u = np.clip(rng.standard_normal(runs), -CLIP, CLIP) / SD_CLIPPED
        g = rng.uniform(-math.sqrt(3), math.sqrt(3), runs)
        person = [u, -u] if k_roll is None else [u, -u, g * u, -g * u]
        stats[[0, 1] + list(range(4, len(h)))] = np.maximum(0, stats[[0, 1] + list(range(4, len(h)))]
                                                            + np.stack(person) - k[[0, 1] + list(range(4, len(h)))])
        for _ in range(rate):
            d = np.clip(rng.standard_normal(runs), -CLIP, CLIP) / SD_CLIPPED
            stats[2:4] = np.maximum(0, stats[2:4] + np.stack([d, -d]) - k[2:4])
        fired = alive & (stats > h).any(axis=0)
        length[fired], alive = step, alive & ~fired
        if not alive.any():
            break
    assert 0.95 < length.mean() / arl0 < 1.3, length.mean()


@pytest.mark.parametrize("step, early", [(-3.0, 0), (-20.0, 3)])
def test_the_horizon_after_a_change_is_the_true_one_within_its_sigma(step, early):
    """40 people at row 200 then 8 at 200 + step (px; their sd 2-8 px, so a step of 0.4-1.5 or 2.5-10 sd a person),
    the CUSUM's last 0 ``early`` people before the change: over 200 draws, after_change's horizon after is the
    true row within its sigma, the z-scores' mean within 0.4 of 0 and root mean square 0.7-1.15 (their standard
    errors 0.07 and 0.05; measured -0.13, 0.79 and +0.07, 0.94). The people since the last 0 alone give z of mean
    +3.4 (RMS 3.6) on the large step; the likeliest change point alone, about -0.6 (RMS 1.2) on the small one."""
    rng = np.random.default_rng(5)
    z = []
    for _ in range(200):
        sd = rng.uniform(2, 8, 48)
        rows = np.r_[np.full(40, 200.0), np.full(8, 200.0 + step)] + sd * rng.standard_normal(48)
        people = [(float(i), rows[i], sd[i], 0.0, 0.0) for i in range(48)]
        before = robust_line(people[:40 - early])
        after = after_change(people, 40 - early, before, None, -1)[1]
        z.append((after.row - (200.0 + step)) / after.sigma)
    assert abs(np.mean(z)) < 0.4 and 0.7 < np.sqrt(np.mean(np.square(z))) < 1.15, (np.mean(z), np.std(z))

def test_steady_camera_tracks_its_horizon_in_bounded_memory():
    cal, states = run(stream(300))
    assert [s.move for s in states if s.move] == []
    last = states[-1]
    assert last.n_people == WINDOW_PEOPLE and len(cal._people) == WINDOW_PEOPLE and len(cal._tracks) <= 10
    assert abs(last.horizon_row - horizon(0)) < 4 * last.horizon_sigma_px < 2.0


def test_boxes_taller_by_a_told_margin_give_the_peoples_horizon():
    """OnlineCalibrator(box_margin_px=3) on boxes 3 px taller, half at each end: the states of the people's own
    boxes (to float rounding); untold, the horizon several px up; a box no taller than the margin is not measured."""
    frames = list(stream(120, seed=4))
    _, own = run(frames)
    _, told = run([(f, b + [0.0, -1.5, 0.0, 1.5], i) for f, b, i in frames], box_margin_px=3.0)
    _, untold = run([(f, b + [0.0, -1.5, 0.0, 1.5], i) for f, b, i in frames])
    np.testing.assert_allclose([s.horizon_row for s in told], [s.horizon_row for s in own], rtol=1e-9)
    assert own[-1].horizon_row - untold[-1].horizon_row > 3.0
    f, b, i = frames[-1]
    cal, _ = run([(f, np.vstack([b, [600.0, 500.0, 620.0, 502.0]]), np.append(i, 10**6))], box_margin_px=3.0)
    assert 10**6 in cal._tracks and cal._tracks[10**6][1] == []  # its track kept alive, no height measured


@pytest.mark.parametrize("roll", [1.5, -1.0])
def test_a_rolled_camera_gives_its_horizon_line(roll):
    """A steady camera rolled by ``roll`` degrees, people spread over the width, estimate_roll: no move; the
    estimate's row at the principal column and its roll within 4 sigma of PinholeCamera's horizon line, the roll's
    sigma under 0.2 degree. Without estimate_roll, the roll is 0 with a NaN sigma and only the row is tested."""
    _, states = run(stream(100, roll=lambda t: roll, side=12.0, seed=1), estimate_roll=True)
    assert [s.move for s in states if s.move] == []
    last = states[-1]
    assert abs(last.horizon_row - horizon(0.0, roll)) < 4 * last.horizon_sigma_px
    assert abs(last.roll_deg - roll) < 4 * last.roll_sigma_deg < 0.8
    cal, states = run(stream(60, roll=lambda t: roll, side=12.0, seed=1))
    assert states[-1].roll_deg == 0.0 and math.isnan(states[-1].roll_sigma_deg) and math.isnan(states[-1].cusum_roll_up)
    assert cal.threshold == cusum_threshold((len(TESTS) - 1) * cal.arl0_people)  # the row and drift tests


def test_a_roll_step_is_a_move_of_the_roll_test():
    """The camera rolls 2 degrees at 60 s (its horizon's row at the principal column unchanged), estimate_roll: one
    move, of the roll test, direction -1 (the horizon rose on the right), found within 30 s, its change point
    within 5 s of the move; the roll before it within 4 sigma of 0, after it and at the end within 4 sigma of 2
    degrees, the row unchanged."""
    _, states = run(stream(150, roll=lambda t: 2.0 if t >= 60 else 0.0, side=12.0, seed=2), estimate_roll=True)
    moves = [s.move for s in states if s.move]
    assert len(moves) == 1
    m = moves[0]
    assert m.test == "roll" and m.direction == -1 and abs(m.t_s - 60) < 5 and 60 < m.detected_s < 90
    assert abs(m.roll_before_deg) < 4 * m.roll_sigma_before_deg and abs(m.roll_after_deg - 2) < 4 * m.roll_sigma_after_deg
    last = states[-1]
    assert abs(last.roll_deg - 2) < 4 * last.roll_sigma_deg and abs(last.horizon_row - horizon(0.0, 2.0)) < 4 * last.horizon_sigma_px


@pytest.mark.parametrize("change, at", [(1.0, 100.0), (-2.0, 100.0), (0.5, 150.0)])
def test_a_tilt_step_is_one_move_with_the_new_horizon(change, at):
    _, states = run(stream(300, tilt=lambda t: change if t >= at else 0.0, seed=2))
    moves = [s.move for s in states if s.move]
    assert len(moves) == 1
    m = moves[0]
    assert at - 10 <= m.t_s <= at + 10 and at < m.detected_s < at + 60
    assert m.direction == (-1 if change > 0 else 1)  # looking further down lifts the horizon
    assert abs(m.horizon_before - horizon(0)) < 4 * m.sigma_before
    assert abs(states[-1].horizon_row - horizon(change)) < 4 * states[-1].horizon_sigma_px
    assert states[-1].stretch_start_s == m.t_s


def test_a_gap_is_not_a_move_and_ends_every_track():
    frames = list(stream(200, seed=4))
    gap = [(f + (3000 if f >= 500 else 0), b, i + (10_000 if f >= 500 else 0)) for f, b, i in frames]
    _, states = run(gap)
    assert not any(s.move for s in states)
    assert states[500].t_s == (500 + 3000) / FPS


@pytest.mark.parametrize("frame, box, message", [
    (5, [[0, 0, 10, 10]], "frame 5 after frame 9: boxes must come in time order"),
    (10, [[0, np.nan, 10, 10]], "not finite or is upside down"),
    (10, [[0, 20, 10, 10]], "not finite or is upside down"),
    (10, [[0, 0, 10, 10]] * 501, "frame 10: 501 boxes, more than 500"),
])
def test_bad_boxes_are_refused(frame, box, message):
    cal = OnlineCalibrator(CAM.K, 4.0, FPS)
    cal.update(9, np.zeros((0, 4)))
    with pytest.raises(ValueError, match=message.replace("(", r"\(")):
        cal.update(frame, np.array(box, float))


@pytest.mark.parametrize("lens_K, lens_size, message", [
    (CAM.K * [[1.01, 1, 1], [1, 1.01, 1], [1, 1, 1]], (CAM.width, CAM.height), "^K: .* is not the lens's K"),
    (CAM.K, (1920, 1080), r"^image_size: \(1280, 720\) is not the lens's image size \(1920, 1080\)")])
def test_lens_of_another_camera_is_refused(lens_K, lens_size, message):
    """OnlineCalibrator(lens=) with a lens whose K or image size is not the K and image_size given: one ValueError."""
    with pytest.raises(ValueError, match=message):
        OnlineCalibrator(CAM.K, 4.0, FPS, image_size=(CAM.width, CAM.height),
                         lens=Lens(lens_K, np.array([-0.2, 0, 0, 0, 0]), lens_size))


def person_box(cam, x, y, height=1.70):
    """The box (4,) homocal edges of a person standing at ground (x, y) m, 0.5 m wide, seen by cam."""
    foot, head = cam.project(np.array([[x, y, 0.0], [x, y, height]]))
    half = 0.25 * cam.focal_px / y
    return np.array([foot[0] - half, head[1], foot[0] + half, foot[1]])


def test_a_person_whose_feet_a_nearer_person_hides_gives_no_observation():
    """A (25 m ahead) stands behind B (18 m, walking across in front) for 10 frames, then alone for 5. While B's
    body covers A's foot point (checked by projection), a detector sees A only down to B's head: that box implies
    a horizon far below the camera's. With B's box in the frame, A's cut boxes are left out and A's observation
    comes from its 5 whole boxes after B has gone; without it (B not detected) the cut boxes make A's
    observation."""
    a_whole = person_box(CAM, 0.0, 25.0)
    frames = []
    for f in range(15):
        b = person_box(CAM, -0.25 + 0.05 * f, 18.0) if f < 10 else None
        a = a_whole.copy()
        if b is not None:
            foot = CAM.project(np.array([[0.0, 25.0, 0.0]]))[0]
            assert b[0] < foot[0] < b[2] and b[1] < foot[1] < b[3]  # A's sole is behind B's body
            a[3] = b[1]  # A seen down to B's head
        frames.append((f, a, b))
    truth = CAM.horizon_row
    cut_row = implied_horizon_rows(np.array([b[1] for _, _, b in frames[:1]]), a_whole[1:2], CAM.focal_px, CAM.K[1, 2],
                                   4.0, 1.70)[0][0]
    assert cut_row - truth > 20  # the cut box's horizon, independently: far below the camera's

    def observed(with_b):
        cal = OnlineCalibrator(CAM.K, 4.0, FPS, (CAM.width, CAM.height), 1.70, 0.07)
        out = []
        for f, a, b in frames:
            boxes, ids = (np.array([a, b]), [1, 2]) if with_b and b is not None else (a[None], [1])
            s = cal.update(f, boxes, np.array(ids))
            out += [(f, row, sigma) for row, sigma in zip(s.person_rows, s.person_sigmas)]
            assert s.hidden_boxes == int(with_b and b is not None)  # A's cut boxes, while B is in front
        return out

    with_b = observed(True)
    assert [f for f, *_ in with_b] == [4, 14]  # B after its 5 boxes, A after its 5 whole boxes
    assert all(abs(row - truth) < 0.01 for _, row, _ in with_b)  # exact boxes, no noise
    without = observed(False)
    assert len(without) == 1 and without[0][0] == 4 and abs(without[0][1] - cut_row) < 1e-6
    assert without[0][1] - truth > 5 * without[0][2]  # it would enter the estimate many sigmas off


# ---- the commands ------------------------------------------------------------------------------
def write_inputs(folder, frames):
    """trap.json (CAM's true trapezoid), camera.json and boxes.csv (corner pixels) of the frames."""
    img = CAM.project_ground(GROUND)
    (folder / "trap.json").write_text(json.dumps({"image": img.tolist(), "map": GROUND.tolist()}))
    (folder / "camera.json").write_text(json.dumps({"width": CAM.width, "height": CAM.height, "K": CAM.K.tolist()}))
    lines = ["frame,x1,y1,x2,y2,track_id"]
    for f, boxes, ids in frames:
        lines += [f"{f},{float(b[0]) + 0.5!r},{float(b[1]) + 0.5!r},{float(b[2]) + 0.5!r},{float(b[3]) + 0.5!r},{i}" for b, i in zip(boxes, ids)]
    (folder / "boxes.csv").write_text("\n".join(lines) + "\n")
    return ["--trapezoid", "trap.json", "--camera-json", "camera.json", "--camera-height", "4", "--fps", str(FPS),
            "--height-mean", "1.70", "--height-sd", "0.07"]


def test_watch_and_apply_at(tmp_path, capsys, monkeypatch):
    flags = write_inputs(tmp_path, stream(200, tilt=lambda t: 1.0 if t >= 100 else 0.0, seed=5))
    r = homocal_main("watch", *flags, "--boxes", "boxes.csv", "--out", "out", cwd=tmp_path, capsys=capsys,
                     monkeypatch=monkeypatch)
    assert r.returncode == 0, r.stderr
    moves = json.loads((tmp_path / "out/moves.json").read_text())["moves"]
    assert len(moves) == 1 and 90 <= moves[0]["t_s"] <= 110
    stretches = sorted((tmp_path / "out/corrections").glob("*.json"), key=lambda p: float(p.stem))
    assert [float(p.stem) for p in stretches] == [0.0, moves[0]["t_s"]]
    table = pq.read_table(tmp_path / "out/horizon.parquet")
    assert table.num_rows == json.loads((tmp_path / "out/watch.json").read_text())["people"] > 2 * MIN_PEOPLE
    assert table.column("stretch_start_s").to_pylist()[-1] == moves[0]["t_s"]
    # ground points seen by the moved camera: the late stretch maps them back, the early one does not
    moved = dataclasses.replace(CAM, tilt_deg=CAM.tilt_deg + 1.0)
    ground = np.array([[0.0, 10.0], [2.0, 30.0], [-3.0, 45.0]])
    uv = moved.project_ground(ground)
    (tmp_path / "feet.csv").write_text("u,v\n" + "".join(f"{float(u)!r},{float(v)!r}\n" for u, v in uv))
    for at, stretch in ((150, stretches[1]), (50, stretches[0])):
        r = homocal_main("apply", "out", "--at", str(at), "--points", "feet.csv", "-o", f"at{at}.csv", cwd=tmp_path,
                         capsys=capsys, monkeypatch=monkeypatch)
        assert r.returncode == 0, r.stderr
        got = np.loadtxt(tmp_path / f"at{at}.csv", delimiter=",", skiprows=1, usecols=(2, 3))
        assert np.allclose(got, load_corrector(stretch).transform_points(uv))
    late, early = (np.loadtxt(tmp_path / f"at{a}.csv", delimiter=",", skiprows=1, usecols=(2, 3)) for a in (150, 50))
    (tmp_path / "timed.csv").write_text("u,v,t\n" + "".join(f"{float(u)!r},{float(v)!r},{t}\n" for (u, v), t in zip(uv, (150, 50, 150))))
    r = homocal_main("apply", "out", "--points", "timed.csv", "-o", "timed_out.csv", cwd=tmp_path, capsys=capsys,
                     monkeypatch=monkeypatch)
    assert r.returncode == 0, r.stderr
    timed = np.loadtxt(tmp_path / "timed_out.csv", delimiter=",", skiprows=1, usecols=(3, 4))
    assert np.allclose(timed, [late[0], early[1], late[2]])
    for points, message in (("feet.csv", "give --at SECONDS or a t column"), ("nan_t.csv", "t is not a finite number")):
        (tmp_path / "nan_t.csv").write_text("u,v,t\n600,400,nan\n")
        r = homocal_main("apply", "out", "--points", points, "-o", "x.csv", cwd=tmp_path, capsys=capsys,
                         monkeypatch=monkeypatch)
        assert r.returncode == 2 and message in r.stderr and r.stderr.count("\n") == 1, r.stderr
    assert np.all(np.abs(late[:, 1] - ground[:, 1]) / ground[:, 1] < 0.03)
    assert np.abs(early[-1, 1] - ground[-1, 1]) / ground[-1, 1] > 0.1


def test_boxes_that_are_not_people_get_no_correction(tmp_path, capsys, monkeypatch):
    """Boxes of things 0.3-3 m tall (a background subtractor's blobs on a moving camera, docs/moving-camera.md): more
    than half of the estimate's people beyond 3 sd of the prior, so the stretch's correction is refused as homocal fit
    refuses (corrections/0.00.json says why; one warning line; exit 0: the watch ran), and homocal apply at its time
    exits 2 with one line, writing nothing. The same stream with people's heights gets its correction."""
    (tmp_path / "feet.csv").write_text("u,v\n640,500\n")
    for heights, refused in ((lambda rng, n: rng.uniform(0.3, 3.0, n), True), (None, False)):
        out = f"out_{refused}"
        flags = write_inputs(tmp_path, stream(40, seed=3, heights=heights))
        r = homocal_main("watch", *flags, "--boxes", "boxes.csv", "--out", out, cwd=tmp_path, capsys=capsys,
                         monkeypatch=monkeypatch)
        assert r.returncode == 0, r.stderr
        written = json.loads((tmp_path / out / "corrections/0.00.json").read_text())
        last = pq.read_table(tmp_path / out / "horizon.parquet").to_pylist()[-1]
        assert (last["n_outliers"] > last["n_people"] / 2) == refused
        assert (written.get("format") == "homocal-watch-refused") == refused
        assert ("1 of the 1 stretches' corrections refused" in r.stderr) == refused
        assert ("(1 refused)" in r.stdout) == refused
        r = homocal_main("apply", out, "--at", "20", "--points", "feet.csv", "-o", f"{out}.csv", cwd=tmp_path,
                         capsys=capsys, monkeypatch=monkeypatch)
        assert r.returncode == (2 if refused else 0) and (tmp_path / f"{out}.csv").exists() != refused, r.stderr
        if refused:
            assert r.stderr.count("\n") == 1 and "line 2: t = 20 s has no correction in out_True" in r.stderr
            assert "people are outliers (implied height beyond 3 sd of 1.7 m at the horizon row" in written["refused"]
            (tmp_path / out / "corrections/0.00.json").write_text(json.dumps({**written, "refused": 5}))  # not ours
            r = homocal_main("apply", out, "--at", "20", "--points", "feet.csv", "-o", f"{out}.csv", cwd=tmp_path,
                             capsys=capsys, monkeypatch=monkeypatch)
            assert r.returncode == 2 and "0.00.json: field refused: expected text" in r.stderr, r.stderr


def test_watch_with_the_roll_writes_it_and_apply_uses_it(tmp_path, capsys, monkeypatch):
    """--estimate-roll yes on a camera that rolls 2 degrees at 60 s: moves.json (strict JSON) has the roll test's
    move with the roll before and after, horizon.parquet the roll columns after the others, and the stretch's
    correction maps ground points seen by the rolled camera within 2 % in range (the one before, roll 0, does
    not: its points to the sides are off by more)."""
    flags = write_inputs(tmp_path, stream(150, roll=lambda t: 2.0 if t >= 60 else 0.0, side=12.0, seed=2))
    r = homocal_main("watch", *flags, "--estimate-roll", "yes", "--boxes", "boxes.csv", "--out", "out", cwd=tmp_path,
                     capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 0, r.stderr
    moves = json.loads((tmp_path / "out/moves.json").read_text(), parse_constant=lambda c: pytest.fail(c))["moves"]
    assert [m["test"] for m in moves] == ["roll"] and moves[0]["roll_after_deg"] > 1.0
    assert json.loads((tmp_path / "out/watch.json").read_text())["estimate_roll"] is True
    table = pq.read_table(tmp_path / "out/horizon.parquet")
    assert table.column_names[-8:] == ["person_column_px", "roll_deg", "roll_sigma_deg", "cusum_roll_up", "cusum_roll_down",
                                       "cusum_drift_up", "cusum_drift_down", "n_outliers"]
    last = table.slice(table.num_rows - 1).to_pylist()[0]
    assert abs(last["roll_deg"] - 2.0) < 4 * last["roll_sigma_deg"]
    rolled = dataclasses.replace(CAM, roll_deg=2.0)
    ground = np.array([[-8.0, 12.0], [8.0, 12.0], [0.0, 25.0], [-10.0, 40.0], [10.0, 40.0]])
    uv = rolled.project_ground(ground)
    (tmp_path / "feet.csv").write_text("u,v\n" + "".join(f"{float(u)!r},{float(v)!r}\n" for u, v in uv))
    errors = []
    for at in (140, 30):
        r = homocal_main("apply", "out", "--at", str(at), "--points", "feet.csv", "-o", f"at{at}.csv", cwd=tmp_path,
                         capsys=capsys, monkeypatch=monkeypatch)
        assert r.returncode == 0, r.stderr
        got = np.loadtxt(tmp_path / f"at{at}.csv", delimiter=",", skiprows=1, usecols=(2, 3))
        errors.append(np.abs(np.hypot(*got.T) - np.hypot(*ground.T)) / np.hypot(*ground.T))
    assert errors[0].max() < 0.02 < errors[1].max()


def stdin_run(tmp_path, capsys, monkeypatch, text, out="out"):
    flags = write_inputs(tmp_path, [])
    monkeypatch.setattr("sys.stdin", io.TextIOWrapper(io.BytesIO(text if isinstance(text, bytes) else text.encode()),
                                                      encoding="utf-8"))
    return homocal_main("watch", *flags, "--boxes", "-", "--out", out, cwd=tmp_path, capsys=capsys, monkeypatch=monkeypatch)


def csv_text(frames):
    return "frame,x1,y1,x2,y2,track_id\n" + "".join(
        f"{f},{float(b[0]) + 0.5!r},{float(b[1]) + 0.5!r},{float(b[2]) + 0.5!r},{float(b[3]) + 0.5!r},{i}\n" for f, boxes, ids in frames
        for b, i in zip(boxes, ids))


def test_watch_reads_standard_input_and_drops_a_cut_last_line(tmp_path, capsys, monkeypatch):
    text = csv_text(stream(60, seed=6))
    r = stdin_run(tmp_path, capsys, monkeypatch, text + "300,3.5,17")
    assert r.returncode == 0, r.stderr
    assert "line" in r.stderr and "cut short at the end of the stream; dropped" in r.stderr
    watch = json.loads((tmp_path / "out/watch.json").read_text())
    assert watch["ended"] == "end of stream"
    assert pq.read_table(tmp_path / "out/horizon.parquet").num_rows >= MIN_PEOPLE


def test_watch_on_a_file_and_on_standard_input_agree(tmp_path, capsys, monkeypatch):
    """The same boxes (3 people a second: some in front of others, whose boxes are left out) read from a file and
    from standard input give the same horizon.parquet, moves and counts."""
    frames = list(stream(60, rate=3, seed=8))
    flags = write_inputs(tmp_path, frames)
    r = homocal_main("watch", *flags, "--boxes", "boxes.csv", "--out", "file", cwd=tmp_path, capsys=capsys,
                     monkeypatch=monkeypatch)
    assert r.returncode == 0, r.stderr
    r = stdin_run(tmp_path, capsys, monkeypatch, csv_text(frames), out="stdin")
    assert r.returncode == 0, r.stderr
    file, stdin = (json.loads((tmp_path / f"{d}/watch.json").read_text()) for d in ("file", "stdin"))
    assert file["boxes_hidden"] > 0 and file["people"] >= MIN_PEOPLE
    assert {k: file[k] for k in ("boxes_read", "boxes_hidden", "people", "moves")} == \
        {k: stdin[k] for k in ("boxes_read", "boxes_hidden", "people", "moves")}
    file, stdin = (pq.read_table(tmp_path / f"{d}/horizon.parquet").to_pydict() for d in ("file", "stdin"))
    assert file.keys() == stdin.keys()
    for column in file:  # NaN where the stretch is too young to test: equal here
        np.testing.assert_array_equal(file[column], stdin[column], err_msg=column)
    assert (tmp_path / "file/moves.json").read_text() == (tmp_path / "stdin/moves.json").read_text()


@pytest.mark.parametrize("tail, message", [
    ("5,1,1,20,40,1\n", "frame 5 after frame 99: boxes must come in time order"),
    ("300,nan,1,20,40,1\n", "a value is not a finite number"),
    ("300,1,1,20\n", "not 6 numbers"),
    (b"300,1,1,20,40,\xff\n", "not UTF-8 text"),
    pytest.param("300,1,1,20,40,1\n" * 501, "frame 300 has more than 500 boxes", id="crowded frame"),
])
def test_watch_stops_at_bad_standard_input_with_whole_files(tmp_path, capsys, monkeypatch, tail, message):
    text = csv_text(stream(20, seed=7))
    r = stdin_run(tmp_path, capsys, monkeypatch, text.encode() + tail if isinstance(tail, bytes) else text + tail)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and message in r.stderr, r.stderr
    assert r.stderr.startswith("homocal: error: standard input, line ") or "UTF-8" in r.stderr
    assert json.loads((tmp_path / "out/watch.json").read_text())["ended"].startswith("stopped: ")
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["corrections", "horizon.parquet", "moves.json",
                                                                     "watch.json"]
    pq.read_table(tmp_path / "out/horizon.parquet")


def test_watch_refuses_a_file_out_of_time_order_before_writing(tmp_path, capsys, monkeypatch):
    flags = write_inputs(tmp_path, [])
    (tmp_path / "boxes.csv").write_text("frame,x1,y1,x2,y2\n3,1,1,20,40\n2,1,1,20,40\n")
    r = homocal_main("watch", *flags, "--boxes", "boxes.csv", "--out", "out", cwd=tmp_path, capsys=capsys,
                     monkeypatch=monkeypatch)
    assert r.returncode == 2 and "boxes out of time order" in r.stderr and r.stderr.count("\n") == 1
    assert not (tmp_path / "out").exists()


def without_fps(flags):
    i = flags.index("--fps")
    return flags[:i] + flags[i + 2:]


def test_watch_takes_the_frame_rate_a_mot_sequence_says(tmp_path, capsys, monkeypatch):
    """A MOT .txt beside its seqinfo.ini needs no --fps: its frameRate is the boxes' (as homocal measure's); the
    same boxes at --fps give the same horizon table."""
    frames = list(stream(60, seed=3))
    flags = without_fps(write_inputs(tmp_path, frames))
    (tmp_path / "SEQ" / "det").mkdir(parents=True)
    (tmp_path / "SEQ" / "seqinfo.ini").write_text(f"[Sequence]\nname=x\nframeRate={FPS}\nseqLength=400\n"
                                                  f"imWidth={CAM.width}\nimHeight={CAM.height}\n")
    (tmp_path / "SEQ" / "det" / "det.txt").write_text("".join(  # MOT: frames 1-based, boxes 1-based pixels
        f"{f + 1},{i},{float(b[0]) + 1.5!r},{float(b[1]) + 1.5!r},{float(b[2] - b[0])!r},{float(b[3] - b[1])!r},1,-1,-1,-1\n"
        for f, boxes, ids in frames for b, i in zip(boxes, ids)))
    r = homocal_main("watch", *flags, "--boxes", "SEQ/det/det.txt", "--out", "mot", cwd=tmp_path, capsys=capsys,
                     monkeypatch=monkeypatch)
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "mot/watch.json").read_text())["fps"] == FPS
    r = homocal_main("watch", *flags, "--boxes", "SEQ/det/det.txt", "--fps", str(FPS), "--out", "given", cwd=tmp_path,
                     capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 0, r.stderr
    mot, given = (pq.read_table(tmp_path / d / "horizon.parquet").to_pandas() for d in ("mot", "given"))
    assert len(mot) > 10
    assert mot.equals(given)


@pytest.mark.parametrize("boxes, rate, message", [
    ("boxes.csv", None, "--fps: required (boxes.csv does not say its frame rate)"),
    ("-", None, "--fps: required with --boxes - (standard input does not say its frame rate)"),
    ("SEQ/det/det.txt", "0", "its folder's frame rate '0' is not in (0, 1000]: give --fps"),
    ("SEQ/det/det.txt", "fast", "its folder's frame rate 'fast' is not in (0, 1000]: give --fps"),
])
def test_watch_without_a_frame_rate_is_refused_before_writing(tmp_path, capsys, monkeypatch, boxes, rate, message):
    flags = without_fps(write_inputs(tmp_path, stream(5, seed=8)))
    (tmp_path / "SEQ" / "det").mkdir(parents=True)
    (tmp_path / "SEQ" / "seqinfo.ini").write_text(f"[Sequence]\nname=x\nframeRate={rate}\n")
    (tmp_path / "SEQ" / "det" / "det.txt").write_text("1,1,100,100,20,80,1,-1,-1,-1\n")
    monkeypatch.setattr("sys.stdin", io.StringIO("frame,x1,y1,x2,y2\n"))
    r = homocal_main("watch", *flags, "--boxes", boxes, "--out", "out", cwd=tmp_path, capsys=capsys,
                     monkeypatch=monkeypatch)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and message in r.stderr, r.stderr
    assert not (tmp_path / "out").exists()


def test_apply_at_needs_a_watch_folder(tmp_path, capsys, monkeypatch):
    write_inputs(tmp_path, [])
    (tmp_path / "feet.csv").write_text("u,v\n600,400\n")
    (tmp_path / "c.json").write_text("{}")
    r = homocal_main("apply", "c.json", "--at", "3", "--points", "feet.csv", "-o", "x.csv", cwd=tmp_path,
                     capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 2 and "--at: for a homocal watch folder" in r.stderr


def test_watch_keeps_the_box_margin_in_each_stretch(tmp_path, capsys, monkeypatch):
    """homocal watch --box-margin 2: watch.json and every stretch's correction keep it (homocal measure's default)."""
    flags = write_inputs(tmp_path, stream(40, seed=9))
    r = homocal_main("watch", *flags, "--boxes", "boxes.csv", "--out", "out", "--box-margin", "2", cwd=tmp_path,
                     capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "out/watch.json").read_text())["box_margin_px"] == 2.0
    stretches = list((tmp_path / "out/corrections").glob("*.json"))
    assert stretches and all(load_corrector(p).box_margin_px == 2.0 for p in stretches)


@pytest.mark.parametrize("extra, message", [
    (["--height-mean", "9"], "argument --height-mean: expected a number in [0.5, 2.5] (m), got '9'"),
    (["--height-sd", "0.6"], "argument --height-sd: expected at most height_mean_m / 4 = 0.425 m, got 0.6"),
    (["--camera-height", "1e-9"], "argument --camera-height: expected a number in"),
    (["--estimate-roll", "maybe"], "argument --estimate-roll: expected yes or no, got 'maybe'"),
    (["--drift-test", "auto"], "argument --drift-test: expected yes or no, got 'auto'"),
    *((["--box-margin", v], f"argument --box-margin: expected a number in [0, 64] (px), got '{v}'")
      for v in ("nan", "inf", "-1", "65", "two", "")),
    (["--out", "full"], "full: exists and is not empty (use another output folder)"),
])
def test_watch_refuses_its_settings_as_fit_does(tmp_path, capsys, monkeypatch, extra, message):
    """The pedestrian flags are fit's (PEDESTRIAN_SETTINGS' bounds and messages); watch has no --resume."""
    flags = write_inputs(tmp_path, stream(5, seed=8))
    (tmp_path / "full").mkdir()
    (tmp_path / "full/x").write_text("a user's file")
    r = homocal_main("watch", *flags, "--boxes", "boxes.csv", "--out", "out", *extra, cwd=tmp_path, capsys=capsys,
                     monkeypatch=monkeypatch)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and message in r.stderr, r.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_a_move_rearms_the_people_in_view_and_the_new_stretch_is_unbiased():
    """simgen.boxstream's walkers of scene1 (seed 2), the camera tilting 2 degrees further down at 60 s: every person
    in view at the detection with PERSON_BOXES usable boxes in the frames after it is in the new stretch at once,
    and that stretch's horizon, and the move's horizon after, are the moved camera's within 3 of their sigmas."""
    from pathlib import Path

    from homocal.geometry.boxes import hidden_feet, on_border
    from homocal.watch.calibrator import PERSON_BOXES
    from simgen.boxstream import box_stream
    from simgen.scene import CameraMove, load_scene

    scene = load_scene(Path(__file__).resolve().parents[2] / "simgen" / "scenes" / "scene1")
    moving = dataclasses.replace(scene, moves=(CameraMove(60.0, tilt_deg=2.0),))
    frames = list(box_stream(moving, 2, 90.0, FPS))
    cam = scene.camera
    cal = OnlineCalibrator(cam.K, cam.mount_height_m, FPS, (cam.width, cam.height), 1.71, 0.09)
    states = [cal.update(f, b, i) for f, b, i in frames]
    detected = [k for k, s in enumerate(states) if s.move]
    assert len(detected) == 1 and states[detected[0]].move.detected_s > 60.0
    d = detected[0]
    # the people in view at the detection whose next PERSON_BOXES boxes are all usable (not at the image border, no
    # nearer person's box over their feet, a finite implied horizon: a person partly in view may have none)
    def usable(xyxy, ids):
        rows = implied_horizon_rows(xyxy[:, 3], xyxy[:, 1], cam.K[1, 1], cam.K[1, 2], cam.mount_height_m, 1.71)[0]
        hidden = hidden_feet(xyxy, np.zeros(len(xyxy), np.int64))
        return set(ids[np.isfinite(rows) & ~on_border(xyxy, (cam.width, cam.height)) & ~hidden].tolist())
    usable = [usable(xyxy, ids) for _, xyxy, ids in frames[d + 1:d + 1 + PERSON_BOXES]]
    in_view = set(frames[d][2].tolist()).intersection(*usable)
    after = states[d + PERSON_BOXES]  # newcomers need PERSON_BOXES boxes after the detection: none is in yet
    assert len(in_view) >= 8 and after.n_people == len(in_view)  # 9: the drift test's move 6 s after the step
    true_row = moving.camera_at(after.t_s).horizon_row
    assert abs(after.horizon_row - true_row) < 3 * after.horizon_sigma_px
    move = states[d].move  # the step the people in view told (the change point's people were 2.97 px off here)
    assert abs(move.horizon_after - true_row) < 3 * move.sigma_after


@pytest.mark.parametrize("drift, tests", [(True, 2), (False, 1)])
def test_the_drift_test_takes_its_share_of_the_budget_or_none(drift, tests):
    """drift_test=False is the row test alone at arl0_people; True shares it with the drift test (each test at twice
    it): the threshold h solves Siegmund's ARL0 for normal increments of unit variance, (exp(2 k b) - 2 k b - 1) /
    (2 k^2) / 2 = tests x arl0_people with b = h + 1.166 (written out here); without the test, no drift statistic
    (with it, tests/watch/test_drift.py)."""
    from homocal.watch.calibrator import CUSUM_K

    cal = OnlineCalibrator(CAM.K, 4.0, FPS, (CAM.width, CAM.height), 1.70, 0.07, arl0_people=5000, drift_test=drift)
    b, k = cal.threshold + 1.166, CUSUM_K
    assert (math.exp(2 * k * b) - 2 * k * b - 1) / (2 * k * k) / 2 == pytest.approx(tests * 5000, rel=1e-6)
    state = None
    for f, boxes, ids in stream(60, seed=3):
        state = cal.update(f, boxes, ids)
    assert math.isfinite(state.threshold)
    if not drift:
        assert all(map(math.isnan, (state.drift_threshold, state.cusum_drift_up, state.cusum_drift_down)))


@pytest.mark.parametrize("value", ["no", 1, None])
def test_drift_test_is_true_or_false(value):
    with pytest.raises(ValueError, match=f"drift_test must be True or False, got {value!r}"):
        OnlineCalibrator(CAM.K, 4.0, FPS, (CAM.width, CAM.height), 1.70, 0.07, drift_test=value)

"""The within-person change test (homocal.watch.drift)."""
import dataclasses
import math

import numpy as np
import pytest
from scipy import stats

from homocal.geometry import PinholeCamera
from homocal.watch import OnlineCalibrator
from homocal.watch.drift import BLOCK_S, block_residual

CAM = PinholeCamera()  # 1280x720, 95 degrees, 4 m high, tilted 15 degrees down
FPS = 5


def predictive_residuals(m, x, g, prior):
    """The standardised one-step prediction errors of m_k = c + x_k dH + g_k N(0, 1), c flat and dH of precision
    prior, by batch weighted least squares on the blocks before k with the prior as a pseudo-observation (numpy's
    lstsq; independent of block_residual's running sums)."""
    out = []
    for k in range(1, len(m)):
        X = np.vstack([np.column_stack([np.ones(k), x[:k]]) / g[:k, None], [0.0, math.sqrt(prior)]])
        y = np.concatenate([m[:k] / g[:k], [0.0]])
        beta = np.linalg.lstsq(X, y, rcond=None)[0]
        v = np.array([1.0, x[k]])
        out.append((m[k] - v @ beta) / math.sqrt(g[k] ** 2 + v @ np.linalg.inv(X.T @ X) @ v))
    return out


def test_block_residuals_are_the_predictive_residuals_and_independent_unit_normals():
    """People walking from 40 m to 8 m (slopes x 60 -> 15 px/m, gains 8 -> 1), heights from the prior (sd 0.09 m),
    block noise g_k N(0, 1): their residuals equal the batch predictive ones, and pooled over 3,000 people (27,000
    residuals) have mean 0 (+-4 standard errors, 0.024), sd 1 (+-0.02: the sd's standard error is 0.0043), a
    normal's tails (Kolmogorov-Smirnov, p > 0.001) and no lag-1 correlation (+-0.03: 4 standard errors)."""
    rng = np.random.default_rng(1)
    sd_h, blocks = 0.09, 10
    prior = (1.0 / sd_h) ** 2  # s = 1 px
    x, g = np.linspace(60, 15, blocks), np.linspace(8, 1, blocks)
    pooled, pairs = [], []
    for person in range(3000):
        m = 300.0 + x * rng.normal(0, sd_h) + g * rng.standard_normal(blocks)
        sums = np.zeros(6)
        rq = [block_residual(sums, *b, prior) for b in zip(m, x, g)]
        assert rq[0] is None
        e = [r / q for r, q in rq[1:]]
        if person < 20:
            np.testing.assert_allclose(e, predictive_residuals(m, x, g, prior), rtol=1e-9, atol=1e-9)
        pooled += e
        pairs += list(zip(e[:-1], e[1:]))
    z = np.array(pooled)
    assert abs(z.mean()) < 0.024 and abs(z.std() - 1) < 0.02
    assert stats.kstest(z, "norm").pvalue > 0.001
    assert abs(np.corrcoef(np.array(pairs).T)[0, 1]) < 0.03


def walkers(seconds, tilt=lambda t: 0.0, rate=0.5, seed=0, noise_px=0.3, fps=FPS):
    """Frames (frame, xyxy (N, 4), ids) at fps of people 1.70 +- 0.07 m tall walking at 1.4 m/s for 20 s each,
    toward the camera or away from it between 8 and 36 m ahead, up to 5 m to either side, arriving at ``rate`` a
    second (Poisson), seen by CAM tilted tilt(t) degrees further down; foot and head projected exactly, each box
    edge plus normal noise of noise_px."""
    rng = np.random.default_rng(seed)
    n = rng.poisson(rate * seconds)
    start, side = np.sort(rng.uniform(-20, seconds, n)), rng.uniform(-5, 5, n)
    toward, tall = rng.random(n) < 0.5, rng.normal(1.70, 0.07, n)
    for frame in range(int(seconds * fps)):
        t = frame / fps
        cam = dataclasses.replace(CAM, tilt_deg=CAM.tilt_deg + tilt(t))
        on = np.flatnonzero((start <= t) & (t < start + 20))
        walked = 1.4 * (t - start[on])
        y = np.where(toward[on], 36 - walked, 8 + walked)
        foot = cam.project(np.column_stack([side[on], y, np.zeros(len(on))]))
        head = cam.project(np.column_stack([side[on], y, tall[on]]))
        half = 0.25 * cam.focal_px / y
        boxes = np.column_stack([np.minimum(foot[:, 0], head[:, 0]) - half, head[:, 1],
                                 np.maximum(foot[:, 0], head[:, 0]) + half, foot[:, 1]])
        yield frame, boxes + rng.normal(0, noise_px, boxes.shape), on


@pytest.mark.slow
def test_a_tilt_step_is_found_by_the_people_in_view_within_a_few_blocks():
    """A 1-degree step at 200 s on people walking across it: the drift test alarms within 3 blocks of it (6 s) and
    declares the move once the people in view have told the step (a block later, 2 at most: 10 s in all), on the
    side the horizon went (up the image: -1), and no test fires before it."""
    cal = OnlineCalibrator(CAM.K, 4.0, FPS, (CAM.width, CAM.height), 1.70, 0.07)
    moves = [s.move for f, b, i in walkers(240, lambda t: 1.0 if t >= 200 else 0.0) if (s := cal.update(f, b, i)).move]
    assert len(moves) >= 1 and moves[0].test == "drift" and moves[0].direction == -1, moves
    assert 200 <= moves[0].detected_s <= 200 + 5 * BLOCK_S, moves[0]


@pytest.mark.slow
@pytest.mark.parametrize("fps, step_deg, seeds", [(1, 2.0, 12), (10, 1.0, 8)])
def test_the_horizon_after_a_drift_alarm_is_the_true_one_within_its_sigma(fps, step_deg, seeds):
    """A tilt step at 80 s (the tests armed since 40-60 s) told by the people in view, boxes of 1 px noise (the
    row estimate's scale floor, so that both sigmas are the noise's): over the seeds whose move the drift test
    finds, the move's horizon after is CAM's tilted horizon row (PinholeCamera.horizon_row) within 3 of its sigmas,
    and the z-scores' sd is a unit normal's within the sampling error of 6-12 draws (0.5-1.6: about +-2.5 standard
    errors; measured 0.82 and 0.89). The people's whole shift since the statistic left 0 gave z of 5-15."""
    truth = dataclasses.replace(CAM, tilt_deg=CAM.tilt_deg + step_deg).horizon_row
    z = []
    for seed in range(seeds):
        cal = OnlineCalibrator(CAM.K, 4.0, fps, (CAM.width, CAM.height), 1.70, 0.07)
        for f, b, i in walkers(95, lambda t: step_deg if t >= 80 else 0.0, seed=seed, noise_px=1.0, fps=fps):
            if (move := cal.update(f, b, i).move) is not None:
                if move.test == "drift":
                    z.append((move.horizon_after - truth) / move.sigma_after)
                break
    assert len(z) >= seeds * 2 // 3, z
    assert np.abs(z).max() < 3 and 0.5 < np.std(z) < 1.6, z


@pytest.mark.slow
@pytest.mark.parametrize("fps, seeds", [(1, 30), (5, 20)])
def test_a_step_while_the_tests_arm_is_measured_whole_whichever_test_finds_it(fps, seeds):
    """A 2-degree tilt step at 50 s, while the tests arm (the drift test at 40-60 s, before or after the step),
    boxes of 1 px noise: over the seeds whose move a test finds (the drift test's step told by the people in
    view, or by the people since the change point when none is; the row test's), the move's horizon after is
    CAM's tilted horizon row (PinholeCamera.horizon_row) within 3.5 of its sigmas, the z-scores' mean 0 within
    2.5 standard errors and their sd a unit normal's within about 2.5 (0.6-1.4; measured: mean 0.12 and 0.08, sd
    1.02 and 0.80). Before, the drift test's change point was where it armed and the people since a CUSUM's last 0
    held some from before the step: the step was measured short (mean z 0.63 and 0.67, up to 4.5 and 5.0)."""
    truth = dataclasses.replace(CAM, tilt_deg=CAM.tilt_deg + 2.0).horizon_row
    z = []
    for seed in range(seeds):
        cal = OnlineCalibrator(CAM.K, 4.0, fps, (CAM.width, CAM.height), 1.70, 0.07)
        for f, b, i in walkers(90, lambda t: 2.0 if t >= 50 else 0.0, seed=seed, noise_px=1.0, fps=fps):
            if (move := cal.update(f, b, i).move) is not None:
                z.append((move.horizon_after - truth) / move.sigma_after)
                break
    assert len(z) >= seeds * 3 // 4, z
    assert np.abs(z).max() < 3.5 and abs(np.mean(z)) < 2.5 / math.sqrt(len(z)) and 0.6 < np.std(z) < 1.4, z


@pytest.mark.slow
def test_a_steady_camera_of_walkers_raises_no_alarm_and_keeps_bounded_state():
    """Walkers under a steady camera for 10 minutes: no test fires at the default ARL0 (20,000 people; a few hundred
    here), and the drift test holds no more tracks than are in view."""
    cal = OnlineCalibrator(CAM.K, 4.0, FPS, (CAM.width, CAM.height), 1.70, 0.07)
    states = [cal.update(f, b, i) for f, b, i in walkers(600, seed=2)]
    assert [s.move for s in states if s.move] == []
    assert np.isfinite([s.drift_threshold for s in states[-100:]]).all()
    assert len(cal._drift._tracks) <= 25


@pytest.mark.slow
def test_the_drift_tests_run_length_on_steady_residuals_is_its_arl0():
    """DriftTest's CUSUM fed independent normal residuals (sd 2 px, above the 1-px floor of its scale; q = 1) at an
    ARL0 of 100 residuals, each run after a full window of them: the mean run length is 100 residuals within
    Monte Carlo error and the approximation's (400 runs: the mean's standard error is about 5 %; Siegmund's
    approximation is +4 % on clipped normal increments, and the window's tilt can only raise h: -15 % to +35 %;
    measured: 111 +- 5)."""
    from homocal.watch.drift import WINDOW, DriftTest

    rng = np.random.default_rng(7)
    lengths = []
    for _ in range(400):
        test = DriftTest(CAM.K, 4.0, FPS, 1.70, 0.07)
        test.window.extend(rng.normal(0, 2.0, WINDOW))
        n = 0
        while max(c - h for c, h in zip(test.cusum, test.h)) <= 0 or n == 0:
            n += 1
            test._step(n, rng.normal(0, 2.0), 1.0, 100.0)
        lengths.append(n)
    assert 0.85 < np.mean(lengths) / 100 < 1.35, np.mean(lengths)

"""research/measure_speeds.py: supervision's speed recipe as its example computes it."""
import importlib.util
from pathlib import Path

import numpy as np
from scipy.special import ndtr, ndtri

SCRIPT = Path(__file__).resolve().parents[2] / "research" / "measure_speeds.py"
spec = importlib.util.spec_from_file_location("measure_speeds", SCRIPT)
script = importlib.util.module_from_spec(spec)
spec.loader.exec_module(script)


def test_recipe_is_the_examples_deque_over_its_length_in_seconds():
    fps = 10
    frames = np.arange(30)
    ids = np.r_[np.zeros(15, int), np.ones(15, int)]
    positions = np.column_stack([np.zeros(30), 1.0 * frames / fps])  # 1 m/s straight ahead
    positions[15:] *= 2  # the second track: 2 m/s
    speeds = script.recipe_speeds(positions[::-1], frames[::-1], ids[::-1], fps)[::-1]  # any row order
    # nothing until the deque holds fps / 2 = 5 positions, then distance over len / fps: n - 1 steps in n frames
    assert np.isnan(speeds[:4]).all() and np.isnan(speeds[15:19]).all()
    np.testing.assert_allclose(speeds[4:10], [1 * (n - 1) / n for n in range(5, 11)])
    np.testing.assert_allclose(speeds[10:15], 0.9)  # the deque is full: 9 steps of 0.1 m over 10 / fps s
    np.testing.assert_allclose(speeds[25:30], 1.8)


def test_spread_over_datasets_is_mean_min_max_of_each_ones_figures():
    def results(rel: float, covered: float) -> dict:  # one method, 4 boxes at 10 m, 20 m, 40 m, 10 m
        n = 4
        return {"m": {"rel": np.full(n, rel), "err": np.full(n, rel / 100), "range": np.array([10.0, 20, 40, 10]),
                      "inner": np.ones(n, bool), "cover1": np.arange(n) < covered * n, "cover2": np.ones(n, bool),
                      "pos1": np.full(n, np.nan), "pos2": np.full(n, np.nan)}}
    lines = script.spread_table([results(2.0, 1.0), results(4.0, 0.5)], "rgb", 16).splitlines()
    row = [c.strip() for c in lines[-1].strip("|").split("|")]
    assert row[0] == "m"
    assert row[1:5] == ["3.0 [2.0, 4.0]"] * 4  # each band's median: 2 % in one dataset, 4 % in the other
    assert row[5] == "3.0 [2.0, 4.0]"  # the 5-50 m 90th percentile
    assert row[6:] == ["75.0 [50.0, 100.0]", "100.0 [100.0, 100.0]", "-", "-"]  # 1-sigma: all, half; no positions


def test_exact_mapping_is_the_cameras_own_through_its_lens(tmp_path):
    from homocal.dataset import load_dataset
    from synthetic_dataset import write_dataset

    barrel = [-0.2, 0.04, 5e-4, -3e-4, 0.0]
    ds = load_dataset(write_dataset(tmp_path / "d", "lensy", n_test=30, distortion=barrel))
    gt = ds.table("gt.parquet").to_pandas()
    pixels, ground = gt[["u", "v"]].to_numpy(float), gt[["x", "y"]].to_numpy(float)  # the camera's projections
    mapped = script.exact_transformer(ds).transform_points(script.undistorted(ds, pixels))
    # the lens's inverse converges to about 1e-6 px; a pixel is at most 0.3 m at 45 m on this camera
    np.testing.assert_allclose(mapped, ground, atol=1e-5)


def test_horizon_table_counts_z_within_one_and_two_sigma():
    rows = [{"detector": "rgb", "error": e, "sigma": 2.0, "sigma_people": 1.0} for e in (-1.0, 3.0, 5.0, 0.4)]
    rows.append({"detector": "rgb", "error": np.nan, "sigma": np.nan, "sigma_people": np.nan, "refusal": "too few"})
    row = [c.strip() for c in script.horizon_table(rows).splitlines()[-1].strip("|").split("|")]
    # z = -0.5, 1.5, 2.5, 0.2 against the whole sigma; -1, 3, 5, 0.4 against the people's
    assert row[:3] == ["rgb", "4 (1)", f"{np.sqrt((1 + 9 + 25 + 0.16) / 4):.2f}"]
    mean = (-1 + 3 + 5 + 0.4) / 4
    assert row[3] == f"{mean:+.2f}, {np.sqrt(sum((e - mean) ** 2 for e in (-1, 3, 5, 0.4)) / 3):.2f}"
    assert row[4] == "2.00"
    assert row[5] == f"50 %, 75 %, {np.sqrt((0.25 + 2.25 + 6.25 + 0.04) / 4):.2f}, {(-0.5 + 1.5 + 2.5 + 0.2) / 4:+.2f}"
    assert row[6] == f"1.00; 25 %, 50 %, {np.sqrt((1 + 9 + 25 + 0.16) / 4):.2f}"


def test_expected_coverage_against_sampled_errors():
    S, a = np.array([1.0, 2.0]), np.array([0.6, 0.0])  # one box mostly the track's error, one all of it
    z = np.array([0.0, 0.5, 3.0])
    rng = np.random.default_rng(1)
    n = 50_000
    for k in (1, 2):
        got = script.expected_coverage(S, a, z, k)
        for d, zd in enumerate(z):  # each box's error a z + e, e ~ N(0, S^2 - a^2), sampled
            e = a * zd + np.sqrt(S**2 - a**2) * rng.standard_normal((n, 2))
            # a share of n samples: its sd is at most 0.5 / sqrt(n) ~ 0.0022; 5 sd
            assert abs(got[d] - np.mean(np.abs(e) <= k * S)) < 0.011
    # no shared part: the normal's own 68.3 / 95.4 %
    np.testing.assert_allclose(script.expected_coverage(S, np.zeros(2), np.array([1.7]), 1), 0.6827, atol=1e-4)


def walkers(tmp_path, speed: float = 1.4, seconds: float = 4.0, fps: int = 20):
    """A synthetic dataset (tests/synthetic_dataset.py's pinhole camera) of three people walking straight at
    ``speed`` m/s, their boxes' foot points the exact projections of their true ground points."""
    import json

    import pyarrow as pa
    import pyarrow.parquet as pq

    from homocal.geometry import PinholeCamera
    from synthetic_dataset import write_dataset

    path = write_dataset(tmp_path / "d", n_test=10)
    manifest = json.loads((path / "manifest.json").read_text())
    (path / "manifest.json").write_text(json.dumps(manifest | {"fps": fps, "gt_dt": 1 / fps, "seconds": seconds}))
    steps = np.arange(int(seconds * fps))
    starts, headings = np.array([[-2.0, 10.0], [1.0, 30.0], [3.0, 15.0]]), np.array([[0.6, 0.8], [-1.0, 0.0], [0.0, 1.0]])
    xy = starts[:, None] + speed * headings[:, None] * steps[None, :, None] / fps  # (agents, steps, 2) m
    uv = PinholeCamera().project_ground(xy.reshape(-1, 2))
    agent, step = np.repeat(np.arange(3, dtype=np.int32), len(steps)), np.tile(steps, 3)
    height = 4000 / np.hypot(*xy.reshape(-1, 2).T)  # px, shrinking with range (its value sets only the bars)
    pq.write_table(pa.table({"agent_id": agent, "step": step, "t": step / fps, "x": xy[..., 0].ravel(),
                             "y": xy[..., 1].ravel(), "u": uv[:, 0], "v": uv[:, 1], "in_frame": np.ones(len(agent), bool)}),
             path / "gt.parquet")
    pq.write_table(pa.table({"detector": ["segmentation"] * len(agent), "frame": step, "agent_id": agent,
                             "x1": uv[:, 0] - height / 4, "y1": uv[:, 1] - height, "x2": uv[:, 0] + height / 4,
                             "y2": uv[:, 1], "u": uv[:, 0], "v": uv[:, 1], "gt_x": xy[..., 0].ravel(),
                             "gt_y": xy[..., 1].ravel()}), path / "detections.parquet")
    return path


def test_exact_path_measures_the_true_speeds_of_exact_foot_points(tmp_path):
    path = str(walkers(tmp_path))
    for noise in ({}, {"box_sigma": True}, {"correlated": True}):
        p = script.evaluate([path], "segmentation", 16, exact=True, **noise)
        assert set(p) == {"exact, filter", "exact, smoother", "exact, 1 s diff"}
        # noise-free points on a straight walk: the smoother is exact but for its start's velocity prior (0 +- 10
        # m/s) near a track's ends; the clicked trapezoid's horizon 16 px off errs by tens of percent (docs/measure.md)
        assert np.nanpercentile(p["exact, smoother"]["rel"], 90) < 1.0
        # the recipe's n - 1 steps over n / fps s, once its deque holds fps positions: 1 / fps short, 5 %
        np.testing.assert_allclose(np.nanmedian(p["exact, 1 s diff"]["rel"]), 100 / 20, rtol=1e-6)
    # straight walks at constant velocity: no true velocity change, so every box is in --steadiness' first bin
    change = p["exact, smoother"]["change"]
    assert np.isfinite(change).any() and np.nanmax(change) < 1e-9
    rows = script.steadiness_table(p, "segmentation").splitlines()[4:]
    assert rows[0].startswith("| exact, smoother | 0-0.1 |") and rows[1] == ""
    # exact foot points: every position inside its bars
    assert rows[-1] == "| exact, smoother | 100.0 / 100.0 % | 100.0 / 100.0 % |"


def test_steadiness_table_gives_the_bar_scale_that_would_cover():
    """Per range band, the quantiles of |error| / sigma at a normal's 1 and 2 sigma shares: errors that are |N(0, 1)|
    (its evenly spaced quantiles) with sigma 1 give 1 and 2 and cover 68.3 / 95.4 %; the same errors with a bar
    twice as wide give 0.5 and 1, and 95.4 / 100 % covered."""
    n = 20_000
    err = np.abs(ndtri((np.arange(n) + 0.5) / n))  # |N(0, 1)|'s quantiles
    rng = np.where(np.arange(n) % 2, 10.0, 40.0)  # every other one at 5-15 m, the others at 30-50 m
    share = 100 * np.array([ndtr(1) - ndtr(-1), ndtr(2) - ndtr(-2)])
    for scale, covered, reach in ((1.0, share, [1.0, 2.0]), (2.0, [share[1], 100.0], [0.5, 1.0])):
        sigma = np.full(n, scale)
        p = {"k, smoother": {"err": err, "sigma": sigma, "range": rng, "change": np.zeros(n),
                             "cover1": err <= sigma, "cover2": err <= 2 * sigma, "pos1": np.ones(n), "pos2": np.ones(n),
                             "ellipse1": np.ones(n), "ellipse2": np.ones(n)}}
        for band in ("5-15", "30-50", "5-50"):
            row = [r for r in script.steadiness_table(p, "rgb").splitlines() if r.startswith(f"| k, smoother | {band} |")]
            cells = [[float(v) for v in c.strip(" %").split(" / ")] for c in row[0].strip("|").split("|")[2:]]
            # the table's rounding (0.05 % and 0.005) and a band's quantile step (2 / n; in |error| / sigma at most
            # 2 / n over |N(0, 1)|'s density at 2, 0.108)
            np.testing.assert_allclose(cells[0], covered, atol=0.05 + 100 * 2 / n)
            np.testing.assert_allclose(cells[1], reach, atol=0.005 + 2 / n / 0.108)


def test_foot_scale_scales_the_filters_measurement_noise(tmp_path):
    """--foot-scale C multiplies the filter's R by C^2 (the fixed model, the true mapping, --exact: R is the foot
    point's noise alone): at a process noise of nearly zero (1e-12 m^2/s^3) the smoothed velocity is a least-squares
    line through the points, its variance R's scale, so C = 2 doubles every speed's sigma, but for the parts that do
    not scale (q and the start's priors, 100 m and 10 m/s: under 1e-4 of the sigma here); a C 5 % off would miss
    by 5 %: 1e-3."""
    path = str(walkers(tmp_path))
    sigma = [script.evaluate([path], "segmentation", 16, accel_psd=1e-12, exact=True, foot_scale=c)["exact, smoother"]["sigma"]
             for c in (1.0, 2.0)]
    np.testing.assert_allclose(sigma[1], 2 * sigma[0], rtol=1e-3)


def test_student_tails_measure_the_true_speeds_of_exact_foot_points(tmp_path):
    """--foot-noise-tails student (with fixed): noise-free points on straight walks are measured as
    with normal noise (the smoother exact but for its start's velocity prior near a track's ends), and the
    bars differ from the normal noise's (another scale, weights above 1 on points that lie where expected)."""
    path = str(walkers(tmp_path))
    p = {tails: script.evaluate([path], "segmentation", 16, exact=True, foot_tails=tails)["exact, smoother"]
         for tails in ("normal", "student")}
    assert np.nanpercentile(p["student"]["rel"], 90) < 1.0
    assert not np.allclose(p["student"]["sigma"], p["normal"]["sigma"])


def test_box_margin_as_homocal_measure_takes_it(tmp_path, capsys):
    """--box-margin PX: homocal measure's trim (PX / 2 off each box's top and bottom edge: the foot points PX / 2
    up) and its "short" feet, boxes no taller than PX not measured, their share on stderr (a track of short boxes
    alone has no state)."""
    import pyarrow.parquet as pq

    path = walkers(tmp_path)
    det = pq.read_table(path / "detections.parquet")
    short = int(np.sum(np.asarray(det["y2"]) - np.asarray(det["y1"]) <= 150.0))
    assert 0 < short < det.num_rows  # the walkers' far boxes
    given = script.evaluate([str(path)], "segmentation", 16, exact=True)["exact, smoother"]
    trimmed = script.evaluate([str(path)], "segmentation", 16, exact=True, box_margin_px=150.0)["exact, smoother"]
    assert f"short {short:,} ({100 * short / det.num_rows:.1f} %)" in capsys.readouterr().err
    assert 0 < len(trimmed["rel"]) < len(given["rel"])
    assert np.nanmedian(trimmed["rel"]) > 10 * np.nanmedian(given["rel"])  # the feet 75 px up: far off the truth


def test_box_margin_is_refused_where_the_boxes_are_read_as_detected(capsys):
    for mode in (["--draws", "10"], ["--fit-imm"], ["--horizons", "10"], ["--throughput", "1"]):
        try:
            script.main(["d", "--box-margin", "2", *mode])
        except SystemExit as e:
            assert e.code == 2
        else:
            raise AssertionError(f"--box-margin with {mode} was not refused")
        assert "--box-margin: for the speed tables only" in capsys.readouterr().err


def test_box_margin_bad_values_are_refused_in_one_line(capsys):
    for text in ("nan", "inf", "-1", "65", "1e308", "two", ""):
        try:
            script.main(["d", "--box-margin", text])
        except SystemExit as e:
            assert e.code == 2
        else:
            raise AssertionError(f"--box-margin {text!r} was not refused")
        err = capsys.readouterr().err
        last = err.strip().splitlines()[-1]  # argparse's usage, then one line naming the flag
        assert "error: argument --box-margin: " in last and sum("--box-margin:" in x for x in err.splitlines()) == 1, err

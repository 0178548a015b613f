"""research/measure_speeds.py: supervision's speed recipe as its example computes it."""
import importlib.util
from pathlib import Path

import numpy as np

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

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

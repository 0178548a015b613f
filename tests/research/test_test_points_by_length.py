"""research/test_points_by_length.py: its KS distance against scipy's, its prefixes against the dataset's own rows,
and its bad input."""
import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from scipy import stats

SCRIPT = Path(__file__).resolve().parents[2] / "research" / "test_points_by_length.py"
spec = importlib.util.spec_from_file_location("test_points_by_length", SCRIPT)
script = importlib.util.module_from_spec(spec)
spec.loader.exec_module(script)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_ks_distance_is_scipys_two_sample_statistic(seed):
    rng = np.random.default_rng(seed)
    a, b = rng.normal(size=300), rng.normal(0.3, 1.2, size=500)
    assert script.ks_distance(a, b) == pytest.approx(stats.ks_2samp(a, b).statistic, abs=1e-12)
    assert script.ks_distance(a, a) == 0


def test_a_prefix_keeps_the_rows_before_its_time_and_the_study_reads_it(tiny_dataset, tmp_path):
    out = script.prefix(tiny_dataset, 1.0, tmp_path)
    t = pq.read_table(out / "gt.parquet").column("t").to_numpy()
    whole = pq.read_table(tiny_dataset / "gt.parquet").column("t").to_numpy()
    assert len(t) == int(np.sum(whole < 1.0)) > 0 and t.max() < 1.0
    distance, lateral = script.draw(out)
    assert len(distance) == len(lateral) > 0 and np.all(distance <= script.STUDY.max_test_distance)


@pytest.mark.parametrize("args, message", [
    (["--seconds", "0"], "--seconds"), (["--seconds", "x"], "--seconds"), (["--seconds", "nan"], "--seconds"),
    (["--seconds", "5,5.0"], "--seconds")])  # twice: one prefix folder per length
def test_bad_seconds_are_one_line(args, message, tiny_dataset):
    done = subprocess.run([sys.executable, str(SCRIPT), str(tiny_dataset), *args], capture_output=True, text=True)
    assert done.returncode == 2 and message in done.stderr and done.stdout == ""


def test_a_folder_that_is_not_a_dataset_is_one_line(tmp_path):
    done = subprocess.run([sys.executable, str(SCRIPT), str(tmp_path)], capture_output=True, text=True)
    assert done.returncode == 1 and done.stderr.count("\n") == 1 and "not" in done.stderr

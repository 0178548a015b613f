"""The report's out-of-core aggregation (homocal.study.aggregate) against numpy on the whole columns in memory."""
from __future__ import annotations

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from homocal.study import aggregate, figures, metrics

PERCENTS = (0, 1, 2.5, 25, 50, 75, 99, 100)


def awkward(rng: np.random.Generator, n: int) -> np.ndarray:
    """float32 values (n,) with repeats, signed zeros, tiny and huge magnitudes, many in one narrow range."""
    parts = [rng.normal(0, 50, n), rng.integers(-3, 3, n).astype(float), np.full(n, -0.0), rng.normal(90, 1e-3, n),
             rng.choice([1e-40, -1e-40, 3e38, -3e38], n)]
    return rng.permutation(np.concatenate(parts))[:n].astype(np.float32)


def two_passes(q: aggregate.Quantiles, batches: list[np.ndarray]) -> list[float]:
    for values in batches:
        q.add(values)
    q.second_pass()
    for values in batches:
        q.add(values)
    return q.values()


@pytest.mark.parametrize("n", [1, 2, 5, 1000, 30000])
@pytest.mark.parametrize("seed", [0, 1])
def test_quantiles_equal_numpy_percentile(n, seed):
    values = awkward(np.random.default_rng(seed), n)
    batches = np.array_split(values, 7)
    got = two_passes(aggregate.Quantiles(PERCENTS), batches)
    expected = np.percentile(values.astype(np.float64), PERCENTS)
    np.testing.assert_array_equal(got, expected)


def test_quantiles_of_nothing_are_nan():
    assert np.isnan(two_passes(aggregate.Quantiles((50,)), [np.empty(0, np.float32)])).all()


def test_sortable_keys_sort_as_the_values_and_map_back():
    values = awkward(np.random.default_rng(2), 5000)
    keys = aggregate.sortable_keys(values)
    order = np.argsort(keys, kind="stable")
    assert (np.diff(values[order].astype(np.float64)) >= 0).all()
    assert [aggregate.key_value(int(k)) for k in keys[:200]] == values[:200].astype(np.float64).tolist()


@pytest.fixture(scope="module")
def shards(tmp_path_factory):
    """Real Parquet shards of two scenes (columns as the study writes them, some values NaN or inf); returns
    ({scene: files}, {scene: {column: whole column}})."""
    root, rng = tmp_path_factory.mktemp("shards"), np.random.default_rng(5)
    files, columns = {}, {}
    for scene, n_shards in (("a", 6), ("b", 3)):
        files[scene], parts = [], []
        for v in range(n_shards):
            n = int(rng.integers(50, 400))
            cols = {"d_sum": rng.uniform(15, 120, n).astype(np.float32), "d_spread": rng.uniform(2, 40, n).astype(np.float32),
                    "hybrid_regression": rng.random(n) < 0.6}
            for m in metrics.METHODS:
                cols[f"cal_{m}"] = (100 - rng.exponential(15, n)).astype(np.float32)
                cols[f"path_{m}"] = awkward(rng, n) if m == "descent" else (rng.normal(20, 60, n)).astype(np.float32)
                cols[f"path_{m}"][rng.random(n) < 0.02] = rng.choice([np.nan, np.inf])
                cols[f"cal_{m}"][rng.random(n) < 0.005] = -np.inf
            path = root / scene / f"variant_{v:05d}.parquet"
            path.parent.mkdir(exist_ok=True)
            pq.write_table(pa.table(cols), path)
            files[scene].append(path)
            parts.append(cols)
        columns[scene] = {c: np.concatenate([p[c] for p in parts]) for c in parts[0]}
    return files, columns


def percentiles_with_failures(values: np.ndarray, qs) -> list[float]:
    """numpy's linear percentiles of values (N,) with every non-finite value a failure at -inf, below every other:
    -inf where the lower neighbour of a rank is a failure (numpy itself gives NaN there)."""
    ranked = np.sort(np.where(np.isfinite(values), values.astype(np.float64), -np.inf))
    stand_in = np.where(np.isinf(ranked), ranked[np.isfinite(ranked)].min() - 1.0, ranked)
    return [-np.inf if np.isinf(ranked[int(np.floor((len(ranked) - 1) * q / 100))]) else float(np.percentile(stand_in, q))
            for q in qs]


def numpy_stats(path: np.ndarray, cal: np.ndarray) -> dict[str, float]:
    """The table's statistics by numpy on the whole (N,) columns in memory: failures (non-finite) counted, not
    positive, at -inf in the percentiles; means and stds over the finite ones, the correlation over both finite."""
    fp, fc = np.isfinite(path), np.isfinite(cal)
    p, c = path[fp].astype(np.float64), cal[fc].astype(np.float64)
    both = fp & fc
    p01, p1, p50 = percentiles_with_failures(path, [0.1, 1, 50])
    c25, c50, c75 = percentiles_with_failures(cal, [25, 50, 75])
    return {"n": path.size, "failures": path.size - p.size, "finite": p.size, "cal_failures": cal.size - c.size,
            "pos_path": 100 * np.count_nonzero(p > 0) / path.size, "pos_cal": 100 * np.count_nonzero(c > 0) / cal.size,
            "mean_path": p.mean(), "median_path": p50, "corr": np.corrcoef(path[both], cal[both])[0, 1],
            "std_path": p.std(), "p1_path": p1, "p0.1_path": p01,
            "below_minus100": 100 * (np.count_nonzero(p < -100) + path.size - p.size) / path.size, "median_cal": c50, "iqr_cal": c75 - c25, "std_cal": c.std()}


def test_table_equals_numpy_in_memory(shards):
    files, columns = shards
    table = metrics.build_table(files)
    for scope in ("a", "b", metrics.OVERALL):
        scenes = ["a", "b"] if scope == metrics.OVERALL else [scope]
        col = lambda name: np.concatenate([columns[s][name] for s in scenes])  # noqa: E731
        for m in metrics.METHODS:
            expected = numpy_stats(col(f"path_{m}"), col(f"cal_{m}"))
            got = {k: table.value(m, k, scope) for k in expected}
            assert got == pytest.approx(expected, rel=1e-9, abs=1e-9)
            assert (got["median_path"], got["p1_path"], got["iqr_cal"]) == (expected["median_path"], expected["p1_path"], expected["iqr_cal"])
            assert got["p0.1_path"] == expected["p0.1_path"]


def test_histogram_equals_numpy_in_memory(shards):
    files, columns = shards
    edges = np.arange(-200.0, 101.0, 2.0)
    hist = figures.ColumnHistogram(edges)
    for first in (True, False):
        for _, batch in aggregate.scan(files, ["path_descent"]):
            hist.add(batch["path_descent"])
        if first:
            hist.second_pass()
    values = np.concatenate([columns[s]["path_descent"] for s in files])
    failed = ~np.isfinite(values)
    finite = values[~failed]
    np.testing.assert_array_equal(hist.counts, np.histogram(finite, edges)[0])
    assert hist.failures == np.count_nonzero(failed) > 0
    assert (hist.below, hist.above) == (np.count_nonzero(finite < -200) + hist.failures, np.count_nonzero(finite > 100))
    assert hist.median.values() == percentiles_with_failures(values, [50])  # as the table's median


def test_heatmap_means_equal_numpy_in_memory(shards):
    files, columns = shards
    bins = 7
    x_edges, y_edges, means, failures = figures.heatmap_means(files, bins)
    col = lambda name: np.concatenate([columns[s][name] for s in files])  # noqa: E731
    d_sum, d_spread = col("d_sum"), col("d_spread")
    np.testing.assert_array_equal(x_edges, np.linspace(float(d_sum.min()), float(d_sum.max()), bins + 1))
    np.testing.assert_array_equal(y_edges, np.linspace(float(d_spread.min()), float(d_spread.max()), bins + 1))
    for m in set(metrics.METHODS) - {"descent"}:  # descent's awkward +/-3e38 make cell sums depend on the order
        path = col(f"path_{m}")
        ok = np.isfinite(path)
        assert failures[m] == np.count_nonzero(~ok) > 0
        total, _, _ = np.histogram2d(d_spread[ok], d_sum[ok], [y_edges, x_edges], weights=path[ok].astype(np.float64))
        count, _, _ = np.histogram2d(d_spread[ok], d_sum[ok], [y_edges, x_edges])
        np.testing.assert_array_equal(means[m].mask, count == 0)
        np.testing.assert_allclose(means[m].filled(0), np.divide(total, count, out=np.zeros_like(total), where=count > 0),
                                   rtol=1e-12)


def test_heatmap_figure_has_a_panel_for_every_method(shards):
    """One panel per method, titled with its name, in METHODS order (a fixed 2 x 2 grid once showed only the first
    four of six methods, descent not among them)."""
    files, _ = shards
    fig, _, _ = figures.heatmap_figure(*figures.heatmap_means(files, 5)[:3])
    assert [ax.get_title() for ax in fig.axes if ax.get_title()] == list(metrics.METHODS)

"""Tests of homocal.study.metrics, figures and report on small hand-made results directories.

Expected statistics come from the standard library (statistics, exact rational arithmetic) on the
float32-rounded values, never from numpy.
"""
from __future__ import annotations

import csv
import io
import json
import math
import statistics
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from matplotlib.image import imread

from homocal.cli import main
from homocal.dataset import load_dataset
from homocal.geometry import ViewTransformer
from homocal.study import figures, metrics, report
from homocal.study.inputs import StudyParams

from study_results import METHODS, PARAMS, SCENES, VARIANTS, f32, write_results, write_shard  # noqa: F401



def expected_stats(path: list[float], cal: list[float], chose: list[bool] | None) -> dict[str, float]:
    """The table's statistics by the standard library (population std, numpy-compatible 'inclusive' quantiles)."""
    pct = statistics.quantiles(path, n=100, method="inclusive")
    quart = statistics.quantiles(cal, n=4, method="inclusive")
    out = {
        "n": len(path), "failures": 0, "finite": len(path), "cal_failures": 0,
        "pos_path": 100 * sum(p > 0 for p in path) / len(path),
        "pos_cal": 100 * sum(c > 0 for c in cal) / len(cal),
        "mean_path": statistics.fmean(path), "median_path": statistics.median(path),
        "corr": statistics.correlation(path, cal), "std_path": statistics.pstdev(path), "p1_path": pct[0],
        "p0.1_path": statistics.quantiles(path, n=1000, method="inclusive")[0],
        "below_minus100": 100 * sum(p < -100 for p in path) / len(path),
        "median_cal": statistics.median(cal), "iqr_cal": quart[2] - quart[0], "std_cal": statistics.pstdev(cal),
    }
    if chose is not None:
        out["chose_regression"] = 100 * sum(chose) / len(chose)
    return out


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    root = tmp_path_factory.mktemp("results")
    return root, write_results(root)


@pytest.fixture(scope="module")
def table(results):
    root, _ = results
    return metrics.build_table(metrics.shard_files(root, metrics.load_study(root)))


class TestMethodStats:
    def test_by_hand(self):
        # path = 5 cal - 100 exactly: correlation 1; sorted path -50, 0, 50, 100
        s = metrics.method_stats(np.array([0, -50, 100, 50], np.float32), np.array([20, 10, 40, 30], np.float32))
        expected = {"n": 4, "failures": 0, "finite": 4, "cal_failures": 0, "pos_path": 50.0, "pos_cal": 100.0, "mean_path": 25.0, "median_path": 25.0,
                    "corr": 1.0, "std_path": math.sqrt(3125), "p1_path": -48.5,  # -50 + 0.03 * 50
                    "p0.1_path": -49.85, "below_minus100": 0.0,
                    "median_cal": 25.0, "iqr_cal": 15.0, "std_cal": math.sqrt(125)}  # quartiles 17.5 and 32.5
        assert s == pytest.approx(expected)

    def test_failures_are_counted_below_every_percentile(self):
        """A failed correction (NaN path improvement) is a sample: counted, not positive, at -inf in the percentiles;
        the mean and std are over the finite samples, the correlation over those with both finite."""
        path = np.array([10, np.nan, 30, 50, -20], np.float32)
        cal = np.array([1, 2, -np.inf, 3, 4], np.float32)
        s = metrics.method_stats(path, cal)
        assert (s["n"], s["failures"], s["finite"], s["cal_failures"]) == (5, 1, 4, 1)
        assert s["pos_path"] == 60.0 and s["pos_cal"] == 80.0
        assert s["mean_path"] == pytest.approx(17.5) and s["std_path"] == pytest.approx(np.std([10, 30, 50, -20]))
        assert s["median_path"] == 10.0  # sorted -inf, -20, 10, 30, 50
        assert s["p1_path"] == s["p0.1_path"] == -math.inf and s["median_cal"] == 2.0  # cal sorted -inf, 1, 2, 3, 4
        assert s["below_minus100"] == 20.0  # the failure's error more than doubled
        assert s["corr"] == pytest.approx(np.corrcoef([10, 50, -20], [1, 3, 4])[0, 1])

    def test_no_samples_gives_nan(self):
        s = metrics.method_stats(np.empty(0, np.float32), np.empty(0, np.float32), np.empty(0, bool))
        assert s["n"] == 0 and math.isnan(s["median_path"]) and math.isnan(s["chose_regression"])


class TestTable:
    def test_csv_has_the_tail_rows_of_every_method(self, table):
        rows = {(r["method"], r["metric"]) for r in csv.DictReader(io.StringIO(metrics.to_csv(table)))}
        assert {(m, k) for m in METHODS for k in ("below_minus100", "p0.1_path", "failures")} <= rows

    @pytest.mark.parametrize("method", METHODS)
    @pytest.mark.parametrize("scope", [*SCENES, metrics.OVERALL])
    def test_matches_standard_library(self, results, table, method, scope):
        _, stored = results
        scenes = list(SCENES) if scope == metrics.OVERALL else [scope]
        col = lambda name: [v for s in scenes for v in stored[s][name]]  # noqa: E731
        chose = col("hybrid_regression") if method == "hybrid" else None
        expected = expected_stats(col(f"path_{method}"), col(f"cal_{method}"), chose)
        got = {key: table.value(method, key, scope) for key in expected}
        assert got == pytest.approx(expected, rel=1e-9, abs=1e-9)

    def test_scopes_and_overall_counts(self, results, table):
        _, stored = results
        assert table.scopes == ("alpha", "beta", "overall")
        for method in METHODS:
            n = [table.value(method, "n", s) for s in SCENES]
            assert n == [len(stored[s]["variant"]) for s in SCENES]
            assert table.value(method, "n") == sum(n)
            shares = [table.value(method, "pos_path", s) for s in SCENES]
            assert table.value(method, "pos_path") == pytest.approx(np.dot(shares, n) / sum(n))

    def test_paper_column_only_for_regression_and_descent(self, table):
        papers = {(r.method, r.metric): r.paper for r in table.rows if r.paper is not None}
        assert papers[("regression", "pos_path")] == 93.0 and papers[("descent", "p1_path")] == -3.8
        assert {m for m, _ in papers} == {"regression", "descent"}

    def test_csv_holds_the_table_at_full_precision(self, table):
        rows = list(csv.DictReader(io.StringIO(metrics.to_csv(table))))
        assert len(rows) == len(table.rows)
        for row, r in zip(rows, table.rows):
            assert (row["method"], row["metric"]) == (r.method, r.metric)
            assert [float(row[s]) for s in table.scopes] == list(r.values)
            assert row["paper"] == ("" if r.paper is None else str(r.paper if r.metric != "n" else int(r.paper)))

    def test_text_and_markdown_show_every_row(self, table):
        text, md = metrics.to_text(table), metrics.to_markdown(table)
        for label, _ in metrics.METRICS.values():
            assert label in text and f"| {label} |" in md
        line = next(x for x in md.splitlines() if x.startswith("| median path improvement"))
        assert line.endswith("| 90.0 |")  # regression's paper value comes first


class TestReportCommand:
    def test_end_to_end(self, results, tmp_path, capsys):
        root, _ = results
        out = tmp_path / "page"
        assert main(["report", str(root), "--out", str(out)]) == 0
        printed = capsys.readouterr().out.strip().splitlines()
        page = Path(printed[-1])
        assert page == out / "report.html" and page.is_file()
        html = page.read_text()
        for label, _ in metrics.METRICS.values():
            assert label in html
        assert "Degenerate trapezoid variants: 1" in html and "collinear vertices" in html
        assert "dataset not available" in html  # the datasets of this study do not exist: figures left out, said so
        pngs = sorted((out / "figures").glob("*.png"))
        assert [p.name for p in pngs] == ["improvement_histograms.png", "path_heatmaps.png", "path_improvement.png"]
        for png in pngs:
            assert f"figures/{png.name}" in html
            assert_nontrivial_png(png)
        assert (out / "table.md").read_text().count("### ") == len(METHODS)
        assert (out / "table.csv").read_text().startswith("method,metric,alpha,beta,overall,paper")

    @pytest.mark.slow  # a whole report drawn
    def test_page_reads_as_a_page(self, results, tmp_path):
        """A table of contents linking every section; the headline figure before every other; the settings as the
        study's flags with their units, never study.json's keys, raw JSON or null."""
        import re
        from html.parser import HTMLParser

        root, _ = results
        report.write_report(root, tmp_path / "page")
        page = (tmp_path / "page" / "report.html").read_text()

        class Text(HTMLParser):  # the text a reader sees: the body's, not the style sheet's
            words: list[str] = []
            tag = ""

            def handle_starttag(self, tag, attrs):
                self.tag = tag

            def handle_data(self, data):
                if self.tag not in ("style", "title"):
                    self.words.append(data)

        reader = Text()
        reader.feed(page)
        text = " ".join(reader.words)
        for raw in ("null", "{\"", "[\"", "\": ", "[{", "n_variants", "samples_degenerate", "n_degenerate",
                    "max_test_distance"):  # no JSON, no study.json key
            assert raw not in text, raw
        sections = re.findall(r"<h2 id='(section-\d+)'>", page)
        assert len(sections) >= 4 and all(f"<a href='#{s}'>" in page for s in sections)
        assert page.index("<nav>") < page.index("<h2 ")
        first, second = [m.start() for m in re.finditer(r"<figure>", page)][:2]
        assert first < page.index("figures/path_improvement.png") < second  # the headline is the first figure
        assert page.index("figures/path_improvement.png") < page.index(">Reproduction of the paper's Table 1</h2>")
        rows = dict(re.findall(r"<tr><td>(--[a-z-]+)</td><td>([^<]*)</td>", page))
        assert rows["--variants"] == str(PARAMS.n_variants) and rows["--n-test"] == str(PARAMS.n_test)
        assert rows["--max-test-distance"] == f"{PARAMS.max_test_distance:g} m"
        assert rows["--horizon-shift"] == "none"
        assert f"--variants {PARAMS.n_variants}" in text

    def test_headline_medians_per_scene(self, results, tmp_path):
        """The headline figure's medians are each scene's own (the standard library's median of its shards'
        values); the scenes are its panels."""
        root, stored = results
        shards = metrics.shard_files(root, metrics.load_study(root))
        edges = np.arange(-100.0, 101.0, 2.0)
        hists = figures.column_histograms(shards, [f"path_{m}" for m in METHODS], edges, "test", per_scene=True)
        assert {scene for scene, _ in hists} == set(SCENES)
        for (scene, column), h in hists.items():
            assert h.median.values()[0] == pytest.approx(statistics.median(stored[scene][column]), abs=1e-4)
            inside = [v for v in stored[scene][column] if -100 <= v <= 100]
            assert h.counts.sum() == len(inside)

    def test_shards_without_a_column_are_bad_input(self, tmp_path, capsys):
        write_results(tmp_path)
        write_shard(tmp_path, "beta", 0, {"variant": [0] * math.comb(len(SCENES["beta"]), 3)})  # a shard, but columns missing
        assert main(["report", str(tmp_path)]) == 2
        assert "the shards have no column(s) path_regression, cal_regression" in capsys.readouterr().err

    @pytest.mark.parametrize("make", [
        lambda d: d / "missing",
        lambda d: d,  # a folder without study.json
        lambda d: (d / "study.json").write_text("{not json") and d,
        lambda d: (d / "study.json").write_text('{"datasets": [{"scene": "a"}]}') and d,  # no shards
    ])
    def test_bad_input_exits_2_with_one_line(self, tmp_path, capsys, make):
        assert main(["report", str(make(tmp_path))]) == 2
        err = capsys.readouterr().err
        assert err.startswith("homocal: error: ") and err.count("\n") == 1
        assert not (tmp_path / "report").exists()


@pytest.fixture
def dataset_dir(tiny_dataset) -> Path:
    """The real simgen dataset of tests/conftest.py."""
    return tiny_dataset


def write_variants(path: Path) -> None:
    """variants/<scene>.parquet: variant 0 unperturbed, 1 degenerate, 2 and 3 perturbed (offsets in px)."""
    offsets = np.zeros((4, 16))
    offsets[1, 0], offsets[2, [1, 9]], offsets[3, [4, 5, 14]] = 3, (2, -1), (-3, 1, 2)
    cols = {"variant": pa.array(range(4), pa.int32()), "horizon_shift_px": pa.array([None, None, 5.0, None], pa.float64())}
    cols |= {f"click_{k}": [0.0, 0.0, 0.0, 0.5] for k in range(8)}
    cols |= {f"{side}_{k}": offsets[:, 8 * s + k] for s, side in enumerate(("img", "map")) for k in range(8)}
    cols |= {"n_perturbed": pa.array((offsets != 0).sum(1), pa.int8()), "degenerate": [False, True, False, False],
             "reason": ["", "collinear vertices", "", ""]}
    path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(pa.table(cols), path)


class TestDatasetFigures:
    def test_exact_trapezoid_maps_exact_foot_points_without_error(self, dataset_dir):
        ds = load_dataset(dataset_dir)
        image, ground, _ = ds.calibration_points("exact")
        exact = ds.trapezoids["exact"]
        error = figures.ground_error(np.array(exact["image"]), np.array(exact["map"]), ds, image, ground)
        assert np.nanmax(error) < 1e-6

    def test_variant_quads_skip_degenerate_and_carry_the_base_error(self, dataset_dir, tmp_path):
        """Variant 0 and the perturbed, non-degenerate variants, each its base quad (horizon shift, click noise)
        plus its offsets; variant 2's horizon shift of 5 px puts its horizon 5 px above the true one before its offsets."""
        ds = load_dataset(dataset_dir)
        write_variants(tmp_path / "v.parquet")
        picked = figures._variant_quads(ds, tmp_path / "v.parquet", 5)
        assert [name for name, _ in picked] == ["base trapezoid (variant 0)", "variant 2", "variant 3"]
        np.testing.assert_array_equal(picked[0][1][0], ds.trapezoid_image)
        image, map_quad = picked[1][1]
        offsets = np.zeros((4, 2))
        offsets[0, 1] = 2
        np.testing.assert_array_equal(map_quad, ds.trapezoid_map + [[0, -1], [0, 0], [0, 0], [0, 0]])
        K = ds.camera.K
        shifted = ViewTransformer(image - offsets, ds.site_map.to_metres(ds.trapezoid_map)).horizon_row(K[0, 2])
        assert shifted == pytest.approx(ds.camera.horizon_row - 5.0, abs=1e-6)
        np.testing.assert_allclose(picked[2][1][0] - ds.trapezoid_image, [[0.5, 0.5], [0.5, 0.5], [-2.5, 1.5], [0.5, 0.5]])

    @pytest.mark.slow  # a whole report drawn
    def test_report_draws_them(self, dataset_dir, tmp_path):
        write_results(tmp_path, datasets={s: str(dataset_dir) for s in SCENES})
        write_variants(tmp_path / "variants" / "alpha.parquet")
        page, _, missing = report.write_report(tmp_path)
        assert missing == 0
        html = page.read_text()
        assert "dataset not available" not in html
        for name in ["error_distance_alpha.png", "error_distance_beta.png", "test_distance.png"]:
            assert f"figures/{name}" in html
            assert_nontrivial_png(tmp_path / "report" / "figures" / name)


def assert_nontrivial_png(path: Path) -> None:
    """A readable PNG of reasonable size whose pixels are not all one colour."""
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    image = imread(path)
    assert image.shape[0] > 300 and image.shape[1] > 300
    assert image[..., :3].std() > 0.05


class TestSeveralStudies:
    """homocal report STUDY [STUDY ...]: one configuration at several seeds, each Table 1 number and D as mean and
    range over them (table_spread.csv and the page)."""

    @pytest.fixture(scope="class")
    def studies(self, tmp_path_factory):
        roots = []
        for seed in (0, 1, 2):
            root = tmp_path_factory.mktemp(f"seed{seed}")
            write_results(root, seed=seed, params=StudyParams(seed=seed, n_variants=2, n_test=300))
            roots.append(root)
        return roots

    @pytest.mark.slow  # a whole report drawn
    def test_spread_table(self, studies, tmp_path, capsys):
        out = tmp_path / "report"
        assert main(["report", *map(str, studies), "--out", str(out)]) == 0
        tables = [metrics.build_table(metrics.shard_files(r, metrics.load_study(r))) for r in studies]
        rows = list(csv.DictReader((out / "table_spread.csv").open(encoding="utf-8")))
        keys = [k for k in metrics.PAPER["descent"] if k != "n"] + [k for k in metrics.PAPER["regression"] if k != "n"]
        assert len(rows) == 3 * (len(keys) + 1)  # alpha, beta, overall: Table 1's numbers and D
        for row in rows:
            if row["metric"] == "D":
                values = [metrics.paper_distance(t, row["scope"]) for t in tables]
            else:
                values = [t.value(row["method"], row["metric"], row["scope"]) for t in tables]
            assert [float(row[f"seed_{s}"]) for s in (0, 1, 2)] == values
            assert (float(row["mean"]), float(row["min"]), float(row["max"])) == pytest.approx(
                (sum(values) / 3, min(values), max(values)), rel=1e-12)
            if row["metric"] == "D":
                assert min(values) < max(values)  # three seeds, three distances
        assert "Over 3 studies of this configuration (seeds 0, 1, 2)" in (out / "report.html").read_text()

    @pytest.mark.slow  # a whole report drawn
    def test_one_study_has_a_spread_table_too(self, studies, tmp_path):
        report.write_report(studies[0], tmp_path / "one")
        rows = list(csv.DictReader((tmp_path / "one" / "table_spread.csv").open(encoding="utf-8")))
        assert all(row["mean"] == row["min"] == row["max"] == row["seed_0"] for row in rows)

    @pytest.mark.parametrize("case, message", [
        ("other n_test", "differs from .* other than by seed \\(n_test\\)"),
        ("same seed", "the same seed \\(1\\)"),
        ("other scene", "differs from .* other than by seed \\(datasets\\)"),
    ])
    def test_refused_in_one_line_before_writing(self, studies, tmp_path, capsys, case, message):
        other = tmp_path / "other"
        params = StudyParams(seed=5, n_variants=2, n_test=300 if case != "other n_test" else 200)
        if case == "same seed":
            params = StudyParams(seed=1, n_variants=2, n_test=300)
        write_results(other, params=params)
        if case == "other scene":
            study = json.loads((other / "study.json").read_text())
            study["datasets"][0]["config_hash"] = "1" * 64
            (other / "study.json").write_text(json.dumps(study))
        out = tmp_path / "report"
        with pytest.raises(ValueError, match=message):
            report.write_report(studies[0], out, replicates=[studies[1], other])
        assert not out.exists()
        assert main(["report", str(studies[0]), str(studies[1]), str(other), "--out", str(out)]) != 0
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and not out.exists()

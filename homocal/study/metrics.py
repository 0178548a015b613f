"""The paper's Table 1 (Section 6) and more, per scene and overall, from a study's results directory.

Reads only the columns it needs from the shards (``shards/<scene>/variant_NNNNN.parquet``), one shard
at a time in two passes (homocal.study.aggregate): memory does not grow with the number of samples.
Every statistic is exact over the full column: percentiles and medians are numpy's (linear
interpolation) on all samples, never sketches; means, standard deviations and correlations are sums
in float64 (about their means in the second pass). Standard deviations are population ones (ddof = 0).

A failed correction (a test point mapped beyond the horizon: the shards hold a path improvement that is not a
number) is a sample whose path error is infinite: it is counted (``failures``), is not positive and sits below
every percentile (as -inf); means and standard deviations are taken over the finite samples (``finite``), the
correlation over the samples whose two improvements are finite. A calibration improvement that is not finite
(``cal_failures``) is treated alike in the calibration statistics. Nothing is left out silently.
"""
from __future__ import annotations

import csv
import io
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from homocal.files import read_json
from homocal.names import check_name
from homocal.study.aggregate import Quantiles, scan
from homocal.study.kernels import METHODS  # the one list of the study's methods
from homocal.study.inputs import StudyParams
from homocal.study.shards import check_shard, study_key  # the shard format's one home

OVERALL = "overall"
SHARD_NAME = re.compile(r"variant_\d+\.parquet")

# key -> (label, format); the order of the table's rows
METRICS = {
    "n": ("samples", "{:,.0f}"),
    "failures": ("failed corrections (path error infinite)", "{:,.0f}"),
    "finite": ("samples with a finite path error (means and stds over them)", "{:,.0f}"),
    "cal_failures": ("calibration error infinite", "{:,.0f}"),
    "pos_path": ("positive path improvement (%)", "{:.1f}"),
    "pos_cal": ("positive calibration improvement (%)", "{:.1f}"),
    "mean_path": ("mean path improvement, finite samples (%)", "{:.1f}"),
    "median_path": ("median path improvement (%)", "{:.1f}"),
    "corr": ("path-calibration correlation, finite samples", "{:.2f}"),
    "std_path": ("path improvement std, finite samples (pp)", "{:.1f}"),
    "p1_path": ("path improvement 1st percentile (%)", "{:.1f}"),
    "p0.1_path": ("path improvement 0.1th percentile (%)", "{:.1f}"),
    "below_minus100": ("path error more than doubled: improvement below -100 %, failures included (%)", "{:.3f}"),
    "median_cal": ("calibration improvement median (%)", "{:.1f}"),
    "iqr_cal": ("calibration improvement IQR (pp)", "{:.1f}"),
    "std_cal": ("calibration improvement std, finite samples (pp)", "{:.1f}"),
    "chose_regression": ("hybrid chose regression (%)", "{:.1f}"),
}

# Table 1 and the text of Section 6 (the text gives 89.6 % for regression's median path improvement,
# the table 90.0 %; the table's value is used).
PAPER = {
    "regression": {"n": 19_038_019, "pos_path": 93.0, "pos_cal": 96.5, "mean_path": 73.9, "median_path": 90.0,
                   "corr": 0.84, "std_path": 47.4, "p1_path": -135.0, "median_cal": 95.4, "iqr_cal": 20.0},
    "descent": {"n": 19_038_019, "pos_path": 98.8, "pos_cal": 100.0, "mean_path": 76.5, "median_path": 86.1,
                "corr": 0.56, "std_path": 23.8, "p1_path": -3.8, "median_cal": 90.9, "std_cal": 8.6},
}


# The 14 numbers of the distance D to the paper: 7 per paper method (Table 1's five, the text's std and 1st
# percentile), ours "regression" (as written) against its regression, "descent" against its descent.
D_METHODS = ("regression", "descent")
D_KEYS = ("pos_path", "pos_cal", "mean_path", "median_path", "corr", "std_path", "p1_path")


def paper_gap(value: float, method: str, key: str) -> float:
    """ours - the paper's, for one of D's numbers: pp for percentages, x 100 for correlations."""
    return (value - PAPER[method][key]) * (100.0 if key == "corr" else 1.0)


def paper_distance(table: "Table", scope: str = OVERALL) -> float:
    """D, percentage points: the RMS of paper_gap over the 14 numbers D_METHODS x D_KEYS (percentages in pp,
    correlations x 100). NaN if any of ours is NaN."""
    diffs = [paper_gap(table.value(m, k, scope), m, k) for m in D_METHODS for k in D_KEYS]
    return math.sqrt(sum(d * d for d in diffs) / len(diffs))


def load_study(results_dir: str | Path) -> dict:
    """study.json of a results directory; ValueError if the folder or the file is missing or malformed."""
    results_dir = Path(results_dir)
    if not results_dir.is_dir():
        raise ValueError(f"{results_dir}: not a results directory")
    study = read_json(results_dir / "study.json")
    if (not isinstance(study.get("datasets"), list) or not study["datasets"]
            or not all(isinstance(d, dict) and "scene" in d for d in study["datasets"])):
        raise ValueError(f"{results_dir / 'study.json'}: needs a non-empty 'datasets' list of {{scene, path, config_hash}}")
    for i, d in enumerate(study["datasets"]):  # scene names become paths (shards/<scene>, figures)
        check_name(d["scene"], f"{results_dir / 'study.json'}: datasets[{i}].scene")
    return study


def shard_files(results_dir: str | Path, study: dict) -> dict[str, list[Path]]:
    """Finished shard files per scene, in variant order (a snapshot: read columns from these lists only)."""
    shards = Path(results_dir) / "shards"
    return {
        d["scene"]: sorted(p for p in (shards / d["scene"]).glob("variant_*.parquet") if SHARD_NAME.fullmatch(p.name))
        for d in study["datasets"]
    }


def verified_shard_files(results_dir: str | Path, study: dict) -> tuple[dict[str, list[Path]], int]:
    """shard_files, each checked to be the shard its name says of the study study.json describes (scene,
    variant, study key, row count: scene.check_shard), and the number of shards missing. ValueError naming
    the first file that is not."""
    try:
        params = StudyParams.from_dict(study).to_dict()
    except (TypeError, ValueError) as e:
        raise ValueError(f"{Path(results_dir) / 'study.json'}: not the parameters of this homocal's study ({e})") from None
    shards = shard_files(results_dir, study)
    for d in study["datasets"]:
        key, rows = study_key(params, d["scene"], d.get("config_hash", "")), math.comb(int(d.get("n_calibration", 0)), 3)
        for path in shards[d["scene"]]:
            check_shard(path, d["scene"], int(path.stem.split("_")[1]), key, rows)
    expected = len(study["datasets"]) * (int(study.get("n_variants", 0)) + 1)
    return shards, expected - sum(len(files) for files in shards.values())


def complete_shard_files(results_dir: str | Path, study: dict) -> dict[str, list[Path]]:
    """verified_shard_files of a complete study: ValueError (one line naming the folder) if a shard is missing."""
    shards, missing = verified_shard_files(results_dir, study)
    if missing:
        raise ValueError(f"{results_dir}: the study is not complete ({missing} shard(s) missing); finish it with "
                         "homocal study ... --resume")
    return shards


def method_columns(method: str) -> list[str]:
    """The shard columns of a method's statistics: path and calibration improvement (and the hybrid's choice)."""
    return [f"path_{method}", f"cal_{method}"] + (["hybrid_regression"] if method == "hybrid" else [])


class MethodSummary:
    """The statistics of METRICS for one method over batches of samples seen twice: add every batch,
    second_pass(), add every batch again, then stats(). Memory does not grow with the number of samples."""

    def __init__(self, hybrid: bool = False):
        self.hybrid = hybrid
        self.sums = dict.fromkeys(("n", "failures", "cal_failures", "pos_path", "pos_cal", "path", "cal", "chose", "pp",
                                   "cc", "both", "bp", "bc", "bpp", "bcc", "bpc", "below"), 0.0)
        self.path_q, self.cal_q = Quantiles((0.1, 1, 50)), Quantiles((25, 50, 75))
        self.means: tuple[float, float] | None = None  # (path, cal) over their finite samples, after the first pass

    def add(self, path: np.ndarray, cal: np.ndarray, chose_regression: np.ndarray | None = None) -> None:
        """path, cal: (N,) improvements, percent, float32 (not finite: a failure); chose_regression: (N,) bool (the
        hybrid's)."""
        fp, fc = np.isfinite(path), np.isfinite(cal)
        self.path_q.add(np.where(fp, path, np.float32(-np.inf)))  # a failure sits below every percentile
        self.cal_q.add(np.where(fc, cal, np.float32(-np.inf)))
        p, c = path[fp], cal[fc]
        s = self.sums
        if self.means is None:
            s["n"] += path.size
            s["failures"] += path.size - p.size
            s["cal_failures"] += cal.size - c.size
            s["pos_path"] += np.count_nonzero(p > 0)
            s["below"] += np.count_nonzero(p < -100) + path.size - p.size  # a failure's error is infinite
            s["pos_cal"] += np.count_nonzero(c > 0)
            s["path"] += float(p.sum(dtype=np.float64))
            s["cal"] += float(c.sum(dtype=np.float64))
            s["chose"] += np.count_nonzero(chose_regression) if self.hybrid else 0
            return
        dp, dc = p.astype(np.float64) - self.means[0], c.astype(np.float64) - self.means[1]
        s["pp"] += float(np.einsum("i,i->", dp, dp))  # einsum: no BLAS threads
        s["cc"] += float(np.einsum("i,i->", dc, dc))
        both = fp & fc  # the correlation's samples, about the same means
        bp, bc = path[both].astype(np.float64) - self.means[0], cal[both].astype(np.float64) - self.means[1]
        s["both"] += bp.size
        s["bp"] += float(bp.sum())
        s["bc"] += float(bc.sum())
        s["bpp"] += float(np.einsum("i,i->", bp, bp))
        s["bcc"] += float(np.einsum("i,i->", bc, bc))
        s["bpc"] += float(np.einsum("i,i->", bp, bc))

    def second_pass(self) -> None:
        s = self.sums
        self.means = (s["path"] / max(s["n"] - s["failures"], 1), s["cal"] / max(s["n"] - s["cal_failures"], 1))
        self.path_q.second_pass()
        self.cal_q.second_pass()

    def stats(self) -> dict[str, float]:
        """{metric key: value} for the keys of METRICS (chose_regression only for the hybrid); after both passes."""
        s, n = self.sums, int(self.sums["n"])
        finite, finite_cal = n - int(s["failures"]), n - int(s["cal_failures"])
        stats = {"n": n, "failures": int(s["failures"]), "finite": finite, "cal_failures": int(s["cal_failures"])}
        if self.hybrid:
            stats["chose_regression"] = 100 * s["chose"] / n if n else math.nan
        if n == 0:
            return stats | {k: math.nan for k in METRICS.keys() - stats.keys() - {"chose_regression"}}
        p01, p1, p50 = self.path_q.values()
        c25, c50, c75 = self.cal_q.values()
        return stats | {
            "pos_path": 100 * s["pos_path"] / n,
            "pos_cal": 100 * s["pos_cal"] / n,
            "mean_path": self.means[0] if finite else math.nan,
            "median_path": p50,
            "corr": _pearson(s["both"], s["bp"], s["bc"], s["bpp"], s["bcc"], s["bpc"]),
            "std_path": math.sqrt(s["pp"] / finite) if finite else math.nan,
            "p1_path": p1,
            "p0.1_path": p01,
            "below_minus100": 100 * s["below"] / n,
            "median_cal": c50,
            "iqr_cal": c75 - c25,
            "std_cal": math.sqrt(s["cc"] / finite_cal) if finite_cal else math.nan,
        }


def _pearson(n: float, sx: float, sy: float, sxx: float, syy: float, sxy: float) -> float:
    """Pearson's correlation of n pairs from their sums of deviations about any fixed point; NaN if undefined."""
    if n == 0:
        return math.nan
    cxx, cyy, cxy = sxx - sx * sx / n, syy - sy * sy / n, sxy - sx * sy / n
    return cxy / math.sqrt(cxx * cyy) if cxx * cyy > 0 else math.nan


def method_stats(path: np.ndarray, cal: np.ndarray, chose_regression: np.ndarray | None = None) -> dict[str, float]:
    """Statistics of one method over N samples in memory. path, cal: (N,) improvements, percent, float32;
    chose_regression: (N,) bool. Returns {metric key: value} for the keys of METRICS (chose_regression only if given)."""
    summary = MethodSummary(hybrid=chose_regression is not None)
    summary.add(path, cal, chose_regression)
    summary.second_pass()
    summary.add(path, cal, chose_regression)
    return summary.stats()


@dataclass(frozen=True)
class Row:
    """One line of the table: a metric of a method, its value per scope (scenes, then overall), the paper's."""

    method: str
    metric: str
    values: tuple[float, ...]
    paper: float | None


@dataclass(frozen=True)
class Table:
    """The study's table: scopes are the scene names then OVERALL; rows grouped by method in METHODS order."""

    scopes: tuple[str, ...]
    rows: tuple[Row, ...]

    def value(self, method: str, metric: str, scope: str = OVERALL) -> float:
        """One number of the table."""
        row = next(r for r in self.rows if r.method == method and r.metric == metric)
        return row.values[self.scopes.index(scope)]


def build_table(shards: dict[str, list[Path]], progress: bool = False) -> Table:
    """Per-scene and overall statistics of every method from the shard files of shard_files(), read in two
    passes one shard at a time (aggregate.scan). progress: a bar per pass on stderr for long reads."""
    scopes = (*shards, OVERALL)
    summaries = {(scope, m): MethodSummary(hybrid=m == "hybrid") for scope in scopes for m in METHODS}
    columns = list(dict.fromkeys(c for m in METHODS for c in method_columns(m)))
    for n in (1, 2):
        for scene, batch in scan(shards, columns, f"table, pass {n} of 2", progress):
            for m in METHODS:
                cols = [batch[c] for c in method_columns(m)]
                summaries[scene, m].add(*cols)
                summaries[OVERALL, m].add(*cols)
        if n == 1:
            for summary in summaries.values():
                summary.second_pass()
    rows = []
    for method in METHODS:
        stats = [summaries[scope, method].stats() for scope in scopes]
        paper = PAPER.get(method, {})
        rows += [Row(method, key, tuple(s[key] for s in stats), paper.get(key)) for key in METRICS if key in stats[0]]
    return Table(scopes, tuple(rows))


def table_cells(table: Table) -> list[tuple[str, list[str], list[list[str]]]]:
    """The table as text, one block per method: (method, header, rows of formatted cells)."""
    with_paper = {r.method for r in table.rows if r.paper is not None}
    blocks = []
    for method in METHODS:
        paper = method in with_paper
        header = ["metric", *table.scopes] + (["paper"] if paper else [])
        lines = [
            [METRICS[r.metric][0], *(format_metric(r.metric, v) for v in r.values)] + ([format_metric(r.metric, r.paper)] if paper else [])
            for r in table.rows
            if r.method == method
        ]
        blocks.append((method, header, lines))
    return blocks


def to_text(table: Table) -> str:
    """Fixed-width text of the table, for a terminal."""
    out = []
    for method, header, lines in table_cells(table):
        widths = [max(len(row[i]) for row in [header, *lines]) for i in range(len(header))]

        def fmt(row: list[str]) -> str:
            return "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(row, widths)))

        out += [method, fmt(header), "  ".join("-" * w for w in widths), *map(fmt, lines), ""]
    return "\n".join(out)


def to_markdown(table: Table) -> str:
    """Markdown of the table: one section and one pipe table per method."""
    out = []
    for method, header, lines in table_cells(table):
        out += [f"### {method}", "", markdown_row(header), markdown_row(["---"] + ["---:"] * (len(header) - 1))]
        out += [markdown_row(line) for line in lines] + [""]
    return "\n".join(out)


def to_csv(table: Table) -> str:
    """CSV of the table at full precision: method, metric, one column per scope, paper (empty if none)."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["method", "metric", *table.scopes, "paper"])
    for r in table.rows:
        writer.writerow([r.method, r.metric, *(csv_number(v) for v in r.values), "" if r.paper is None else csv_number(r.paper)])
    return buf.getvalue()


def format_metric(metric: str, value: float | None) -> str:
    """A value of a METRICS key as the table shows it ("n/a" for NaN, "" for None)."""
    if value is None:
        return ""
    return "n/a" if math.isnan(value) else METRICS[metric][1].format(value)


def csv_number(value: float) -> str:
    """A number as table.csv writes it: integers as they are, floats at full precision (repr), NaN empty."""
    if isinstance(value, (int, np.integer)):
        return str(value)
    return "" if math.isnan(value) else repr(float(value))


def markdown_row(cells: Sequence[str]) -> str:
    """One row of a Markdown pipe table."""
    return "| " + " | ".join(cells) + " |"

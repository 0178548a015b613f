"""The paper's Table 1 (Section 6) and more, per scene and overall, from a study's results directory.

Reads only the columns it needs from the shards (``shards/<scene>/variant_NNNNN.parquet``), one method
at a time. Every statistic is exact over the full column: percentiles and medians are numpy's
(linear interpolation) on all samples, never sketches; the overall column concatenates the scenes'
float32 columns, about 0.3 GB of float64 per method for the paper's 19,038,019 samples. Standard
deviations are population ones (ddof = 0). Samples whose path or calibration improvement is not
finite are counted and left out of every statistic.
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
import pyarrow.dataset as pds

from homocal.correctors.serialization import read_json

from homocal.study.kernels import METHODS  # the one list of the study's methods
OVERALL = "overall"
SHARD_NAME = re.compile(r"variant_\d+\.parquet")

# key -> (label, format); the order of the table's rows
METRICS = {
    "n": ("samples", "{:,.0f}"),
    "nonfinite": ("non-finite samples (left out)", "{:,.0f}"),
    "pos_path": ("positive path improvement (%)", "{:.1f}"),
    "pos_cal": ("positive calibration improvement (%)", "{:.1f}"),
    "mean_path": ("mean path improvement (%)", "{:.1f}"),
    "median_path": ("median path improvement (%)", "{:.1f}"),
    "corr": ("path-calibration correlation", "{:.2f}"),
    "std_path": ("path improvement std (pp)", "{:.1f}"),
    "p1_path": ("path improvement 1st percentile (%)", "{:.1f}"),
    "median_cal": ("calibration improvement median (%)", "{:.1f}"),
    "iqr_cal": ("calibration improvement IQR (pp)", "{:.1f}"),
    "std_cal": ("calibration improvement std (pp)", "{:.1f}"),
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


def paper_distance(table: "Table", scope: str = OVERALL) -> float:
    """D, percentage points: the RMS of (ours - paper) over the 14 numbers D_METHODS x D_KEYS (percentages in
    pp, correlations x 100). NaN if any of ours is NaN."""
    diffs = [(table.value(m, k, scope) - PAPER[m][k]) * (100.0 if k == "corr" else 1.0) for m in D_METHODS for k in D_KEYS]
    return math.sqrt(sum(d * d for d in diffs) / len(diffs))


def load_study(results_dir: str | Path) -> dict:
    """study.json of a results directory; ValueError if the folder or the file is missing or malformed."""
    results_dir = Path(results_dir)
    if not results_dir.is_dir():
        raise ValueError(f"{results_dir}: not a results directory")
    study = read_json(results_dir / "study.json")
    if not isinstance(study.get("datasets"), list) or not all(isinstance(d, dict) and "scene" in d for d in study["datasets"]):
        raise ValueError(f"{results_dir / 'study.json'}: needs a 'datasets' list of {{scene, path, config_hash}}")
    return study


def shard_files(results_dir: str | Path, study: dict) -> dict[str, list[Path]]:
    """Finished shard files per scene, in variant order (a snapshot: read columns from these lists only)."""
    shards = Path(results_dir) / "shards"
    return {
        d["scene"]: sorted(p for p in (shards / d["scene"]).glob("variant_*.parquet") if SHARD_NAME.fullmatch(p.name))
        for d in study["datasets"]
    }


def read_columns(files: Sequence[Path], columns: Sequence[str]) -> dict[str, np.ndarray]:
    """The named columns of the shards, concatenated in file order: {name: (N,) array as stored}."""
    if not files:
        return {c: np.empty(0, dtype=np.float32) for c in columns}
    dataset = pds.dataset([str(f) for f in files], format="parquet")
    missing = [c for c in columns if c not in dataset.schema.names]
    if missing:
        raise ValueError(f"{files[0].parent}: the shards have no column(s) {', '.join(missing)}")
    table = dataset.to_table(columns=list(columns))
    return {c: table.column(c).to_numpy() for c in columns}


def method_stats(path: np.ndarray, cal: np.ndarray, chose_regression: np.ndarray | None = None) -> dict[str, float]:
    """Statistics of one method over N samples. path, cal: (N,) improvements, percent; chose_regression: (N,) bool.

    Returns {metric key: value} for the keys of METRICS (chose_regression only if given).
    """
    ok = np.isfinite(path) & np.isfinite(cal)
    p, c = path[ok].astype(np.float64), cal[ok].astype(np.float64)
    stats = {"n": p.size, "nonfinite": path.size - p.size}
    if chose_regression is not None:
        stats["chose_regression"] = 100 * chose_regression[ok].mean() if p.size else math.nan
    if p.size == 0:
        return stats | {k: math.nan for k in METRICS.keys() - stats.keys() - {"chose_regression"}}
    p1, p50 = np.percentile(p, [1, 50])
    c25, c50, c75 = np.percentile(c, [25, 50, 75])
    return stats | {
        "pos_path": 100 * np.count_nonzero(p > 0) / p.size,
        "pos_cal": 100 * np.count_nonzero(c > 0) / c.size,
        "mean_path": p.mean(),
        "median_path": p50,
        "corr": pearson(p, c),
        "std_path": p.std(),
        "p1_path": p1,
        "median_cal": c50,
        "iqr_cal": c75 - c25,
        "std_cal": c.std(),
    }


def pearson(x: np.ndarray, y: np.ndarray) -> float:
    """Pearson correlation of two (N,) float64 arrays; NaN if either is constant."""
    dx, dy = x - x.mean(), y - y.mean()
    denom = math.sqrt(float(dx @ dx) * float(dy @ dy))
    return float(dx @ dy) / denom if denom > 0 else math.nan


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


def build_table(shards: dict[str, list[Path]]) -> Table:
    """Per-scene and overall statistics of every method from the shard files of shard_files()."""
    scenes = tuple(shards)
    rows = []
    for method in METHODS:
        columns = [f"path_{method}", f"cal_{method}"] + (["hybrid_regression"] if method == "hybrid" else [])
        per_scene = [list(read_columns(shards[s], columns).values()) for s in scenes]
        overall = [np.concatenate(parts) for parts in zip(*per_scene)]
        stats = [method_stats(*cols) for cols in per_scene + [overall]]
        paper = PAPER.get(method, {})
        rows += [Row(method, key, tuple(s[key] for s in stats), paper.get(key)) for key in METRICS if key in stats[0]]
    return Table(scenes + (OVERALL,), tuple(rows))


def table_cells(table: Table) -> list[tuple[str, list[str], list[list[str]]]]:
    """The table as text, one block per method: (method, header, rows of formatted cells)."""
    with_paper = {r.method for r in table.rows if r.paper is not None}
    blocks = []
    for method in METHODS:
        paper = method in with_paper
        header = ["metric", *table.scopes] + (["paper"] if paper else [])
        lines = [
            [METRICS[r.metric][0], *(_fmt(r.metric, v) for v in r.values)] + ([_fmt(r.metric, r.paper)] if paper else [])
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
        out += [f"### {method}", "", _md_row(header), _md_row(["---"] + ["---:"] * (len(header) - 1))]
        out += [_md_row(line) for line in lines] + [""]
    return "\n".join(out)


def to_csv(table: Table) -> str:
    """CSV of the table at full precision: method, metric, one column per scope, paper (empty if none)."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["method", "metric", *table.scopes, "paper"])
    for r in table.rows:
        writer.writerow([r.method, r.metric, *(_num(v) for v in r.values), "" if r.paper is None else _num(r.paper)])
    return buf.getvalue()


def _fmt(metric: str, value: float | None) -> str:
    if value is None:
        return ""
    return "n/a" if math.isnan(value) else METRICS[metric][1].format(value)


def _num(value: float) -> str:
    if isinstance(value, (int, np.integer)):
        return str(value)
    return "" if math.isnan(value) else repr(float(value))


def _md_row(cells: Sequence[str]) -> str:
    return "| " + " | ".join(cells) + " |"

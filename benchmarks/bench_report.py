"""Peak memory and time of `homocal report` on a study's results directory.

    python benchmarks/bench_report.py RESULTS_DIR [--repeats N] [--code DIR]

Runs `homocal report RESULTS_DIR -o TMP --no-progress` in a fresh process under GNU time (/usr/bin/time -v)
and prints its wall time, CPU time and peak resident memory, and the table's sample count. --code DIR runs the
homocal of another checkout (its folder on PYTHONPATH), e.g. an older commit unpacked with `git archive`, to
compare before and after; the last line gives the largest relative difference between the checkouts' tables
(table.csv, full precision) and the metrics where they differ at all.
"""
from __future__ import annotations

import argparse
import csv
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def run_report(results: Path, out: Path, code: Path) -> dict:
    """One `homocal report` in a fresh process: {wall_s, cpu_s, peak_mb}."""
    env = {**os.environ, "PYTHONPATH": str(code), "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    cmd = ["/usr/bin/time", "-v", sys.executable, "-m", "homocal.cli", "report", str(results.resolve()), "-o", str(out)]
    done = subprocess.run(cmd, cwd=code, env=env, capture_output=True, text=True, check=True)  # cwd: python -m imports from it first
    field = lambda name: re.search(rf"{re.escape(name)}: (.+)", done.stderr).group(1)  # noqa: E731
    minutes, seconds = field("Elapsed (wall clock) time (h:mm:ss or m:ss)").split(":")[-2:]
    return {"wall_s": 60 * float(minutes) + float(seconds),
            "cpu_s": float(field("User time (seconds)")) + float(field("System time (seconds)")),
            "peak_mb": int(field("Maximum resident set size (kbytes)")) / 1024}


def samples(table_csv: Path) -> int:
    """The overall sample count of the table (regression's row n)."""
    row = next(r for r in csv.DictReader(table_csv.open()) if r["method"] == "regression" and r["metric"] == "n")
    return int(float(row["overall"]))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("results", type=Path, help="a results directory written by homocal study")
    p.add_argument("--repeats", type=int, default=1, help="runs per checkout (default 1)")
    p.add_argument("--code", type=Path, action="append", default=[], metavar="DIR",
                   help="another checkout to measure as well (repeatable); this one is always measured")
    args = p.parse_args()
    tables = {}
    with tempfile.TemporaryDirectory() as tmp:
        for code in [REPO, *(c.resolve() for c in args.code)]:
            for i in range(args.repeats):
                out = Path(tmp) / f"{len(tables)}_{i}"
                r = run_report(args.results, out, code)
                print(f"{code}: homocal report of {samples(out / 'table.csv'):,} samples: {r['wall_s']:.1f} s wall, "
                      f"{r['cpu_s']:.1f} s CPU, {r['peak_mb']:.0f} MB peak resident memory", flush=True)
            tables[code] = list(csv.reader((out / "table.csv").open()))
    first, *others = tables.values()
    for other in others:
        print("tables: largest relative difference %.2g; metrics that differ: %s" % table_difference(first, other))


def table_difference(a: list[list[str]], b: list[list[str]]) -> tuple[float, str]:
    """Largest relative difference between two table.csv's values (rows method, metric, scopes..., paper), and
    the metrics where any differs."""
    worst, metrics = 0.0, set()
    for ra, rb in zip(a[1:], b[1:]):
        for x, y in zip(ra[2:], rb[2:]):
            if x != y:
                metrics.add(ra[1])
                worst = max(worst, abs(float(x) - float(y)) / max(abs(float(x)), 1e-300))
    return worst, ", ".join(sorted(metrics)) or "none"


if __name__ == "__main__":
    main()

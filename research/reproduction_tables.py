"""The tables of docs/reproduction.md from studies of one configuration run at several seeds.

For the studies given (the same options, different seeds; as `homocal report STUDY [STUDY ...]` checks), it
prints in Markdown: Table 1's 14 numbers and D per scope (each scene, both pooled) as mean and range (min..max)
over the studies, beside the paper's; then, pooled, the seven corrections' positive path share, median, 1st
and 0.1th percentiles, share below -100 % and failures, as mean and range too. The numbers are those of
the report's table.csv (homocal.study.metrics.build_table over each study's verified shards).

    python research/reproduction_tables.py OUT/paper-0 OUT/paper-1 OUT/paper-2
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from homocal.study.kernels import METHODS  # noqa: E402
from homocal.study.metrics import (D_KEYS, D_METHODS, METRICS, OVERALL, PAPER, build_table, complete_shard_files,  # noqa: E402
                                   load_study, paper_distance)
from homocal.study.report import check_replicates  # noqa: E402

TAILS = ("pos_path", "median_path", "p1_path", "p0.1_path", "below_minus100", "failures")


def spread(values: list[float], digits: int) -> str:
    """'mean (min..max)' of values, or the one value."""
    if len(values) == 1:
        return f"{values[0]:.{digits}f}"
    return f"{np.mean(values):.{digits}f} ({min(values):.{digits}f}..{max(values):.{digits}f})"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="reproduction_tables.py", description=__doc__.split("\n")[0])
    p.add_argument("studies", nargs="+", type=Path, metavar="STUDY")
    args = p.parse_args(argv)
    try:
        studies = [(path, load_study(path)) for path in args.studies]
        check_replicates(studies)
        tables = [build_table(complete_shard_files(path, study)) for path, study in studies]
    except ValueError as e:
        print(f"reproduction_tables.py: error: {e}", file=sys.stderr)
        return 1
    seeds = ", ".join(str(s["seed"]) for _, s in studies)
    scopes = tables[0].scopes
    print(f"Table 1, seeds {seeds}: mean (min..max)\n")
    print("| method | metric | paper | " + " | ".join(scopes) + " |")
    print("|---|---|---:|" + "---:|" * len(scopes))
    for method in D_METHODS:
        for key in D_KEYS:
            digits = 2 if key == "corr" else 1
            cells = [spread([t.value(method, key, s) for t in tables], digits) for s in scopes]
            print(f"| {method} | {METRICS[key][0]} | {PAPER[method][key]:g} | " + " | ".join(cells) + " |")
    print("| | **D** (pp) | 0 | " + " | ".join(spread([paper_distance(t, s) for t in tables], 1) for s in scopes) + " |")
    print(f"\nThe seven corrections, both scenes pooled, seeds {seeds}: mean (min..max)\n")
    print("| metric | " + " | ".join(METHODS) + " |")
    print("|---|" + "---:|" * len(METHODS))
    for key in TAILS:
        digits = 0 if key == "failures" else 3 if key == "below_minus100" else 1
        cells = [spread([t.value(m, key, OVERALL) for t in tables], digits) for m in METHODS]
        print(f"| {METRICS[key][0]} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

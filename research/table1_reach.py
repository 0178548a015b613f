"""How near any searched configuration comes to each of Table 1's numbers (docs/reproduction.md,
"What no configuration reaches").

Run: python research/table1_reach.py FOLDER [FOLDER ...] [--top N]
     (each FOLDER a `homocal sweep` folder, whose runs are read from sweep.csv and runs/*/study.json, or a
     `homocal study` results folder)

Every configuration is named by the study options that differ from `homocal study`'s defaults. Prints three
markdown tables:
1. The N configurations nearest the paper by D (metrics.paper_distance), with the two paper methods'
   positive rates and whether they meet the rate targets (TARGETS).
2. Per number of D's 14 (metrics.D_METHODS x D_KEYS): the paper's value, the nearest value any configuration
   gives and where, the nearest among configurations meeting the rate targets for both methods (TARGETS:
   positive path within 3 pp of the paper, positive calibration within 2 pp), and that number's share of D^2
   at the least-D configuration.
3. One line: the least D found (of all configurations, and of those on target), and the D that taking every
   number's nearest value from whichever configuration gives it would make (of all, and of those on target):
   no configuration of the search can be nearer than that.
"""
from __future__ import annotations

import argparse
import csv
import json
import math
from pathlib import Path

from homocal.arguments import number
from homocal.study.inputs import StudyParams, options_label
from homocal.study.metrics import D_KEYS, D_METHODS, PAPER, build_table, load_study, paper_distance, paper_gap, shard_files

TARGETS = {"pos_path": 3.0, "pos_cal": 2.0}  # the reproduction's rate targets (issue 9), pp from the paper, both methods


def configurations(folder: Path) -> list[tuple[str, dict, float]]:
    """[(options, {(method, key): value}, D)] for a sweep folder (one per run) or a study results folder."""
    if (folder / "sweep.json").is_file():
        sweep = json.loads((folder / "sweep.json").read_text())
        rows: dict[str, dict] = {}
        with open(folder / "sweep.csv", newline="") as f:
            for r in csv.DictReader(f):
                rows.setdefault(r["value"], {}).update({(r["method"], k): float(r[k]) for k in (*D_KEYS, "D")})
        found = []
        for value, numbers in rows.items():
            run = folder / "runs" / f"{sweep['param']}={value}".replace("/", "_")
            found.append((options_label(StudyParams.from_dict(load_study(run))), numbers, numbers[("regression", "D")]))
        return found
    study = load_study(folder)
    if not study.get("complete"):
        raise ValueError("the study is not complete: finish it with homocal study --resume")
    table = build_table(shard_files(folder, study))
    numbers = {(m, k): table.value(m, k) for m in D_METHODS for k in D_KEYS}
    return [(options_label(StudyParams.from_dict(study)), numbers, paper_distance(table))]


def gap(numbers: dict, method: str, key: str) -> float:
    return paper_gap(numbers[(method, key)], method, key)


def meets_targets(numbers: dict) -> bool:
    return all(abs(gap(numbers, m, k)) <= pp for m in D_METHODS for k, pp in TARGETS.items())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("folders", nargs="+", type=Path, metavar="FOLDER")
    parser.add_argument("--top", type=number(int, 1), default=10, help="configurations in the first table (default 10)")
    args = parser.parse_args()
    configs, D = {}, {}
    for folder in args.folders:
        try:
            found = configurations(folder)
        except (ValueError, KeyError, OSError) as e:  # not a sweep or study folder, or one with a file missing
            raise SystemExit(f"{folder}: not a complete sweep or study folder ({e})") from None
        for name, numbers, d in found:
            if name not in configs:  # the same configuration in two folders: the first one's numbers
                configs[name], D[name] = numbers, d
    ranked = sorted(configs, key=D.get)
    print(f"{len(configs)} configurations searched; the {min(args.top, len(ranked))} nearest the paper:\n")
    print("| configuration | D (pp) | regression: positive path / calibration (%) | descent: positive path (%) | "
          "rate targets |\n|---|---:|---:|---:|---|")
    for c in ranked[:args.top]:
        n = configs[c]
        print(f"| `{c}` | {D[c]:.1f} | {n[('regression', 'pos_path')]:.1f} / {n[('regression', 'pos_cal')]:.1f} | "
              f"{n[('descent', 'pos_path')]:.1f} | {'met' if meets_targets(n) else 'not met'} |")

    best, on_target = configs[ranked[0]], [c for c in ranked if meets_targets(configs[c])]
    total = sum(gap(best, m, k) ** 2 for m in D_METHODS for k in D_KEYS)
    print(f"\nPer number: the nearest value of all {len(configs)} configurations, and of the {len(on_target)} that "
          f"meet the rate targets for both methods (positive path within 3 pp of the paper, positive calibration within 2); the share of D^2 at the "
          f"least-D configuration (`{ranked[0]}`):\n")
    print("| method | number | paper | nearest | where | nearest on target | where | share of D^2 at the least D |")
    print("|---|---|---:|---:|---|---:|---|---:|")
    bound, bound_on_target = [], []
    for m in D_METHODS:
        for k in D_KEYS:
            near = min(configs, key=lambda c: abs(gap(configs[c], m, k)))
            bound.append(gap(configs[near], m, k))
            cells = [f"{configs[near][(m, k)]:.2f}", f"`{near}`"]
            if on_target:
                near_t = min(on_target, key=lambda c: abs(gap(configs[c], m, k)))
                bound_on_target.append(gap(configs[near_t], m, k))
                cells += [f"{configs[near_t][(m, k)]:.2f}", f"`{near_t}`"]
            else:
                cells += ["", ""]
            print(f"| {m} | {k} | {PAPER[m][k]:g} | {' | '.join(cells)} | {100 * gap(best, m, k) ** 2 / total:.0f} % |")
    rms = lambda gaps: math.sqrt(sum(g * g for g in gaps) / len(gaps))  # noqa: E731
    print(f"\nLeast D found: {D[ranked[0]]:.1f} pp; on target: "
          f"{min((D[c] for c in on_target), default=math.nan):.1f} pp. Every number at its nearest value, each from "
          f"its own configuration: D {rms(bound):.1f} pp, and {rms(bound_on_target) if on_target else math.nan:.1f} "
          f"pp on target (no configuration of this search is nearer).")

if __name__ == "__main__":
    main()

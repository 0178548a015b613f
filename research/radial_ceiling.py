"""How much of a study's path error a radial correction can remove at best (docs/reproduction.md,
"What no configuration reaches").

Run: python research/radial_ceiling.py FOLDER [FOLDER ...] [--variants N]
     (each FOLDER a complete `homocal study` results folder, or a `homocal sweep` folder: each of its runs)

The paper's regression moves each mapped point p along its bearing from the camera origin o by
c(d) = a d^2 + b d, d = ||p - o|| (eqs. (23)-(24)); the signed and intercept forms use the same family
(a, b free in sign; + c). Per trapezoid variant this script finds the coefficients that minimise the mean
test-point error of the study's metric over the test points themselves, an oracle that knows every test
point's true position, so that no three calibration points can do better on that variant: for every sample
(variant, triple) the methods' path improvement is at most the variant's ceiling (with range errors: see
homocal.study.ceiling), and the median over the
study's samples at most the median of the ceilings weighted by the samples per variant
(homocal.study.ceiling.weighted_median). Also the ceiling of any radial correction at all
(every point moved along its bearing to its true range).

The ceilings are homocal.study.ceiling's (the report states the paper preset's for its first variants).

Prints one row per configuration (named by the study options that differ from homocal study's defaults):
regression's positive path rate, the study's median path improvement of the three radial methods, and the
sample-weighted medians of the ceilings over both scenes; then the highest a d^2 + b d ceiling of all, and of
the configurations whose regression positive path rate is within 3 pp of the paper's.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from homocal.arguments import number
from homocal.study.ceiling import CEILINGS, QUADRATIC, variant_ceilings, weighted_median
from homocal.study.engine import load_scenes
from homocal.study.inputs import StudyParams, options_label
from homocal.study.metrics import PAPER, load_study, method_stats, shard_files

RADIAL = ("regression", "regression_signed", "regression_intercept")


def study_folders(folder: Path) -> list[Path]:
    """The study folders of a sweep folder (its runs), or the folder itself."""
    return sorted(p for p in (folder / "runs").iterdir() if p.is_dir()) if (folder / "sweep.json").is_file() else [folder]


def configuration_row(folder: Path, most: int | None) -> tuple[str, dict[str, float]]:
    """(options, {name: value}) of one complete study: regression's positive path rate and the radial methods'
    medians (metrics.method_stats over the samples read), and the weighted medians of the ceilings."""
    study = load_study(folder)
    if not study.get("complete"):
        raise ValueError("the study is not complete: finish it with homocal study --resume")
    params = StudyParams.from_dict(study)
    scenes = load_scenes([d["path"] for d in study["datasets"]], params)
    shards = shard_files(folder, study)
    columns = {m: ([], []) for m in RADIAL}
    ceilings, weights = {k: [] for k in CEILINGS}, []
    for scene in scenes:
        for path in shards[scene.name][:most]:
            table = pq.read_table(path, columns=["variant", *(f"{k}_{m}" for m in RADIAL for k in ("path", "cal"))])
            for m in RADIAL:
                columns[m][0].append(table.column(f"path_{m}").to_numpy())
                columns[m][1].append(table.column(f"cal_{m}").to_numpy())
            if table.num_rows:
                found = variant_ceilings(scene, params, int(table.column("variant")[0].as_py()))
                for k in CEILINGS:
                    ceilings[k].append(found[k])
                weights.append(table.num_rows)
    stats = {m: method_stats(np.concatenate(columns[m][0]), np.concatenate(columns[m][1])) for m in RADIAL}
    row = {"variants": len(weights), "pos_path": stats["regression"]["pos_path"]}
    row |= {m: stats[m]["median_path"] for m in RADIAL}
    row |= {k: weighted_median(np.asarray(ceilings[k]), np.asarray(weights, float)) for k in CEILINGS}
    return options_label(params), row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("folders", nargs="+", type=Path, metavar="FOLDER")
    parser.add_argument("--variants", type=number(int, 1), help="only the first N shards per scene (default: all)")
    args = parser.parse_args()
    print(f"| configuration | shards | regression: positive path (%) | {' | '.join(f'median, {m} (%)' for m in RADIAL)} | "
          f"{' | '.join(f'ceiling, {k} (%)' for k in CEILINGS)} |")
    print("|---|---:|" + "---:|" * (1 + len(RADIAL) + len(CEILINGS)))
    rows = {}
    for folder in args.folders:
        try:
            for study in study_folders(folder):
                name, row = configuration_row(study, args.variants)
                if name not in rows:  # the same configuration in two folders: the first one's
                    rows[name] = row
                    print(f"| `{name}` | {row['variants']} | {row['pos_path']:.1f} | "
                          + " | ".join(f"{row[k]:.1f}" for k in (*RADIAL, *CEILINGS)) + " |", flush=True)
        except np.linalg.LinAlgError:  # a ValueError, but not the folder's fault
            raise
        except (ValueError, KeyError, OSError) as e:  # not a study or sweep folder, or one with a file missing
            raise SystemExit(f"{folder}: not a complete study or sweep folder ({e})") from None
    on_rate = {n: r for n, r in rows.items() if abs(r["pos_path"] - PAPER["regression"]["pos_path"]) <= 3.0}
    for label, chosen in (("all", rows), ("regression's positive path within 3 pp of the paper's", on_rate)):
        if chosen:
            best = max(chosen, key=lambda n: chosen[n][QUADRATIC])
            print(f"\nHighest a d^2 + b d ceiling, {label} ({len(chosen)} configurations): {chosen[best][QUADRATIC]:.1f} % "
                  f"(`{best}`); the paper's regression median: {PAPER['regression']['median_path']:.1f} %")


if __name__ == "__main__":
    main()

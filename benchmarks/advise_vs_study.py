"""Where `homocal advise`'s triple ranks in a study of the same scene (the check of issue 10 item 7).

    homocal study DATASET -o STUDY --variants 50
    homocal advise --trapezoid DATASET/trapezoids.json --distances <the dataset's calibration distances> -o A.csv
    python benchmarks/advise_vs_study.py STUDY SCENE METHOD A.csv

METHOD: a study method name (regression_intercept, descent, ...). Prints the advised triple's mean path improvement
in the study (mean over the scene's variants, shards' path_<METHOD>) and how many triples do better.
"""
import argparse
import csv
import json
from pathlib import Path

import numpy as np
import pyarrow.dataset as pds

from homocal.dataset import EXACT, load_dataset


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("study")
    p.add_argument("scene")
    p.add_argument("method")
    p.add_argument("advice", help="the CSV of homocal advise -o")
    args = p.parse_args()
    column = f"path_{args.method}"
    table = pds.dataset(Path(args.study) / "shards" / args.scene, format="parquet").to_table(columns=["i", "j", "k", column])
    grouped = table.group_by(["i", "j", "k"]).aggregate([(column, "mean")])
    ijk = np.column_stack([grouped.column(c).to_numpy() for c in "ijk"])
    mean = grouped.column(f"{column}_mean").to_numpy()
    path = next(d["path"] for d in json.loads((Path(args.study) / "study.json").read_text())["datasets"]
                if d["scene"] == args.scene)
    distance = load_dataset(path).calibration_points(EXACT)[2]
    with open(args.advice, newline="") as f:
        best = next(csv.DictReader(f))
    advised = sorted(float(best[f"y{n}"]) for n in (1, 2, 3))
    idx = sorted(int(np.argmin(np.abs(distance - d))) for d in advised)
    s = int(np.flatnonzero((ijk == idx).all(axis=1))[0])
    better = int((mean > mean[s]).sum())
    print(f"{args.scene} {args.method}: advised {', '.join(f'{d:g}' for d in advised)} m: study mean {mean[s]:.2f} %, "
          f"{better} of {len(mean)} triples better (top {100 * (better + 1) / len(mean):.1f} %); study best "
          f"{mean.max():.2f} %, median {np.median(mean):.2f} %, worst {mean.min():.2f} %")


if __name__ == "__main__":
    main()

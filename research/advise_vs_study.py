"""Where `homocal advise`'s triple ranks in a study of the same scene (the check of issue 10 item 7).

    homocal study DATASET -o STUDY --variants 50
    homocal advise --trapezoid DATASET/trapezoids.json --distances <the dataset's calibration distances> -o A.csv
    python research/advise_vs_study.py STUDY SCENE METHOD A.csv

METHOD: a study method name (regression_intercept, descent, ...). Prints the advised triple's mean path improvement
in the study (mean over the scene's variants, shards' path_<METHOD>), how many triples do better, and the correlation
of advise's and the study's per-triple means over all triples.
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
    ijk = np.column_stack([grouped.column(c).to_numpy() for c in "ijk"]).astype(np.int64)
    mean = grouped.column(f"{column}_mean").to_numpy()
    path = next(d["path"] for d in json.loads((Path(args.study) / "study.json").read_text())["datasets"]
                if d["scene"] == args.scene)
    distance = load_dataset(path).calibration_points(EXACT)[2]
    with open(args.advice, newline="") as f:
        rows = list(csv.DictReader(f))  # every triple, best first
    y = np.array([[float(r[f"y{n}"]) for n in (1, 2, 3)] for r in rows])
    idx = np.sort(np.abs(y[:, :, None] - distance).argmin(axis=2), axis=1)  # the study's calibration points
    m = len(distance)
    where = dict(zip((ijk[:, 0] * m + ijk[:, 1]) * m + ijk[:, 2], range(len(ijk))))
    in_study = mean[[where[key] for key in (idx[:, 0] * m + idx[:, 1]) * m + idx[:, 2]]]
    advised = in_study[0]
    better = int((mean > advised).sum())
    corr = np.corrcoef(in_study, [float(r["mean_path"]) for r in rows])[0, 1]
    print(f"{args.scene} {args.method}: advised {', '.join(f'{d:g}' for d in sorted(y[0]))} m: study mean {advised:.2f} %, "
          f"{better} of {len(mean)} triples better (top {100 * (better + 1) / len(mean):.1f} %); study best "
          f"{mean.max():.2f} %, median {np.median(mean):.2f} %, worst {mean.min():.2f} %; correlation of advise's and "
          f"the study's means over all triples {corr:.2f}")

if __name__ == "__main__":
    main()

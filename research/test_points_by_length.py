"""How the study's test points depend on the dataset's length.

For each prefix of a dataset (its first T seconds of ground truth), the test points the study draws from it
(``Dataset.test_points`` with the study's defaults: 2000 points, seed 0, at most 50 m from the camera): how
many, their distances from the camera (quartiles, m) and lateral offsets (median |x|, m), and the
Kolmogorov-Smirnov distance between their distances and those drawn from the whole dataset. The prefix is a
copy of the dataset folder whose gt.parquet keeps the rows with t < T (the other files linked), read by the
study's own loader.

    python research/test_points_by_length.py DATASET [DATASET ...] [--seconds 5,10,20,30,45]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
import pyarrow.compute as pc
import pyarrow.parquet as pq

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from homocal.dataset import load_dataset  # noqa: E402
from homocal.study.inputs import StudyParams  # noqa: E402

STUDY = StudyParams()  # the study's defaults: its n_test, seed and max_test_distance


def prefix(dataset: Path, seconds: float, folder: Path) -> Path:
    """A copy of dataset in folder whose gt.parquet holds the rows with t < seconds; the other files linked."""
    out = folder / f"{dataset.name}_{seconds:g}s"
    out.mkdir()
    for f in dataset.iterdir():
        if f.name != "gt.parquet":
            (out / f.name).symlink_to(f.resolve())
    gt = pq.read_table(dataset / "gt.parquet")
    pq.write_table(gt.filter(pc.less(gt.column("t"), seconds)), out / "gt.parquet")
    return out


def draw(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(distance (N,) m, lateral offset |x - o_x| (N,) m) of the study's test points of a dataset."""
    ds = load_dataset(path)
    _, ground = ds.test_points(n=STUDY.n_test, seed=STUDY.seed, max_distance=STUDY.max_test_distance)
    offset = ground - ds.camera_origin
    return np.hypot(*offset.T), np.abs(offset[:, 0])


def ks_distance(a: np.ndarray, b: np.ndarray) -> float:
    """max |F_a - F_b| over the pooled sample (two-sample Kolmogorov-Smirnov statistic)."""
    grid = np.sort(np.concatenate([a, b]))
    fa = np.searchsorted(np.sort(a), grid, side="right") / len(a)
    fb = np.searchsorted(np.sort(b), grid, side="right") / len(b)
    return float(np.max(np.abs(fa - fb)))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="test_points_by_length.py", description=__doc__.split("\n")[0])
    p.add_argument("datasets", nargs="+", type=Path, metavar="DATASET")
    p.add_argument("--seconds", default="5,10,20,30,45", help="prefix lengths (s), comma-separated")
    args = p.parse_args(argv)
    try:
        lengths = [float(s) for s in args.seconds.split(",")]
        if not all(0 < s < 1e6 for s in lengths) or len(set(lengths)) != len(lengths):
            raise ValueError
    except ValueError:
        p.error(f"--seconds {args.seconds!r}: expected positive numbers of seconds, comma-separated, none twice")
    print("| dataset | first T s | test points | distance quartiles (m) | median lateral (m) | KS to whole |")
    print("|---|---:|---:|---|---:|---:|")
    try:
        for dataset in args.datasets:
            whole, whole_lateral = draw(dataset)
            with tempfile.TemporaryDirectory() as tmp:
                for seconds in lengths:
                    d, lateral = draw(prefix(dataset, seconds, Path(tmp)))
                    q = np.percentile(d, [25, 50, 75])
                    print(f"| {dataset.name} | {seconds:g} | {len(d)} | {q[0]:.1f} / {q[1]:.1f} / {q[2]:.1f} | "
                          f"{np.median(lateral):.1f} | {ks_distance(d, whole):.3f} |")
            q = np.percentile(whole, [25, 50, 75])
            print(f"| {dataset.name} | whole | {len(whole)} | {q[0]:.1f} / {q[1]:.1f} / {q[2]:.1f} | "
                  f"{np.median(whole_lateral):.1f} | 0 |")
    except ValueError as e:
        print(f"test_points_by_length.py: error: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())

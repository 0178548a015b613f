"""Which of homocal watch's stretch corrections are refused, and how far off each is (docs/moving-camera.md, "The rgb
boxes on a camera that keeps moving").

    python research/watch_refusals.py DATASET [DATASET ...] --work WORK [--detector rgb]

Per dataset (a simgen recording: its camera_pose.parquet is the truth), ``homocal watch`` with its defaults on the
detector's boxes (the hand-placed trapezoid, camera.json; the camera height from the trapezoid, the default prior)
into WORK/<dataset>_<detector>, then per stretch (corrections/<start_s>.json, to the next stretch's start or the
recording's end): a kept correction's horizon row against the camera's at the stretch's end, or for a refused one
the running estimate's at its last person (horizon.parquet); last, how many of each and the range of |off|.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from homocal.cli import main as homocal_main  # noqa: E402
from homocal.dataset import load_dataset  # noqa: E402
from homocal.watch.folder import REFUSED  # noqa: E402


def stretches(dataset: Path, detector: str, out: Path) -> list[tuple[float, float, bool, float]]:
    """homocal watch on the dataset's boxes into out; [(start_s, end_s, refused, off px)] per stretch."""
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        code = homocal_main(["watch", "--trapezoid", str(dataset / "trapezoids.json"), "--boxes",
                             str(dataset / "detections.parquet"), "--detector", detector, "--out", str(out)])
    if code != 0:
        raise SystemExit(f"watch_refusals: homocal watch failed on {dataset} ({detector})")
    ds = load_dataset(dataset)  # its camera_pose.parquet, checked: the camera's horizon at each step
    t, rows = ds.pose.t, ds.pose.horizon_rows(ds.camera.K[0, 2])
    people = pq.read_table(out / "horizon.parquet").to_pandas()
    starts = sorted(float(p.stem) for p in (out / "corrections").glob("*.json"))
    found = []
    for start, end in zip(starts, starts[1:] + [float(t[-1])]):
        written = json.loads((out / "corrections" / f"{start:.2f}.json").read_text())
        if written.get("format") == REFUSED:
            last = people[people.stretch_start_s == start].iloc[-1]
            found.append((start, end, True, float(last.horizon_row_px - np.interp(last.t_s, t, rows))))
        else:
            found.append((start, end, False, float(written["fitted"]["horizon_row"] - np.interp(end, t, rows))))
    return found


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("datasets", nargs="+", type=Path)
    ap.add_argument("--work", type=Path, required=True, help="a folder for the watches' outputs (new subfolders)")
    ap.add_argument("--detector", default="rgb")
    args = ap.parse_args(argv)
    off = {False: [], True: []}
    for dataset in args.datasets:
        for start, end, refused, px in stretches(dataset, args.detector, args.work / f"{dataset.name}_{args.detector}"):
            off[refused].append(abs(px))
            print(f"{dataset.name} {args.detector} {start:.2f}-{end:.1f} s: {'refused' if refused else 'kept'}, "
                  f"{px:+.1f} px off")
    for refused, name in ((False, "kept"), (True, "refused")):
        spread = f": |off| {min(off[refused]):.1f}-{max(off[refused]):.1f} px" if off[refused] else ""
        print(f"{name} {len(off[refused])}{spread}")


if __name__ == "__main__":
    main()

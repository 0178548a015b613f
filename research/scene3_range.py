"""What a dataset's trapezoid maps with the camera's lens known and ignored: the median relative range error at 5-50 m
(docs/real-camera.md, "Range error of scene3's trapezoid").

Run: python research/scene3_range.py DATASET [DATASET ...] [--trapezoid exact|hand_placed]

Per dataset (a simgen dataset: camera.json, trapezoids.json, gt.parquet, site_map.json): the trapezoid (the exact
one by default: its image corners are the distorted pixels of its ground corners, trapezoids.json's "exact" and
"ground_m"; hand_placed: the clicked corners and the hand-placed map corners in metres) maps the ground truth's
in-frame foot points (gt.parquet's u, v: the camera's distorted pixels) whose true range from the camera's ground
point (camera_origin) is 5-50 m:
  known:   corners and points undistorted with camera.json's lens (homocal.geometry.Lens.undistort_points), as
           homocal fit --camera-json and homocal study --lens known do;
  ignored: the camera's pixels mapped as a pinhole's, as homocal study --lens ignore and the paper's pipeline do.
Prints one line per dataset: the points used, each median |mapped range - true range| / true range in %, and how
far the trapezoid's horizon (lens known) lies below the true one at the principal column, px (> 0: below, the
mapping overestimates far ranges; camera.json's horizon).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from homocal.dataset import load_dataset
from homocal.geometry import ViewTransformer

RANGE_M = (5.0, 50.0)  # the paper's operating range (its Fig. 2), metres from the camera's ground point


def range_errors(path: Path, trapezoid: str = "exact") -> dict:
    """{"points": N, "known": %, "ignored": %, "horizon_below_px": px} of the dataset at path (the module
    docstring)."""
    ds = load_dataset(path)
    entry = ds.trapezoids["exact"] if trapezoid == "exact" else ds.trapezoids["hand_placed"]
    corners = np.asarray(entry["image"], float)
    ground = np.asarray(ds.trapezoids["ground_m"], float) if trapezoid == "exact" else ds.site_map.to_metres(
        np.asarray(entry["map"], float))
    gt = pq.read_table(path / "gt.parquet", columns=["u", "v", "x", "y", "in_frame"]).to_pandas()
    gt = gt[gt["in_frame"]]
    truth = np.hypot(gt["x"] - ds.camera_origin[0], gt["y"] - ds.camera_origin[1]).to_numpy()
    near = (truth >= RANGE_M[0]) & (truth <= RANGE_M[1])
    pixels, truth = gt[["u", "v"]].to_numpy()[near], truth[near]
    lens = ds.camera.lens
    cx = ds.camera.K[0, 2]
    out = {"points": int(near.sum()), "horizon_below_px": float(
        ViewTransformer(lens.undistort_points(corners), ground).horizon_row(cx) - ds.camera.horizon_row)}
    for name, undistort in (("known", lens.undistort_points), ("ignored", lambda q: q)):
        mapped = ViewTransformer(undistort(corners), ground).transform_points(undistort(pixels))
        out[name] = 100 * float(np.median(np.abs(np.hypot(*(mapped - ds.camera_origin).T) - truth) / truth))
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("datasets", nargs="+", type=Path)
    ap.add_argument("--trapezoid", choices=("exact", "hand_placed"), default="exact")
    args = ap.parse_args(argv)
    for path in args.datasets:
        e = range_errors(path, args.trapezoid)
        print(f"{path}: {args.trapezoid} trapezoid, {e['points']} ground-truth foot points at {RANGE_M[0]:g}-{RANGE_M[1]:g} m: "
              f"median relative range error {e['known']:.4f} % with the lens known, {e['ignored']:.2f} % with it ignored; "
              f"its horizon {e['horizon_below_px']:+.2f} px below the true one")


if __name__ == "__main__":
    main()

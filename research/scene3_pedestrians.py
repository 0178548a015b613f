"""The pedestrians' correction on a rolled camera with a wide lens, end to end, with no reference point
(docs/real-camera.md, "The people on scene3").

Run: python research/scene3_pedestrians.py DATASET [--detectors segmentation,rgb] [--height-mean M] [--height-sd M]
         [--estimate-roll yes|no] [--drop-hidden-feet yes|no|auto] [--horizon-shift PX] [--lens known|ignore] [--seconds S]

Per detector, as a user runs it: `homocal fit --method pedestrians --trapezoid DATASET/trapezoids.json --boxes
DATASET/detections.parquet --detector D --camera-json DATASET/camera.json --camera-height H --estimate-roll yes`
(--drop-hidden-feet when given, else fit's default; the camera's K, lens and height given, as a user who knows
them; H camera.json's mount_height_m; --lens ignore: camera.json's K with no distortion, so the boxes and the
trapezoid are the camera's pixels read as a pinhole's, as homocal study --lens ignore reads them), the clicked
trapezoid the dataset's hand-placed one (--horizon-shift PX: moved as a tilt error moves it so that its horizon
lies PX above the true one at the principal column, homocal.study.perturb.tilt_shift); then, from the saved
correction:
  - the horizon line: the fitted one (horizon_row_ at the principal column, slope -tan(roll_deg_) in camera.json's
    roll convention) against camera.json's horizon (a u + b v + c = 0, the undistorted image), RMS of their row
    difference over the image's pixel columns 0..W-1 (``horizon_rms``); the fitted roll, its sigma and its move
    per centimetre of the prior mean (tilt_roll_sensitivity_);
  - the median relative range error of the ground truth's in-frame foot points 5-50 m from the camera's ground
    point (gt.parquet's u, v: the camera's pixels, undistorted with the correction's lens, as they are without one,
    then mapped):
    ``median_range_error``.
--seconds S: the recording's first S seconds only (the boxes and the ground truth whose time t is below S).
Prints one line per detector (a fit homocal fit refuses: its message, and the detector's line says so).
"""
from __future__ import annotations

import argparse
import json
import math
import tempfile
from contextlib import redirect_stdout
from dataclasses import replace
from pathlib import Path

import numpy as np
import pyarrow.compute as pc
import pyarrow.parquet as pq

from homocal.cli import main as homocal_main
from homocal.correctors.base import load_corrector
from homocal.dataset import load_dataset
from homocal.geometry import ViewTransformer
from homocal.geometry.camera_file import NO_DISTORTION
from homocal.study.inputs import LENS_MODES
from homocal.study.perturb import tilt_shift

RANGE_M = (5.0, 50.0)  # the paper's operating range (its Fig. 2), metres


def horizon_rms(horizon_row: float, roll_deg: float, principal: tuple[float, float], horizon: np.ndarray,
                width: int) -> float:
    """RMS over the pixel columns u = 0..width-1 of the row difference between a fitted horizon line (row
    horizon_row at the principal column, slope -tan(roll_deg): camera.json's roll) and the true line horizon
    (a, b, c): a u + b v + c = 0."""
    u = np.arange(width, dtype=np.float64)
    fitted = horizon_row - math.tan(math.radians(roll_deg)) * (u - principal[0])
    a, b, c = horizon
    return float(np.sqrt(np.mean((fitted + (a * u + c) / b) ** 2)))


def median_range_error(corrector, pixels: np.ndarray, ground: np.ndarray, origin: np.ndarray) -> float:
    """Median |mapped range - true range| / true range, %, of the camera's pixels (N, 2) (undistorted with the
    correction's lens_ when it has one) against their true ground points (N, 2) m, ranges from origin (2,)."""
    q = pixels if corrector.lens_ is None else corrector.lens_.undistort_points(pixels)
    mapped, truth = corrector.transform_points(q), np.hypot(*(ground - origin).T)
    return 100 * float(np.median(np.abs(np.hypot(*(mapped - origin).T) - truth) / truth))


def run(path: Path, detector: str, prior: list[str], estimate_roll: str, shift_px: float | None, folder: Path,
        lens_mode: str = "known", seconds: float | None = None) -> dict:
    """Fit with homocal fit (the module docstring; prior: its --height-mean, --height-sd and --drop-hidden-feet flags; lens_mode: known
    or ignore; seconds: the recording's first seconds only, None: all of it) into folder; the figures of the saved
    correction ("refused": True if homocal fit refused the boxes)."""
    ds = load_dataset(path)
    boxes = path / "detections.parquet"
    if seconds is not None:
        boxes = folder / "detections.parquet"
        table = pq.read_table(path / "detections.parquet")
        pq.write_table(table.filter(pc.less(table["t"], seconds)), boxes)
    camera_json = path / "camera.json"
    if lens_mode == "ignore":
        camera_json = folder / "pinhole.json"
        camera_json.write_text(json.dumps(replace(ds.camera, distortion=NO_DISTORTION).to_dict()))
    trapezoid = path / "trapezoids.json"
    if shift_px is not None:
        lens, camera = ds.camera.lens, ds.camera
        clicked = lens.undistort_points(ds.trapezoid_image)
        row = ViewTransformer(clicked, ds.site_map.to_metres(ds.trapezoid_map)).horizon_row(camera.K[0, 2])
        moved = lens.distort_points(tilt_shift(clicked, camera.K, row, row - camera.horizon_row + shift_px))
        trapezoid = folder / f"trapezoid_{detector}.json"
        trapezoid.write_text(json.dumps({"image": moved.tolist(), "map": ds.site_map.to_metres(ds.trapezoid_map).tolist(),
                                         "image_size": list(camera.image_size)}))
    out = folder / f"{detector}.json"
    args = ["fit", "--method", "pedestrians", "--trapezoid", str(trapezoid), "--boxes", str(boxes),
            "--detector", detector, "--camera-json", str(camera_json), "--estimate-roll", estimate_roll,
            "--camera-height", str(ds.camera.mount_height_m), "--out", str(out), *prior]
    with redirect_stdout(None):
        if homocal_main(args) != 0:
            return {"detector": detector, "refused": True}
    c = load_corrector(out)
    gt = pq.read_table(path / "gt.parquet", columns=["t", "u", "v", "x", "y", "in_frame"]).to_pandas()
    gt = gt[gt["in_frame"] & (gt["t"] < (math.inf if seconds is None else seconds))]
    ground = gt[["x", "y"]].to_numpy()
    r = np.hypot(*(ground - ds.camera_origin).T)
    near = (r >= RANGE_M[0]) & (r <= RANGE_M[1])
    return {"detector": detector, "refused": False, "people": c.n_people_used_, "boxes": c.n_boxes_, "roll_deg": c.roll_deg_,
            "hidden_feet": c.hidden_feet_,
            "roll_sigma_deg": c.roll_sigma_deg_,
            "roll_per_cm_deg": math.degrees(c.tilt_roll_sensitivity_[1]) / 100 if c.roll_estimated_ else math.nan,
            "true_roll_deg": json.loads((path / "camera.json").read_text()).get("roll_deg", 0.0),
            "horizon_rms_px": horizon_rms(c.horizon_row_, c.roll_deg_, c.principal_point_, ds.camera.horizon,
                                          ds.camera.image_size[0]),
            "horizon_sigma_px": c.horizon_sigma_px_, "points": int(near.sum()),
            "median_range_error_pct": median_range_error(c, gt[["u", "v"]].to_numpy()[near], ground[near], ds.camera_origin)}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--detectors", default="segmentation,rgb")
    ap.add_argument("--height-mean", help="the people's mean height, m (default: homocal fit's)")
    ap.add_argument("--height-sd", help="their standard deviation, m (default: homocal fit's)")
    ap.add_argument("--estimate-roll", choices=("yes", "no"), default="yes")
    ap.add_argument("--drop-hidden-feet", choices=("yes", "no", "auto"), help="default: homocal fit's")
    ap.add_argument("--horizon-shift", type=float, metavar="PX")
    ap.add_argument("--lens", choices=LENS_MODES, default="known",
                    help="ignore: camera.json's K with no distortion (the camera's pixels read as a pinhole's)")
    ap.add_argument("--seconds", type=float, metavar="S", help="the recording's first S seconds only")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        for detector in args.detectors.split(","):
            prior = [x for flag, value in (("--height-mean", args.height_mean), ("--height-sd", args.height_sd),
                                           ("--drop-hidden-feet", args.drop_hidden_feet))
                     if value is not None for x in (flag, value)]
            e = run(args.dataset, detector, prior, args.estimate_roll, args.horizon_shift, Path(tmp), args.lens, args.seconds)
            if e["refused"]:
                print(f"{args.dataset} {detector}, lens {args.lens}: homocal fit refused the boxes (its message above)")
                continue
            print(f"{args.dataset} {detector}, lens {args.lens}: {e['people']} people of {e['boxes']} boxes (hidden feet "
                  f"{e['hidden_feet']}); roll {e['roll_deg']:.2f} "
                  f"+- {e['roll_sigma_deg']:.2f} deg (camera.json {e['true_roll_deg']:g}; {e['roll_per_cm_deg']:+.3f} deg per cm of "
                  f"the prior mean); horizon line RMS "
                  f"{e['horizon_rms_px']:.2f} px (sigma {e['horizon_sigma_px']:.2f}); median relative range error "
                  f"{e['median_range_error_pct']:.2f} % ({e['points']} foot points at {RANGE_M[0]:g}-{RANGE_M[1]:g} m)")


if __name__ == "__main__":
    main()

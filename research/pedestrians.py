"""How well PedestrianCorrector corrects the study's trapezoid variants with no reference point (issue 27 item 3).

    python research/pedestrians.py DATASET [DATASET ...] --detectors segmentation,rgb,hog --seconds 10
        [--base fitted|hand-placed] [--variants 100] [--height-mean 1.71 --height-sd 0.09] [--estimate-camera]
        [--boxes FILE] [--end-to-end exact|hand-placed --det SEQ/det/segmentation.txt [--give-k]]

Per dataset and detector, the corrector is fitted once per study variant (homocal.study: the same variants as
`homocal study` draws with these options, variants 0..--variants) from that detector's boxes of the first
--seconds of video (detections.parquet; the intrinsics K from camera.json and the camera height from
camera.json's mount_height_m, as a user who knows both; --estimate-camera: neither, the focal length and the
camera height from each variant's clicked mapping). Printed, per dataset and detector:
  - the horizon error after the fit (fitted minus true row at the principal column, px): RMS, max |.|, and
    the fit's own 1-sigma; with K and the camera height given it does not depend on the variant;
  - the path improvement 100 (E_before - E_after) / E_before over the study's test points (range errors
    | ||g - o|| - ||p - o|| |, the study's `--metric range`, E = their mean): positive share, median, 1st
    percentile, share below -100 %, over the variants;
  - the relative range error at 5-50 m, read as Brouwers et al. (2016) read "mean metric error" in this
    comparison: the mean over ground points of |estimated range - true range| / true range (range from the
    camera's ground point), here over the study's test points at 5-50 m; mean and median over the variants
    of each variant's mean, before and after. A correction that puts a test point beyond its horizon has an
    infinite error there: it counts as not positive and below every percentile.
--base fitted: the variants of `homocal study --preset table1-fit` (horizon 16 px above the true one, the
perturbation read as variant-positive, map perturbations in px of a 1.5 px/m map); hand-placed: those of
`--preset paper` (the hand-placed trapezoid, the per-coordinate perturbation).
--end-to-end KIND: instead, the issue's end-to-end check on one dataset: export-mot's det/segmentation.txt
(--det, written by `simgen export-mot DATASET -o SEQ` beforehand), the KIND ("exact" or "hand-placed")
image trapezoid moved as a tilt error moves it so that its horizon lies 16 px above the true one, the camera
height 4 m given and nothing else (the focal length from the clicked mapping, the image size from
seqinfo.ini; --give-k: camera.json's K too); the median relative range error of the ground-truth foot points
(gt.parquet, in frame, 5-50 m) mapped with the fitted correction after a save and a load.
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from homocal.boxes import read_boxes
from homocal.correctors.base import FORMAT, load_corrector
from homocal.correctors.pedestrians import DEFAULT_HEIGHT_MEAN_M, DEFAULT_HEIGHT_SD_M, MODELS, PedestrianCorrector
from homocal.dataset import load_dataset
from homocal.files import check_output_file, json_format
from homocal.geometry import ViewTransformer
from homocal.study.inputs import StudyScene, preset_params
from homocal.study.perturb import base_quad
from homocal.study.shards import prepare_variant

BASES = {"fitted": "table1-fit", "hand-placed": "paper"}  # --base: the study preset whose base error it takes
RANGE_M = (5.0, 50.0)


def relative_range_errors(mapped: np.ndarray, ground: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """|estimated range - true range| / true range (N,) of mapped and true ground points (N, 2) m."""
    true = np.linalg.norm(ground - origin, axis=1)
    return np.abs(np.linalg.norm(mapped - origin, axis=1) - true) / true


def detector_boxes(path: str, detector: str, seconds: float, boxes_file: str | None = None):
    """(xyxy (N, 4) homocal px, frames (N,)) of detector's boxes (or those of boxes_file, read_boxes) in the
    first `seconds` of the dataset's video."""
    ds = load_dataset(path)
    boxes = read_boxes(boxes_file if boxes_file else Path(path) / "detections.parquet", None if boxes_file else detector)
    keep = boxes.frames < seconds * float(ds.manifest["fps"])
    return boxes.xyxy[keep], boxes.frames[keep]


def measure(path: str, detector: str, args) -> dict:
    params = preset_params(BASES[args.base], n_variants=args.variants)
    scene = StudyScene.from_dataset(path, params)
    ds = load_dataset(path)
    xyxy, frames = detector_boxes(path, detector, args.seconds, args.boxes)
    given = {} if args.estimate_camera else {"K": scene.K, "camera_height_m": float(ds.camera["mount_height_m"])}
    o = scene.origin
    true_range = np.linalg.norm(scene.test_ground - o, axis=1)
    near = (true_range >= RANGE_M[0]) & (true_range <= RANGE_M[1])
    rows, once = [], None
    for v in range(args.variants + 1):
        tables = prepare_variant(scene, params, v)
        if isinstance(tables, str):
            continue
        image, map_quad = scene.variant_quads(params, v)
        clicked = ViewTransformer(image, scene.site_map.to_metres(map_quad))
        if once is None or args.estimate_camera:  # with K and the height given the fit does not depend on the variant
            once = corrector = PedestrianCorrector(args.height_mean, args.height_sd, args.model).fit(
                clicked, xyxy, convention="homocal", frames=frames,
                image_size=(int(ds.camera["width"]), int(ds.camera["height"])), camera_origin=o, **given)
        else:
            corrector = once.with_mapping(clicked)
        after_points = corrector.transform_points(scene.test_image)
        after = float(np.mean(np.abs(true_range - np.linalg.norm(after_points - o, axis=1))))
        if math.isnan(after):  # a test point beyond the corrected horizon: a failed correction, error infinite
            after = math.inf
        before_points = clicked.transform_points(scene.test_image)
        rows.append({"variant": v, "horizon_error": corrector.horizon_row_ - scene.true_horizon_row,
                     "sigma": corrector.horizon_sigma_px_, "path": 100 * (tables.path_before - after) / tables.path_before,
                     "rel_before": float(np.mean(relative_range_errors(before_points[near], scene.test_ground[near], o))),
                     "rel_after": float(np.nan_to_num(np.mean(relative_range_errors(after_points[near], scene.test_ground[near], o)), nan=math.inf)),
                     "people": corrector.n_people_used_, "tracks": corrector.n_people_, "boxes": corrector.n_boxes_,
                     "outliers": corrector.n_outliers_, "border": corrector.n_border_})
    h = np.array([r["horizon_error"] for r in rows])
    path_imp = np.array([r["path"] for r in rows])
    rb, ra = (np.array([r[k] for r in rows]) for k in ("rel_before", "rel_after"))
    return {"dataset": scene.name, "path": str(path), "detector": detector, "seconds": args.seconds, "base": args.base,
            "model": args.model, "prior": [args.height_mean, args.height_sd], "estimate_camera": args.estimate_camera,
            "variants": len(rows), "horizon_rms_px": float(np.sqrt(np.mean(h**2))), "horizon_max_px": float(np.abs(h).max()),
            "horizon_sigma_px": float(np.median([r["sigma"] for r in rows])),
            "positive_share": float(np.mean(path_imp > 0) * 100), "median_path": float(np.median(path_imp)),
            "p1_path": float(np.percentile(path_imp, 1, method="lower")), "below_minus100": float(np.mean(path_imp < -100) * 100),
            "rel_range_before_mean": float(rb.mean() * 100), "rel_range_after_mean": float(ra.mean() * 100),
            "rel_range_after_median": float(np.median(ra) * 100), "boxes": rows[0]["boxes"], "tracks": rows[0]["tracks"],
            "people_used": rows[0]["people"], "outlier_boxes": rows[0]["outliers"], "border_boxes": rows[0]["border"],
            "test_points_5_50m": int(near.sum())}


def end_to_end(path: str, kind: str, args) -> dict:
    ds = load_dataset(path)
    K, true_row = np.asarray(ds.camera["K"], float), float(ds.camera["horizon_row"])
    quads = {"exact": ds.trapezoids["exact"], "hand-placed": ds.trapezoids["hand_placed"]}[kind]
    target = ds.site_map.to_metres(np.asarray(quads["map"], float))
    image = np.asarray(quads["image"], float)
    row = float(ViewTransformer(image, target).horizon_row(K[0, 2]))
    shift = preset_params(BASES["fitted"]).horizon_shift.a  # the fitted base error (a fixed shift, px)
    clicked = ViewTransformer(base_quad(image, K, row, true_row, shift, np.zeros(8)), target)
    out = Path(args.out) / f"end_to_end_{ds.name}_{kind}.json"
    check_output_file(out, lambda p: json_format(p) == FORMAT, "homocal correction")  # never a file it did not write
    boxes = read_boxes(args.det)
    corrector = PedestrianCorrector(args.height_mean, args.height_sd, args.model).fit(
        clicked, boxes.xyxy, convention="homocal", frames=boxes.frames, track_ids=boxes.track_ids,
        camera_height_m=float(ds.camera["mount_height_m"]), image_size=boxes.image_size, K=K if args.give_k else None)
    corrector.save(out)
    loaded = load_corrector(out)
    gt = ds.table("gt.parquet")
    gt = gt.filter(gt.column("in_frame"))
    feet = np.column_stack([gt.column(c).to_numpy() for c in ("u", "v")])
    ground = np.column_stack([gt.column(c).to_numpy() for c in ("x", "y")])
    r = np.linalg.norm(ground, axis=1)
    keep = (r >= RANGE_M[0]) & (r <= RANGE_M[1])
    after = relative_range_errors(loaded.transform_points(feet[keep]), ground[keep], np.zeros(2))
    before = relative_range_errors(clicked.transform_points(feet[keep]), ground[keep], np.zeros(2))
    return {"dataset": ds.name, "trapezoid": kind, "model": args.model, "K_given": args.give_k, "prior": [args.height_mean, args.height_sd], "clicked_horizon_above_true_px": true_row - corrector.clicked_horizon_row_,
            "horizon_error_px": corrector.horizon_row_ - true_row, "horizon_sigma_px": corrector.horizon_sigma_px_,
            "focal_px": corrector.focal_px_, "true_focal_px": float(K[1, 1]), "points": int(keep.sum()),
            "median_rel_range_error_before": float(np.median(before) * 100),
            "median_rel_range_error_after": float(np.median(after) * 100), "people_used": corrector.n_people_used_}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("datasets", nargs="+")
    p.add_argument("--detectors", default="segmentation")
    p.add_argument("--boxes", help="a boxes file (homocal.boxes.read_boxes) instead of the dataset's detections")
    p.add_argument("--seconds", type=float, default=math.inf)
    p.add_argument("--base", choices=BASES, default="fitted")
    p.add_argument("--variants", type=int, default=100)
    p.add_argument("--height-mean", type=float, default=DEFAULT_HEIGHT_MEAN_M)
    p.add_argument("--height-sd", type=float, default=DEFAULT_HEIGHT_SD_M)
    p.add_argument("--model", choices=MODELS, default=MODELS[0], help="PedestrianCorrector's model")
    p.add_argument("--estimate-camera", action="store_true")
    p.add_argument("--end-to-end", choices=("exact", "hand-placed"))
    p.add_argument("--det", help="--end-to-end: export-mot's det/segmentation.txt of the dataset")
    p.add_argument("--give-k", action="store_true", help="--end-to-end: give the fit camera.json's K")
    p.add_argument("--out", default=".", help="folder for the end-to-end correction file")
    args = p.parse_args()
    for path in args.datasets:
        if args.end_to_end:
            print(json.dumps(end_to_end(path, args.end_to_end, args)))
            continue
        for detector in args.detectors.split(","):
            print(json.dumps(measure(path, detector, args)), flush=True)


if __name__ == "__main__":
    main()

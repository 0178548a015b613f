"""How well PedestrianCorrector corrects the study's trapezoid variants with no reference point (issue 27 item 3).

    python research/pedestrians.py --study STUDY -o OUT [--detectors segmentation,rgb] [--seconds 10,60]
        [--boxes SCENE=FILE ...] [--height-mean 1.71 --height-sd 0.09] [--model camera|rotation] [--estimate-camera] [--accept-outliers]
    python research/pedestrians.py DATASET [DATASET ...] --detectors segmentation,rgb,hog --seconds 10
        [--base fitted|hand-placed] [--variants 100] [--height-mean 1.71 --height-sd 0.09] [--estimate-camera]
        [--boxes FILE] [--windows] [--end-to-end exact|hand-placed --det SEQ/det/segmentation.txt [--give-k] [-o FOLDER]]

--study STUDY: a complete `homocal study` folder. Its configuration (StudyParams from study.json), seed,
datasets and variants (0..n_variants, as the study ran them); per dataset, detector and --seconds value (a
comma list; default: the whole video), the corrector is fitted once per variant, and the report beside the
study's seven reference-point methods on the same variants (their figures computed by homocal report's
homocal.study.metrics.build_table) is written to OUT (a new folder, or one this command wrote):
pedestrians.csv (one row per scene, detector and seconds, then the scenes pooled as "overall"),
pedestrians.md (printed too) and pedestrians.json (the folder's marker). --boxes SCENE=FILE (repeatable):
that scene's boxes from FILE (homocal.boxes.read_boxes) instead of its detections.parquet, labelled with
--detectors (one name); only the scenes named get pedestrian rows.

DATASET: the same on variants drawn here (homocal.study: the same variants as `homocal study --preset P
--variants N` draws, P by --base), one JSON line per dataset, detector and seconds value. --windows: each
seconds value S measured on every disjoint window of S seconds of the video (0-S, S-2S, ...; "start" says
which), then one line of the windows' spread (mean, min, max of each figure): how much the fit moves from one
recording of that length to the next.

Per variant: the corrector is fitted from the detector's boxes of the first --seconds of video
(detections.parquet; the intrinsics K from camera.json and the camera height from camera.json's
mount_height_m, as a user who knows both; --estimate-camera: neither, the focal length and the camera height
from each variant's clicked mapping). Per row:
  - the horizon error after the fit (fitted minus true row at the principal column, px): RMS, max |.|, and
    the fit's own 1-sigma from the people alone (horizon_sigma_people_px_, median); with K and the camera height given it does not depend on the variant;
  - the path improvement 100 (E_before - E_after) / E_before over the study's test points (StudyScene; E the
    mean of the study's --metric errors, homocal.study.shards.path_errors): positive share, median, 1st
    percentile, share below -100 % and failures over the variants, by the study's own statistics
    (homocal.study.metrics.method_stats). A correction that puts a test point beyond its horizon, and a fit
    PedestrianCorrector.fit refuses (the row's refusal), are failures: not positive, below every percentile;
  - the relative range error at 5-50 m, read as Brouwers et al. (2016) read "mean metric error" in this
    comparison: the mean over ground points of |estimated range - true range| / true range (range from the
    camera's ground point), here over the study's test points at 5-50 m; mean (and median, after) over the
    variants of each variant's mean, before and after (infinite for a failure);
  - people used of tracks, boxes and outlier boxes of the first variant's fit that was not refused (with K and
    the height given, every variant's).
A degenerate variant (no shard samples in the study) is left out, as the study leaves it.
--base fitted: the variants of `homocal study --preset table1-fit` (horizon 16 px above the true one, the
perturbation read as variant-positive, map perturbations in px of a 1.5 px/m map); hand-placed: those of
`--preset paper` (the hand-placed trapezoid, the per-coordinate perturbation).
--end-to-end KIND: instead, the issue's end-to-end check on one dataset: export-mot's det/segmentation.txt
(--det, written by `simgen export-mot DATASET -o SEQ` beforehand), the KIND ("exact" or "hand-placed")
image trapezoid moved as a tilt error moves it so that its horizon lies 16 px above the true one, the camera
height 4 m given and nothing else (the focal length from the clicked mapping, the image size from
seqinfo.ini; --give-k: camera.json's K too); the median relative range error of the ground-truth foot points
(gt.parquet, in frame, 5-50 m) mapped with the fitted correction after a save and a load (written to -o, default
the current folder).
"""
from __future__ import annotations

import argparse
import csv
import io
import json
import math
import shlex
import sys
from pathlib import Path

import numpy as np

from homocal.arguments import number
from homocal.boxes import read_boxes
from homocal.correctors.base import FORMAT, load_corrector
from homocal.correctors.pedestrians import MAX_OUTLIER_SHARE, DEFAULT_HEIGHT_MEAN_M, DEFAULT_HEIGHT_SD_M, MODELS, PedestrianCorrector
from homocal.dataset import Dataset, load_dataset
from homocal.files import OutputFolderError, check_output_file, json_format, output_folder, write_json_atomic, write_text_atomic
from homocal.geometry import ViewTransformer
from homocal.study.engine import load_scenes
from homocal.study.inputs import StudyParams, StudyScene, preset_params
from homocal.study.kernels import METHODS
from homocal.study.metrics import (OVERALL, build_table, complete_shard_files, csv_number, format_metric, load_study,
                                   markdown_row, method_stats)
from homocal.study.perturb import base_trapezoid
from homocal.study.report import config_label
from homocal.study.shards import path_errors, prepare_variant

BASES = {"fitted": "table1-fit", "hand-placed": "paper"}  # --base: the study preset whose base error it takes
RANGE_M = (5.0, 50.0)
REPORT_FORMAT = "homocal-pedestrians-report"  # pedestrians.json's "format": marks OUT as this command's
REPORT_FILES = ("pedestrians.json", "pedestrians.csv", "pedestrians.md")  # the marker first
TAILS = ("pos_path", "median_path", "p1_path", "below_minus100", "failures")  # the study's statistics shown (metrics.METRICS)
COUNTS = ("people_used", "tracks", "boxes", "outlier_boxes", "border_boxes")
FIGURES = ("variants", "horizon_rms_px", "horizon_max_px", "horizon_sigma_px", *TAILS, "refused", "refusal",
           "rel_range_before_mean", "rel_range_after_mean", "rel_range_after_median", *COUNTS)


def seconds_list(text: str) -> list[float]:
    """argparse type of --seconds: a comma list of numbers of seconds > 0, none twice."""
    values = [number(float, 0.0, low_open=True)(part) for part in text.split(",")]
    if len(set(values)) != len(values):
        raise argparse.ArgumentTypeError(f"a value given twice in {text!r}")
    return values


def relative_range_errors(mapped: np.ndarray, ground: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """|estimated range - true range| / true range (N,) of mapped and true ground points (N, 2) m."""
    true = np.linalg.norm(ground - origin, axis=1)
    return np.abs(np.linalg.norm(mapped - origin, axis=1) - true) / true


def in_range(scene: StudyScene) -> np.ndarray:
    """(N,) bool: the scene's test points at RANGE_M (5-50 m) from the camera's ground point."""
    true_range = np.linalg.norm(scene.test_ground - scene.origin, axis=1)
    return (true_range >= RANGE_M[0]) & (true_range <= RANGE_M[1])


def video_seconds(ds: Dataset, seconds: float | None) -> float:
    """seconds, or the dataset's whole video if None; ValueError (naming --seconds) beyond its length."""
    length = float(ds.manifest["seconds"])
    if seconds is not None and seconds > length:
        raise ValueError(f"--seconds {seconds:g}: beyond the {length:g} s of video of {ds.name} ({ds.path})")
    return length if seconds is None else seconds


def detector_boxes(ds: Dataset, detector: str, seconds: float, boxes_file: str | None = None, start: float = 0.0):
    """(xyxy (N, 4) homocal px, frames (N,)) of detector's boxes (or those of boxes_file, read_boxes) in the
    `seconds` of the dataset's video from `start` (s); ValueError (naming --detectors) if the dataset has no such
    detector."""
    if boxes_file is None and detector not in ds.manifest.get("detectors", ()):
        raise ValueError(f"--detectors {detector}: {ds.name} ({ds.path}) has no boxes of it "
                         f"(has: {', '.join(ds.manifest.get('detectors', ())) or 'none'})")
    boxes = read_boxes(boxes_file if boxes_file else Path(ds.path) / "detections.parquet", None if boxes_file else detector)
    fps = float(ds.manifest["fps"])
    keep = (boxes.frames >= start * fps) & (boxes.frames < (start + seconds) * fps)
    return boxes.xyxy[keep], boxes.frames[keep]


def variant_rows(scene: StudyScene, params: StudyParams, ds: Dataset, xyxy: np.ndarray, frames: np.ndarray, args) -> list[dict]:
    """One dict per variant 0..params.n_variants that is not degenerate (prepare_variant): scene, variant,
    path (improvement %, NaN: a failure), rel_before, rel_after (5-50 m; inf: a failure), and either refusal
    (PedestrianCorrector.fit's message) or horizon_error, sigma (px) and the fit's COUNTS."""
    given = {} if args.estimate_camera else {"K": scene.K, "camera_height_m": ds.camera.mount_height_m}
    o, near = scene.origin, in_range(scene)

    def fit(clicked: ViewTransformer) -> PedestrianCorrector | str:
        try:
            return PedestrianCorrector(args.height_mean, args.height_sd, args.model).fit(
                clicked, xyxy, convention="homocal", frames=frames,
                image_size=ds.camera.image_size, camera_origin=o,
                max_outlier_share=max_outlier_share(args), **given)
        except ValueError as e:
            return str(e)

    rows, once = [], None
    for v in range(params.n_variants + 1):
        tables = prepare_variant(scene, params, v)
        if isinstance(tables, str):
            continue
        image, map_quad = scene.variant_quads(params, v)
        clicked = ViewTransformer(image, scene.site_map.to_metres(map_quad))
        before = relative_range_errors(clicked.transform_points(scene.test_image[near]), scene.test_ground[near], o)
        row = {"scene": scene.name, "variant": v, "rel_before": float(np.mean(before))}
        if once is None or args.estimate_camera:  # with K and the height given the fit does not depend on the variant
            corrector = once = fit(clicked)
        else:
            corrector = once if isinstance(once, str) else once.with_mapping(clicked)
        if isinstance(corrector, str):
            rows.append(row | {"refusal": corrector, "path": math.nan, "rel_after": math.inf})
            continue
        after_points = corrector.transform_points(scene.test_image)
        after = float(np.mean(path_errors(after_points, scene.test_ground, o, params.metric)))  # NaN: beyond the horizon
        rel_after = float(np.mean(relative_range_errors(after_points[near], scene.test_ground[near], o)))
        rows.append(row | {"path": 100 * (tables.path_before - after) / tables.path_before,
                           "rel_after": math.inf if math.isnan(rel_after) else rel_after,
                           "horizon_error": corrector.horizon_row_ - scene.true_horizon_row, "sigma": corrector.horizon_sigma_people_px_,
                           "people_used": corrector.n_people_used_, "tracks": corrector.n_people_, "boxes": corrector.n_boxes_,
                           "outlier_boxes": corrector.n_outliers_, "border_boxes": corrector.n_border_})
    return rows


def summarise(rows: list[dict]) -> dict:
    """The FIGURES of variant_rows' rows (of one scene, or several pooled): the path statistics by
    metrics.method_stats over the variants; the horizon figures over the fits not refused (NaN if none); refused:
    whether any variant's fit was, refusal the first message; COUNTS summed over the scenes, each scene's from its
    first fit not refused (None if none)."""
    path = np.array([r["path"] for r in rows], dtype=np.float32)
    stats = method_stats(path, np.full_like(path, np.nan))
    fitted = [r for r in rows if "refusal" not in r]
    h = np.array([r["horizon_error"] for r in fitted])
    refusals = [r["refusal"] for r in rows if "refusal" in r]
    firsts = {}
    for r in fitted:
        firsts.setdefault(r["scene"], r)
    rb, ra = (np.array([r[k] for r in rows]) for k in ("rel_before", "rel_after"))
    nan = math.nan
    return {"variants": len(rows), "horizon_rms_px": float(np.sqrt(np.mean(h**2))) if fitted else nan,
            "horizon_max_px": float(np.abs(h).max()) if fitted else nan,
            "horizon_sigma_px": float(np.median([r["sigma"] for r in fitted])) if fitted else nan,
            **{k: stats[k] for k in TAILS}, "refused": bool(refusals), "refusal": refusals[0] if refusals else "",
            "rel_range_before_mean": float(rb.mean() * 100) if rows else nan,
            "rel_range_after_mean": float(ra.mean() * 100) if rows else nan,
            "rel_range_after_median": float(np.median(ra) * 100) if rows else nan,
            **{k: sum(r[k] for r in firsts.values()) if firsts else None for k in COUNTS}}


def measure(path: str, detector: str, seconds: float | None, args) -> list[dict]:
    """DATASET mode: one dataset, detector and seconds value on the variants of the --base preset; with
    --windows, on every disjoint window of that length, then the windows' spread (window_spread)."""
    params = preset_params(BASES[args.base], n_variants=args.variants)
    scene = StudyScene.from_dataset(path, params)
    ds = load_dataset(path)
    seconds = video_seconds(ds, seconds)
    starts = [k * seconds for k in range(int(float(ds.manifest["seconds"]) // seconds))] if args.windows else [0.0]
    lines = []
    for start in starts:
        rows = variant_rows(scene, params, ds, *detector_boxes(ds, detector, seconds, args.boxes, start), args)
        lines.append({"dataset": scene.name, "path": str(path), "detector": detector, "seconds": seconds, "start": start,
                      "base": args.base, "model": args.model, "prior": [args.height_mean, args.height_sd],
                      "estimate_camera": args.estimate_camera, "max_outlier_share": max_outlier_share(args), **summarise(rows),
                      "test_points_5_50m": int(in_range(scene).sum())})
    return lines + ([window_spread(lines)] if args.windows else [])


def window_spread(lines: list[dict]) -> dict:
    """Mean, min and max over --windows' lines of each numeric figure (None where a window has none)."""
    spread = {k: lines[0][k] for k in ("dataset", "detector", "seconds", "base", "model", "prior")}
    for key in FIGURES:
        values = [line[key] for line in lines]
        if all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in values):
            spread[key] = {"mean": float(np.mean(values)), "min": float(min(values)), "max": float(max(values))}
    return {"windows": len(lines), **spread}


def end_to_end(path: str, kind: str, args) -> dict:
    ds = load_dataset(path)
    K, true_row = ds.camera.K, ds.camera.horizon_row
    quads = {"exact": ds.trapezoids["exact"], "hand-placed": ds.trapezoids["hand_placed"]}[kind]
    target = ds.site_map.to_metres(np.asarray(quads["map"], float))
    image = np.asarray(quads["image"], float)
    shift = preset_params(BASES["fitted"]).horizon_shift.a  # the fitted base error (a fixed shift, px)
    clicked = ViewTransformer(base_trapezoid(image, target, K, true_row, shift, np.zeros(8)), target)
    out = Path(args.out) / f"end_to_end_{ds.name}_{kind}.json"
    check_output_file(out, lambda p: json_format(p) == FORMAT, "homocal correction")  # never a file it did not write
    boxes = read_boxes(args.det)
    corrector = PedestrianCorrector(args.height_mean, args.height_sd, args.model).fit(
        clicked, boxes.xyxy, convention="homocal", frames=boxes.frames, track_ids=boxes.track_ids,
        camera_height_m=ds.camera.mount_height_m, image_size=boxes.image_size, K=K if args.give_k else None)
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
            "horizon_error_px": corrector.horizon_row_ - true_row, "horizon_sigma_px": corrector.horizon_sigma_people_px_,
            "focal_px": corrector.focal_px_, "true_focal_px": float(K[1, 1]), "points": int(keep.sum()),
            "median_rel_range_error_before": float(np.median(before) * 100),
            "median_rel_range_error_after": float(np.median(after) * 100), "people_used": corrector.n_people_used_}


def scene_boxes(values: list[str], scenes: list[str]) -> dict[str, str]:
    """{scene: boxes file} of --boxes SCENE=FILE values; ValueError for another form or a scene the study lacks."""
    found = {}
    for value in values:
        scene, sep, file = value.partition("=")
        if not sep or not file:
            raise ValueError(f"--boxes {value}: with --study, expected SCENE=FILE (the scene's boxes)")
        if scene not in scenes or scene in found:
            raise ValueError(f"--boxes {value}: {scene!r} is {'given twice' if scene in found else 'not a scene of the study'} "
                             f"(its scenes: {', '.join(scenes)})")
        found[scene] = file
    return found


def study_report(args, argv: list[str]) -> str:
    """--study mode: check every input, then write OUT's files (REPORT_FILES); return pedestrians.md's text.
    ValueError or OutputFolderError (one line) for bad input, before anything is written."""
    study = load_study(args.study)
    shards = complete_shard_files(args.study, study)
    if not study.get("complete"):
        raise ValueError(f"{args.study}: the study is not complete (study.json); finish it with homocal study ... --resume")
    params = StudyParams.from_dict(study)
    scenes = load_scenes([d["path"] for d in study["datasets"]], params)
    for scene, d in zip(scenes, study["datasets"]):
        if (scene.name, scene.config_hash, len(scene.test_image)) != (d["scene"], d.get("config_hash", ""), d.get("n_test")):
            raise ValueError(f"{d['path']}: not the dataset the study ran on (its scene, configuration or test points differ)")
    detectors = args.detectors.split(",")
    boxes = scene_boxes(args.boxes, [s.name for s in scenes])
    if boxes and len(detectors) != 1:
        raise ValueError("--detectors: with --boxes, one name (the label of the boxes given)")
    asked = args.seconds or [None]  # None: each video's whole length
    plan = []  # (scene, dataset, detector, seconds asked, seconds, xyxy, frames): every input read before any work
    for scene, d in zip(scenes, study["datasets"]):
        if boxes and scene.name not in boxes:
            continue
        ds = load_dataset(d["path"])
        for detector in detectors:
            for seconds in asked:
                length = video_seconds(ds, seconds)
                plan.append((scene, ds, detector, seconds, length, *detector_boxes(ds, detector, length, boxes.get(scene.name))))
    with output_folder(args.out, REPORT_FORMAT, resume=True, marker=REPORT_FILES[0]) as folder:
        folder.remove_temporaries(REPORT_FILES)
        write_json_atomic(folder.marker, {"format": REPORT_FORMAT, "study": str(Path(args.study).resolve()),
                                          "command": shlex.join(["python", "research/pedestrians.py", *argv])})
        table = build_table(shards)
        measured = [(scene.name, detector, seconds, length, variant_rows(scene, params, ds, xyxy, frames, args))
                    for scene, ds, detector, seconds, length, xyxy, frames in plan]
        rows = [(scene, detector, length, summarise(r)) for scene, detector, _, length, r in measured]
        pooled = len(scenes) > 1 and not boxes  # every scene measured: pooled as the study's table pools them
        for detector, seconds in [(d, s) for d in detectors for s in asked] if pooled else []:
            of = [m for m in measured if m[1:3] == (detector, seconds)]
            lengths = {m[3] for m in of}
            rows.append((OVERALL, detector, lengths.pop() if len(lengths) == 1 else math.nan,
                         summarise([r for m in of for r in m[4]])))
        write_text_atomic(args.out / "pedestrians.csv", report_csv(rows, args))
        text = report_markdown(study, table, rows, args, argv)
        write_text_atomic(args.out / "pedestrians.md", text)
    return text


def max_outlier_share(args) -> float:
    """The fit's max_outlier_share: 1 with --accept-outliers (no fit refused), else the library's."""
    return 1.0 if args.accept_outliers else MAX_OUTLIER_SHARE


def fit_setting(args) -> dict:
    """The fit's setting, as pedestrians.csv gives it on every row."""
    return {"model": args.model, "height_mean_m": args.height_mean, "height_sd_m": args.height_sd,
            "camera": "clicked mapping" if args.estimate_camera else "given", "max_outlier_share": max_outlier_share(args)}


def report_csv(rows: list[tuple[str, str, float, dict]], args) -> str:
    """pedestrians.csv: scene (OVERALL: the scenes pooled), detector, seconds, the fit's setting (fit_setting) and
    FIGURES, numbers at full precision (metrics.csv_number; empty: none)."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    setting = fit_setting(args)
    writer.writerow(["scene", "detector", "seconds", *setting, *FIGURES])
    for scene, detector, seconds, figures in rows:
        values = [*setting.values(), *(figures[k] for k in FIGURES)]
        cells = [v if isinstance(v, str) else "" if v is None else csv_number(v) for v in values]
        writer.writerow([scene, detector, csv_number(seconds), *cells])
    return buf.getvalue()


def report_markdown(study: dict, table, rows: list[tuple[str, str, float, dict]], args, argv: list[str]) -> str:
    """pedestrians.md: per scope (each scene, then OVERALL), the seven methods' TAILS from the study's table
    (build_table: what homocal report's table.csv holds), then the pedestrian rows of that scope."""
    header = ["method", "samples", "positive (%)", "median (%)", "1st percentile (%)", "below -100 % (%)", "failures",
              "horizon error RMS / max (px)", "horizon sigma (px)", "range error 5-50 m, before -> after (%)",
              "people used / tracks", "boxes (outliers)"]
    camera = ("the focal length and camera height from each variant's clicked mapping" if args.estimate_camera
              else "K and the camera height from camera.json")
    out = ["# The pedestrian correction beside the seven reference-point methods", "",
           f"Study `{args.study}`: {config_label(study)}, seed {StudyParams.from_dict(study).seed}; datasets: "
           + ", ".join(f"{d['scene']} `{d['path']}`" for d in study["datasets"]) + ".",
           "", "The seven methods: every calibration triple of every variant (homocal report's table.csv). The pedestrian "
           f"correction ({args.model} model, prior {args.height_mean:g} m, sd {args.height_sd:g} m, {camera}): one fit per "
           "variant from the boxes of the first seconds of video, no reference point; samples are its variants. "
           + ("No fit refused (--accept-outliers: what a fit PedestrianCorrector refuses would give)." if args.accept_outliers
              else "A refused fit's variants are failures."), "",
           f"    {shlex.join(['python', 'research/pedestrians.py', *argv])}", ""]
    pooled = any(scene == OVERALL for scene, *_ in rows)
    for scope in table.scopes if pooled else table.scopes[:-1]:
        out += [f"## {'all scenes pooled' if scope == OVERALL else scope}", "", markdown_row(header),
                markdown_row(["---"] + ["---:"] * (len(header) - 1))]
        out += [markdown_row([m, format_metric("n", table.value(m, "n", scope)),
                         *(format_metric(k, table.value(m, k, scope)) for k in TAILS), *[""] * 5]) for m in METHODS]
        for scene, detector, seconds, f in rows:
            if scene != scope:
                continue
            name = f"pedestrians, {detector}, {seconds:g} s" + (f" (refused: {f['refusal']})" if f["refused"] else "")
            counts = ["" if f[k] is None else f"{f[k]:,}" for k in COUNTS]
            out.append(markdown_row([name, format_metric("n", f["variants"]), *(format_metric(k, f[k]) for k in TAILS),
                                f"{f['horizon_rms_px']:.2f} / {f['horizon_max_px']:.2f}", f"{f['horizon_sigma_px']:.2f}",
                                f"{f['rel_range_before_mean']:.2f} -> {f['rel_range_after_mean']:.2f}",
                                f"{counts[0]} / {counts[1]}", f"{counts[2]} ({counts[3]})"]))
        out.append("")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    p = argparse.ArgumentParser(prog="pedestrians.py", description=__doc__.split("\n")[0])
    p.add_argument("datasets", nargs="*", metavar="DATASET")
    p.add_argument("--study", type=Path, help="a complete homocal study folder: its datasets, configuration and variants")
    p.add_argument("--detectors", default="segmentation")
    p.add_argument("--boxes", action="append", default=[],
                   help="a boxes file (homocal.boxes.read_boxes) instead of the dataset's detections; with --study "
                        "SCENE=FILE, repeatable")
    p.add_argument("--seconds", type=seconds_list, help="comma list of seconds of video (default: all of it)")
    p.add_argument("--windows", action="store_true",
                   help="DATASET mode: each --seconds value on every disjoint window of that length, and their spread")
    p.add_argument("--base", choices=BASES, help="DATASET mode: the preset whose variants it draws (default fitted)")
    p.add_argument("--variants", type=number(int, 0), help="DATASET mode: variants 0..N (default 100)")
    p.add_argument("--height-mean", type=float, default=DEFAULT_HEIGHT_MEAN_M)
    p.add_argument("--height-sd", type=float, default=DEFAULT_HEIGHT_SD_M)
    p.add_argument("--model", choices=MODELS, default=MODELS[0], help="PedestrianCorrector's model")
    p.add_argument("--estimate-camera", action="store_true")
    p.add_argument("--accept-outliers", action="store_true",
                   help="refuse no fit for its share of outliers (PedestrianCorrector.fit's max_outlier_share 1): "
                        "what a refused fit would give")
    p.add_argument("--end-to-end", choices=("exact", "hand-placed"))
    p.add_argument("--det", help="--end-to-end: export-mot's det/segmentation.txt of the dataset")
    p.add_argument("--give-k", action="store_true", help="--end-to-end: give the fit camera.json's K")
    p.add_argument("-o", "--out", type=Path,
                   help="--study: the report folder; --end-to-end: the folder for the correction file (default .)")
    args = p.parse_args(argv)
    if (args.study is None) == (not args.datasets):
        p.error("give DATASET ... or --study STUDY (one of them)")
    dataset_only = {"--windows": args.windows or None, "--base": args.base, "--variants": args.variants, "--end-to-end": args.end_to_end, "--det": args.det,
                    "--give-k": args.give_k or None}
    if args.study is not None and any(v is not None for v in dataset_only.values()):
        p.error(f"{', '.join(k for k, v in dataset_only.items() if v is not None)}: not with --study (it takes the study's variants)")
    if args.study is not None and args.out is None:
        p.error("--study needs -o OUT (the report folder)")
    if args.study is None and args.out is not None and not args.end_to_end:
        p.error("-o: only with --study or --end-to-end")
    if args.study is None and len(args.boxes) > 1:
        p.error("--boxes: one file with DATASET")
    args.base, args.variants = args.base or "fitted", 100 if args.variants is None else args.variants
    try:
        PedestrianCorrector(args.height_mean, args.height_sd, args.model)
    except ValueError as e:
        p.error(f"argument --height-mean/--height-sd: {e}")
    try:
        if args.study is not None:
            print(study_report(args, argv))
            return 0
        args.boxes = args.boxes[0] if args.boxes else None
        for path in args.datasets:
            if args.end_to_end:
                args.out = args.out or Path(".")
                print(json.dumps(end_to_end(path, args.end_to_end, args)))
                continue
            for detector in args.detectors.split(","):
                for seconds in args.seconds or [None]:
                    for line in measure(path, detector, seconds, args):
                        print(json.dumps(line), flush=True)
    except (ValueError, OutputFolderError, OSError) as e:
        print(f"pedestrians.py: error: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())

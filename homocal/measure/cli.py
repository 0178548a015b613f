"""``homocal measure``: people's ground positions, speeds and distances from their boxes (docs/measure.md)."""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from tqdm import tqdm

from homocal.arguments import CAMERA_JSON_HELP, camera_json, number
from homocal.boxes import DEFAULT_DETECTOR, MAX_FPS, boxes_fps, read_boxes
from homocal.correctors.base import load_corrector
from homocal.correctors.catalogue import label
from homocal.correctors.pedestrians import SETTINGS as PEDESTRIAN_SETTINGS
from homocal.correctors.serialization import FORMAT
from homocal.files import check_output_file, json_format, write_atomic
from homocal.geometry import read_trapezoid_file
from homocal.geometry.lens import first_outside_frame
from homocal.geometry.boxes import box_bottom_points, link_tracks, trim_boxes, undistort_boxes
from homocal.measure.kalman import ACCEL_PSD, ACCEL_PSD_BOUNDS, IMM, IMM_ACCEL_PSD, IMM_SWITCH_PER_S
from homocal.measure.tracks import (COLUMNS, FEET, FOOT, FOOT_CORRELATION_S, FOOT_NOISE, FOOT_SIGMA_PER_BOX_HEIGHT,
                                    FOOT_TAILS, MAX_TRACK_FRAMES, MIN_TRACK_FRAMES, PAIR_COLUMNS, STATIONARY_MPS,
                                    STUDENT_FOOT_NOISE, SUMMARY_COLUMNS, TrapezoidMapping, box_margin_of,
                                    check_people_per_frame, check_tracks, fit_tracks_accel_psd, foot_noise_options,
                                    measure_tracks, measured_feet, pair_distances, summarise)
from homocal.progress import add_progress_option, show_progress
from homocal.study.options import flag_type

"""The highest frame rate taken (--fps, or the boxes' file's)."""
INTEGER_COLUMNS = {"frame", "track_id", "frames", "first_frame", "last_frame", "track_a", "track_b"}
STRING_COLUMNS = {"foot"}

FORMATS = f"""\
CORRECTION.json: written by homocal fit (any method, pedestrians too), or a trapezoid file alone (homocal fit
--help's TRAP.json: the clicked mapping, uncorrected).
BOXES: a MOTChallenge .txt (a gt.txt's ids are the tracks; seqinfo.ini beside SEQ/det or SEQ/gt gives the
image size and frame rate), a simgen dataset's detections.parquet (--detector; manifest.json beside it gives
the frame rate) or a .csv of frame,x1,y1,x2,y2 (optional track_id; pixel corners at integers, as
supervision's Detections.xyxy). Without track ids the boxes are linked into tracks by IoU (homocal's
link_tracks: IoU >= 0.3, gaps up to 5 frames). A track's rows must come in increasing frame order, one box per
track and frame; tracks of fewer than {MIN_TRACK_FRAMES} frames are left out (and counted).
TRACKS.parquet, one row per track and frame, tracks in increasing id, frames in order:
  frame, t (s, frame / fps), track_id, u, v (the foot point, px: the box's bottom edge's centre, --box-margin
  / 2 up), x, y (its ground point, m), sigma_m (its 1-sigma radius, m), x_smooth, y_smooth (m), vx, vy (m/s),
  speed_mps and speed_sigma_mps (its 1-sigma): a constant-velocity Kalman filter with an RTS smoother per
  track, whose measurement noise is each point's own covariance (the mapping's error model at
  --click-sigma-px, --point-sigma-px) and whose process noise is a white acceleration of spectral density
  --accel-psd; foot ({" | ".join(FOOT)}): the foot point measured,
  or with --feet soles not, as a nearer person's box may hide the feet or the image border cuts the box's
  bottom or a side (the image size of seqinfo.ini, camera.json or the correction's lens), nor a box no taller
  than --box-margin: the filter predicts through that frame and the smoother fills it in (x, y stay the
  mapped foot point).
--summary TRACKS_SUMMARY.parquet, one row per track: {", ".join(SUMMARY_COLUMNS)}
  (stationary: smoothed speed under {STATIONARY_MPS:g} m/s).
--pairs PAIRS.parquet, one row per two people in one frame: {", ".join(PAIR_COLUMNS)}."""


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "measure", help="people's ground positions, speeds and distances, with error bars, from their boxes",
        description="Map each track's foot points to the ground and smooth them into positions and speeds with "
                    "error bars.", epilog=FORMATS, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("correction", type=Path, metavar="CORRECTION.json", help="homocal fit's output, or a trapezoid file")
    p.add_argument("--boxes", required=True, type=Path, metavar="FILE", help="people's boxes (see below)")
    p.add_argument("--camera-json", type=Path, metavar="CAMERA.json",
                   help=CAMERA_JSON_HELP + ". With a trapezoid file only: a correction carries the lens it was fitted with")
    p.add_argument("--detector", metavar="NAME", help=f"the detector's rows of a detections.parquet (default {DEFAULT_DETECTOR})")
    p.add_argument("--fps", type=number(float, 0, MAX_FPS, low_open=True), metavar="F",
                   help="frames per second (default: the boxes' file's, when it says it)")
    p.add_argument("-o", "--out", required=True, type=Path, metavar="TRACKS.parquet", help="the table to write")
    p.add_argument("--summary", type=Path, metavar="FILE.parquet", help="also write one row per track here")
    p.add_argument("--pairs", type=Path, metavar="FILE.parquet", help="also write the distances between people here")
    p.add_argument("--accel-psd", type=accel_psd, default=ACCEL_PSD, metavar=f"{FITTED}|{IMM}|Q",
                   help=f"the filter's acceleration spectral density, m^2/s^3, or {FITTED}: fitted to the tracks by "
                        "maximum likelihood of the filter's innovations, in "
                        f"[{ACCEL_PSD_BOUNDS[0]:g}, {ACCEL_PSD_BOUNDS[1]:g}], or {IMM}: two models, a steady walker's "
                        f"{IMM_ACCEL_PSD[0]:g} and a manoeuvre's {IMM_ACCEL_PSD[1]:g}, switching at "
                        f"{IMM_SWITCH_PER_S[0]:g} and {IMM_SWITCH_PER_S[1]:g} per s (fitted; an interacting "
                        f"multiple model filter and smoother) (default {ACCEL_PSD:g})")
    p.add_argument("--click-sigma-px", type=number(float, 0), default=1.5, metavar="PX",
                   help="clicking error of each trapezoid coordinate, pixels (default 1.5)")
    p.add_argument("--point-sigma-px", type=number(float, 0), default=1.0, metavar="PX",
                   help="error of each foot point coordinate, pixels (default 1.0)")
    p.add_argument("--foot-noise", choices=FOOT_NOISE, default=FOOT_NOISE[0],
                   help="fixed: each point's whole covariance (--point-sigma-px) is the filter's measurement noise; "
                        f"box-height: the foot point's own error, {FOOT_SIGMA_PER_BOX_HEIGHT[0]:g} x its box's height "
                        f"px across (u) and {FOOT_SIGMA_PER_BOX_HEIGHT[1]:g} x along (v) (fitted), is, and the shared "
                        "mapping error goes into the speed's sigma; correlated: as "
                        f"box-height, the foot point's error correlated over {FOOT_CORRELATION_S:g} s (fitted), "
                        "an AR(1) in the filter's state (default fixed)")
    p.add_argument("--foot-noise-tails", choices=FOOT_TAILS, default=FOOT_TAILS[0],
                   help="the foot point's noise distribution: normal; student, heavy tailed (a Student-t, fitted per "
                        "--foot-noise: " + ", ".join(f"{k} scale {c:g} x, {dof:g} degrees of freedom"
                                                    for k, (c, dof) in STUDENT_FOOT_NOISE.items())
                        + "), so that a foot point far off (hidden feet, a box merged or split) counts little; with "
                        f"--foot-noise {' or '.join(STUDENT_FOOT_NOISE)} (default {FOOT_TAILS[0]})")
    p.add_argument("--feet", choices=FEET, default=FEET[0],
                   help="the foot points measured: all; soles: not those whose bottom edge may not be the sole, a box "
                        "whose feet a nearer person's box may hide or whose bottom or side the image border cuts (the "
                        f"table's foot column; default {FEET[0]})")
    margin = PEDESTRIAN_SETTINGS["box_margin_px"]
    p.add_argument(margin.flag, dest="box_margin_px", type=flag_type(margin), metavar=margin.metavar,
                   help=f"how much taller than their people the boxes are, in the camera's pixels: half off each box's "
                        f"top and bottom edge before its foot point, a box no taller not measured (the foot column's "
                        f"{FOOT[3]}): {margin.expected()} (default: the pedestrians correction's, homocal fit "
                        f"{margin.flag}; 0 for any other)")
    add_progress_option(p)
    p.set_defaults(handler=handle_measure)


FITTED = "fitted"
"""--accel-psd's word for a q fitted to the file's tracks (``fit_tracks_accel_psd``)."""


def accel_psd(text: str) -> float | str:
    """argparse type of --accel-psd: FITTED, IMM, or a number in (0, 1e6]."""
    if text in (FITTED, IMM):
        return text
    try:
        return number(float, 0, 1e6, low_open=True)(text)
    except argparse.ArgumentTypeError as e:
        raise argparse.ArgumentTypeError(f"{FITTED}, {IMM} or a number: {e}") from None


def load_mapping(path: Path, camera_json_path: Path | None = None):
    """(a fitted Corrector or a TrapezoidMapping, its label) of a correction file or a trapezoid file (its corners
    undistorted with --camera-json's lens, which the mapping keeps); ValueError for --camera-json with a correction."""
    if json_format(path) == FORMAT:
        if camera_json_path is not None:
            raise ValueError(f"--camera-json: {path} is a correction, which carries the lens it was fitted with "
                             "(homocal fit --camera-json); give --camera-json with a trapezoid file only")
        corrector = load_corrector(path)
        return corrector, f"the {label(corrector)} correction"
    camera = camera_json(camera_json_path)
    lens = None if camera is None else camera.lens
    return TrapezoidMapping(read_trapezoid_file(path, lens)[0], lens), "the trapezoid (uncorrected)"


def check_image_size(mapping, size: tuple[int, int] | None, args: argparse.Namespace) -> None:
    """ValueError when the boxes' image size is known and the correction's clicked corners (or the pedestrian
    fit's principal point) lie outside that image by more than a pixel: a correction of another camera."""
    if size is None:
        return
    points = np.array([*mapping.base_transformer_.source] + ([mapping.principal_point_] if hasattr(mapping, "principal_point_") else []))
    if (i := first_outside_frame(points, size)) is not None:
        raise ValueError(f"{args.correction}: its image point ({points[i, 0]:g}, {points[i, 1]:g}) lies outside the "
                         f"{size[0]}x{size[1]} image of {args.boxes}: a correction of another image size or camera")


def parquet_columns(path: Path) -> list[str] | None:
    try:
        return pq.read_schema(path).names
    except (pa.ArrowException, OSError):
        return None


def schema(columns: tuple[str, ...]) -> pa.Schema:
    return pa.schema([(c, pa.int64() if c in INTEGER_COLUMNS else pa.string() if c in STRING_COLUMNS else pa.float64())
                      for c in columns])


def write_table(path: Path, columns: tuple[str, ...], batches, bar=None) -> None:
    """Write batches (dicts of columns) to the Parquet file ``path`` atomically, one row group a batch."""
    def write(tmp: Path) -> None:
        with pq.ParquetWriter(tmp, schema(columns)) as writer:
            for batch in batches:
                writer.write_table(pa.table({c: batch[c] for c in columns}, schema=schema(columns)))
                if bar is not None:
                    bar.update(len(batch[columns[0]]))
    write_atomic(path, write)


def handle_measure(args: argparse.Namespace) -> int:
    outputs = {"--out": (args.out, COLUMNS), "--summary": (args.summary, SUMMARY_COLUMNS),
               "--pairs": (args.pairs, PAIR_COLUMNS)}
    paths = [p.resolve() for p, _ in outputs.values() if p is not None]
    if len(set(paths)) != len(paths):
        raise ValueError("--out, --summary and --pairs: give each its own file")
    for flag, (path, columns) in outputs.items():
        if path is not None:
            check_output_file(path, lambda p, c=columns: parquet_columns(p) == list(c), f"table of homocal measure {flag}")
    fps = boxes_fps(args.boxes, args.fps)
    mapping, what = load_mapping(args.correction, args.camera_json)
    lens = getattr(mapping, "lens_", None)
    boxes = read_boxes(args.boxes, args.detector, lens, undistort=False)  # the camera's pixels: the border is there
    check_image_size(mapping, boxes.image_size, args)
    margin = box_margin_of(mapping) if args.box_margin_px is None else args.box_margin_px
    xyxy = undistort_boxes(boxes.xyxy, lens)  # as the fit's
    if boxes.track_ids is None:
        ids, source = link_tracks(boxes.frames, xyxy), "linked by IoU"  # the boxes as detected
    else:
        ids, source = boxes.track_ids, "tracks of the file"
        try:
            check_tracks(boxes.frames, ids)
        except ValueError as e:
            raise ValueError(f"{args.boxes}: {e}") from None
    _, inverse, counts = np.unique(ids, return_inverse=True, return_counts=True)
    keep = counts[inverse] >= MIN_TRACK_FRAMES
    if not keep.any():
        raise ValueError(f"{args.boxes}: no track has {MIN_TRACK_FRAMES} frames or more ({len(counts)} tracks of one "
                         "frame): nothing to measure a speed from")
    if counts.max() > MAX_TRACK_FRAMES:
        raise ValueError(f"{args.boxes}: a track of {counts.max():,} frames: at most {MAX_TRACK_FRAMES:,} "
                         "(MAX_TRACK_FRAMES; split the recording)")
    if margin:  # the camera's pixels, as the fit's (PedestrianCorrector.fit)
        xyxy = undistort_boxes(trim_boxes(boxes.xyxy, margin), lens)
    frames, feet, ids = boxes.frames[keep], box_bottom_points(xyxy[keep], convention="homocal"), ids[keep]
    foot = measured_feet(boxes.xyxy[keep], frames, boxes.image_size, args.feet, margin)
    if args.pairs is not None:
        try:
            check_people_per_frame(frames)
        except ValueError as e:
            raise ValueError(f"--pairs: {args.boxes}: {e}") from None
    noise = foot_noise_options(args.foot_noise, xyxy[keep], args.point_sigma_px, args.foot_noise_tails,
                               names=("--foot-noise", "--foot-noise-tails"))
    sigmas = {"click_sigma_px": args.click_sigma_px, "point_sigma_px": noise.pop("point_sigma_px")}
    q, fitted = args.accel_psd, ""
    if q == FITTED:
        q = fit_tracks_accel_psd(mapping, frames, feet, ids, fps, **noise, **sigmas, foot=foot)
        fitted = f" Process noise fitted to the tracks: {q:.3g} m^2/s^3."
    summaries = []

    def tracks():
        for batch in measure_tracks(mapping, frames, feet, ids, fps, accel_psd=q, **noise, **sigmas, foot=foot):
            summaries.append(summarise(batch))
            yield batch

    with tqdm(total=len(frames), unit="box", desc="measure", disable=not show_progress(args)) as bar:
        write_table(args.out, COLUMNS, tracks(), bar)
    summary = {c: np.concatenate([s[c] for s in summaries]) for c in SUMMARY_COLUMNS}
    if args.summary is not None:
        write_table(args.summary, SUMMARY_COLUMNS, [summary])
    pairs = ""
    if args.pairs is not None:
        count = []

        def counted():
            for batch in pair_distances(mapping, frames, feet, ids, fps, **sigmas):
                count.append(len(batch["frame"]))
                yield batch

        write_table(args.pairs, PAIR_COLUMNS, counted())
        pairs = f"; {sum(count):,} distances written to {args.pairs}"
    dropped = len(counts) - len(summary["track_id"])
    short = f"; {dropped:,} of one frame left out" if dropped else ""
    unused = ", ".join(f"{np.sum(foot == k):,} {k}" for k in FOOT[1:] if np.any(foot == k))
    unused = f" Feet not measured (predicted through): {unused}." if unused else ""
    trimmed = f", {margin:g} px box margin" if margin else ""
    print(f"homocal measure: {len(frames):,} boxes in {len(summary['track_id']):,} tracks ({source}{short}) of "
          f"{args.boxes} mapped with {what} of {args.correction}{trimmed} at {fps:g} fps, smoothed and written to {args.out}"
          f"{pairs}. Median speed {np.nanmedian(summary['mean_speed_mps']):.2f} m/s over the tracks.{unused}{fitted}")
    return 0

"""``homocal fit`` and ``homocal apply``: fit a correction from reference points (or, with --method pedestrians,
from people's boxes), apply it to foot points.

The input formats are in the --help texts below (FIT_FORMATS, APPLY_FORMATS).
"""
from __future__ import annotations

import argparse
import csv
import io
import sys
import warnings
from pathlib import Path

import numpy as np

from homocal.arguments import CAMERA_JSON_HELP, SEED, camera_json, number, xy_pair
from homocal.boxes import DEFAULT_DETECTOR, read_boxes
from homocal.correctors.base import MAX_REFERENCE_POINTS, load_corrector
from homocal.correctors.catalogue import DEFAULT_METHOD, LEAST_CHANGE_PRIORS, METHODS, fit_note, label, quality
from homocal.correctors.hybrid import DEFAULT_THRESHOLD
from homocal.correctors.least_change import LeastChangeCorrector
from homocal.correctors.pedestrians import SETTINGS as PEDESTRIAN_SETTINGS
from homocal.correctors.pedestrians import PedestrianCorrector
from homocal.correctors.serialization import FORMAT
from homocal.files import check_output_file, csv_header, json_format, read_points_csv, write_text_atomic
from homocal.geometry import MAX_COORDINATE, CameraModel, ViewTransformer, read_trapezoid_file
from homocal.geometry.lens import undistort_input
from homocal.study.options import OptionError, flag_type
from homocal.uncertainty import max_trustworthy_range, sigma_radius, straight_ahead_column
from homocal.watch.folder import correction_at, load_stretches, watch_corrections

LEAST_CHANGE = {k: LeastChangeCorrector().get_params()[k] for k in LEAST_CHANGE_PRIORS}  # fit's prior flags, defaults
TRUST_TOLERANCE_M = 0.5  # homocal fit reports how far the 1-sigma error stays under this
APPLIED = ("x", "y", "sigma_m", "status")  # the columns homocal apply adds (last in its output)
BOX_FLAGS = {"boxes": "--boxes", "detector": "--detector",
             **{name: opt.flag for name, opt in PEDESTRIAN_SETTINGS.items()}}  # fit's flags of --method pedestrians

FIT_FORMATS = """\
TRAP.json, the trapezoid (vertices in the order TL, TR, BR, BL as seen in the image):
  {"image": [[u, v], x4],          image pixels (OpenCV: x right, y down, pixel centres at integers)
   "map":   [[x, y], x4]}          the same 4 points on the ground, metres (x right, y forward)
  or, when "map" is in site-map pixels, add their scale and origin (the map pixel of the ground origin):
  {"image": ..., "map": [[px, py], x4], "site_map": {"scale_px_per_m": 10, "origin_px": [ox, oy]}}
  A simgen dataset's trapezoids.json is accepted too: its "hand_placed" trapezoid is used, with the
  site_map.json beside it.
REF.csv, three or more reference points, a header line then one row per point:
  u,v,x,y        u, v: the image foot point (pixels); x, y: its true ground position (metres)
  Other columns are ignored. Points are counted from 0 in error messages. Each point must be measured
  once (a repeated image or ground point is refused); a point with y < the camera origin's y (behind
  the camera) gets a warning.
The map trapezoid must go round the same way as the image's (the same corner order TL, TR, BR, BL as
seen in the image): a mirrored or upside-down map is refused.
The camera origin (--camera-origin, metres, default 0,0) is the ground point under the camera; write
a negative value as --camera-origin=-1.5,0.
The correction JSON holds everything needed to apply it later (homocal apply). The last line printed is
the range straight ahead out to which the 1-sigma error of a corrected point (the correction's error model,
as homocal apply's sigma_m, at 1.5 px clicking error on each trapezoid corner and 1 px on the foot point:
homocal.max_trustworthy_range) stays under 0.5 m.

CAMERA.json (--camera-json, any method): a dataset's camera.json; a lens.json
  {"K": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], "distortion": [k1, k2, p1, p2, k3], "image_size": [W, H]}
(homocal lens; OpenCV's distortion model); or {"width": W, "height": H, "K": ...} (K optional). Its lens
undistorts the trapezoid's image corners, the reference points and the boxes (after testing them for the
image border in the camera's pixels, where the frame cuts them) before any homography, and
the correction carries it (homocal apply undistorts the feet with it). The trapezoid file's "image_size"
(a dataset's: its camera.json's) and the boxes file's must be the lens's.

--method pedestrians fits from people's boxes instead (--boxes), with no reference point: the camera's
tilt from the boxes' implied heights (docs/pedestrians.md). BOXES is a MOTChallenge .txt (simgen export-mot's
SEQ/det/<detector>.txt; seqinfo.ini beside SEQ/det gives the image size), a simgen dataset's
detections.parquet (--detector, default segmentation; its camera.json gives K and the image size) or a
.csv with columns frame,x1,y1,x2,y2 (optional track_id; pixel corners at integers, as supervision's
Detections.xyxy). --camera-json gives the image size and K (K optional): without K the focal length is
read from the clicked trapezoid (principal point at the image centre), without --camera-height the height
too; give both when you can.
--points is then optional: the reference points do not enter the fit, they check it (independent
evidence: their mean error before and after is printed and stored). The fit is refused when more than half
of the boxes, or of the people (tracks), are outliers: the robust fit can follow them there."""

APPLY_FORMATS = """\
FEET.csv: a header line then one row per point; columns u, v (image foot point, pixels) are required,
other columns are carried through to the output. The output has the same rows and columns plus
  x, y      the corrected ground position in metres (replacing any x, y of the input);
  sigma_m   its 1-sigma radius in metres (sqrt of the largest eigenvalue of the first-order covariance
            of the correction's error model, Corrector.ground_uncertainty): homocal.ground_uncertainty
            for a clicking error of --click-sigma-px on each corner of the trapezoid the correction maps
            with (descent's, horizon's, least-change's and pedestrians' own, the clicked one for the
            regressions) and --point-sigma-px on the foot point; for pedestrians plus the fitted
            horizon's own uncertainty (its horizon_sigma_px as a tilt error);
  status    ok; beyond_horizon (on or above the horizon: x, y, sigma_m = nan); bad_input (u or v is
            nan, inf or beyond +/-1e9 in the input, or beyond the fold of the correction's lens: x, y,
            sigma_m = nan).
A correction fitted with --camera-json carries that lens: the feet are the camera's pixels, undistorted
with it before the mapping.
Rows are never dropped; the summary line names the lines of the non-finite rows."""


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Register ``fit`` and ``apply``."""
    fmt = argparse.RawDescriptionHelpFormatter
    fit = subparsers.add_parser(
        "fit", help="fit a correction from reference points", epilog=FIT_FORMATS, formatter_class=fmt,
        description="Fit a correction of a trapezoid homography from three or more reference points.",
    )
    fit.add_argument("--trapezoid", required=True, type=Path, metavar="TRAP.json", help="the trapezoid (see below)")
    fit.add_argument("--points", type=Path, metavar="REF.csv",
                     help=f"reference points u,v,x,y (at most {MAX_REFERENCE_POINTS:,}); required, except with "
                          "--method pedestrians, where they only check the fit")
    fit.add_argument("--method", default=DEFAULT_METHOD, choices=METHODS, help="; ".join(
                     f"{m.name}: {m.description}" for m in METHODS.values()) + f" (default {DEFAULT_METHOD})")
    fit.add_argument("-o", "--out", required=True, type=Path, metavar="CORRECTION.json", help="the correction to write")
    fit.add_argument("--camera-origin", type=xy_pair, default=(0.0, 0.0), metavar="X,Y",
                     help="ground point under the camera, metres (default 0,0)")
    fit.add_argument("--threshold", type=number(float, 0, 100), default=DEFAULT_THRESHOLD, help="hybrid: keep regression at or "
                     "above this calibration improvement, percent (default %(default)g)")
    fit.add_argument("--seed", type=SEED, default=0, help="descent, hybrid: seed of the coordinate order (default 0)")
    for name, what, low_open in (("click_sigma_px", "clicking error of each image corner coordinate, pixels", True),
                                 ("map_sigma_m", "clicking error of each map corner coordinate, metres (0: the map trapezoid stays)", False),
                                 ("point_sigma_m", "measurement error of each reference point coordinate, metres", True)):
        fit.add_argument("--" + name.replace("_", "-"), type=number(float, 0, 1e6, low_open=low_open), default=None,
                         metavar=name.rsplit("_", 1)[1].upper(),
                         help=f"least-change only: prior sigma, {what} (default {LEAST_CHANGE[name]:g})")
    fit.add_argument("--boxes", type=Path, metavar="BOXES", help="pedestrians: people's boxes, a MOT .txt, a "
                     "detections.parquet or a .csv (see below)")
    fit.add_argument("--detector", metavar="NAME", help=f"pedestrians: the detector's rows of a detections.parquet "
                     f"(default {DEFAULT_DETECTOR})")
    add_pedestrian_flags(fit, PEDESTRIAN_SETTINGS, "pedestrians: ")
    fit.add_argument("--camera-json", type=Path, metavar="CAMERA.json", help=CAMERA_JSON_HELP + "; it is saved "
                     "with the correction. Pedestrians: its image size and K (default: those beside the boxes file)")
    fit.set_defaults(handler=handle_fit)

    apply = subparsers.add_parser(
        "apply", help="map image foot points to corrected ground positions", epilog=APPLY_FORMATS,
        formatter_class=fmt, description="Map image foot points to corrected ground positions with a fitted correction.",
    )
    apply.add_argument("correction", type=Path, metavar="CORRECTION.json", help="written by homocal fit, or a homocal "
                       "watch folder (with --at, or a t column in FEET.csv: the stretch of that time)")
    apply.add_argument("--at", type=number(float, 0), metavar="SECONDS", help="a watch folder's stretch at this time")
    apply.add_argument("--points", required=True, type=Path, metavar="FEET.csv", help="image foot points u,v")
    apply.add_argument("-o", "--out", required=True, type=Path, metavar="CORRECTED.csv",
                       help="the CSV to write; - writes it to stdout (the summary line then goes to stderr)")
    apply.add_argument("--click-sigma-px", type=number(float, 0), default=1.5, metavar="PX",
                       help="sigma_m: clicking error of each trapezoid coordinate, pixels (default 1.5)")
    apply.add_argument("--point-sigma-px", type=number(float, 0), default=1.0, metavar="PX",
                       help="sigma_m: error of each foot point coordinate, pixels (default 1.0)")
    apply.add_argument("--decimals", type=number(int, 0, 17), metavar="N", help="x, y and sigma_m rounded to N "
                       "decimals of a metre (3: the millimetre, finer than any error bar of a homography fit); "
                       "default: every digit of the float")
    apply.set_defaults(handler=handle_apply)


def add_pedestrian_flags(parser: argparse.ArgumentParser, names, use: str = "") -> None:
    """Add the flags of the pedestrian settings ``names`` (PEDESTRIAN_SETTINGS: each one's flag, bounds and help)
    to parser, dest the setting's name, default None (PedestrianCorrector's default, which the help names; use
    starts the help): homocal fit's and homocal watch's."""
    defaults = PedestrianCorrector().get_params()
    for name in names:
        opt = PEDESTRIAN_SETTINGS[name]
        default = opt.none if defaults.get(name) is None else opt.to_text(defaults[name])
        parser.add_argument(opt.flag, dest=name, type=flag_type(opt), metavar=opt.metavar,
                            help=f"{use}{opt.help}: {opt.expected()} (default: {default})")


def pedestrian_flag_error(e: OptionError) -> ValueError:
    """A pedestrian setting's OptionError as the one-line error of its flag (add_pedestrian_flags)."""
    return ValueError(f"argument {PEDESTRIAN_SETTINGS[e.name].flag}: {e.expected}, got {e.value!r}")


def handle_fit(args: argparse.Namespace) -> int:
    camera = camera_json(args.camera_json)
    lens = None if camera is None else camera.lens
    transformer = read_trapezoid_file(args.trapezoid, lens)[0]
    method = METHODS[args.method]
    boxes_flags = [flag for key, flag in BOX_FLAGS.items() if getattr(args, key) is not None]
    if method.evidence == "boxes" and args.boxes is None:
        raise ValueError(f"--boxes: required with --method {args.method}")
    if method.evidence == "points" and args.points is None:
        raise ValueError(f"--points: required with --method {args.method}")
    if method.evidence == "points" and boxes_flags:
        raise ValueError(f"{', '.join(boxes_flags)}: for --method pedestrians, not {args.method}")
    points = None
    if args.points is not None:
        _, _, cols, _ = read_points_csv(args.points, ("u", "v", "x", "y"), finite=True, most=MAX_REFERENCE_POINTS)
        points = np.column_stack([undistort_input(np.column_stack([cols["u"], cols["v"]]), lens, str(args.points)),
                                  cols["x"], cols["y"]])
    if str(args.out) == "-":
        raise ValueError("-o -: the correction is a JSON file, not a table: give its file name")
    check_output_file(args.out, lambda p: json_format(p) == FORMAT, "homocal correction (JSON with format "
                      f"{FORMAT!r})")
    given = [f"--{k.replace('_', '-')}" for k in LEAST_CHANGE if getattr(args, k) is not None]
    if given and args.method != "least-change":
        raise ValueError(f"{', '.join(given)}: the priors of --method least-change, not of {args.method}")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if method.evidence == "boxes":
            corrector, source = _fit_from_boxes(args, method, transformer, points, camera)
        else:
            corrector, source = _fit_from_points(args, method, transformer, points)
    for w in caught:
        print(f"homocal: warning: {args.points or args.boxes}: {w.message}", file=sys.stderr)
    corrector.lens_ = None if lens is None or lens.is_identity else lens  # a pinhole's correction stays as before
    corrector.save(args.out)
    print(f"homocal fit: {args.method} correction from {source} written to {args.out}: "
          f"{quality(corrector)}.{fit_note(corrector)}")
    mapping = corrector.mapping
    trust = max_trustworthy_range(mapping, TRUST_TOLERANCE_M, camera_origin=args.camera_origin,
                                  uncertainty=corrector.ground_uncertainty)
    print(f"Error bars (1.5 px clicking error on each trapezoid corner, 1 px on a foot point): the 1-sigma error "
          f"stays under {TRUST_TOLERANCE_M:g} m out to {trust:.1f} m straight ahead (image column "
          f"{straight_ahead_column(mapping):.0f}).")
    return 0


def _fit_from_points(args: argparse.Namespace, method, transformer: ViewTransformer, points: np.ndarray):
    """The fitted corrector of a points method and a phrase naming its evidence; ValueError naming --points."""
    corrector = method.make(**{k: getattr(args, k) for k in method.settings})
    try:
        corrector.fit(transformer, points[:, :2], points[:, 2:], args.camera_origin)
    except ValueError as e:
        raise ValueError(f"{args.points}: {e}") from None
    return corrector, f"{len(points)} reference points"


def _fit_from_boxes(args: argparse.Namespace, method, transformer: ViewTransformer, points: np.ndarray | None,
                    camera: CameraModel | None):
    """The fitted PedestrianCorrector of fit's flags (the camera's pixels and its lens: fit(lens=) tests the image
    border on them, then undistorts) and a phrase naming its evidence; ValueError naming the flag (or --boxes /
    --points) for bad input or an untrustworthy fit."""
    lens = None if camera is None else camera.lens
    try:
        corrector = method.make(**{k: getattr(args, k) for k in method.settings})
        boxes = _read_boxes(args, lens)
        size, K = boxes.image_size, boxes.K
        source = f"--boxes {args.boxes}'s folder"
        if camera is not None:
            size, K = camera.image_size, camera.K
            source = f"--camera-json {args.camera_json}"
        check = {} if points is None else {"image_points": points[:, :2], "ground_points": points[:, 2:]}
        corrector.fit(transformer, boxes.xyxy, convention="homocal", frames=boxes.frames, track_ids=boxes.track_ids,
                      camera_height_m=args.camera_height_m, K=K, image_size=size, camera_origin=args.camera_origin,
                      lens=lens, **check)
    except OptionError as e:  # a value within its own bounds that does not fit another (the sd and the mean)
        raise pedestrian_flag_error(e) from None
    except ValueError as e:
        message = str(e)
        if message.startswith("--"):  # already naming its flag (the boxes and camera readers')
            raise
        if message.startswith("K and image_size"):
            raise ValueError(f"--camera-json: needed ({args.boxes} gives neither the image size nor K)") from None
        if message.startswith(("K:", "image_size:")):  # the camera's, from --camera-json or the boxes' folder
            raise ValueError(f"{source}: {message}") from None
        if message.startswith(("image_points", "ground_points", "need at least 3 calibration")):  # the check points'
            raise ValueError(f"--points {args.points}: {message}") from None
        raise ValueError(f"--boxes {args.boxes}: {message.removeprefix('xyxy: ')}") from None
    checked = "" if points is None else f", checked on {len(points)} reference points"
    return corrector, f"{corrector.n_boxes_} boxes of {args.boxes}{checked}"


def _read_boxes(args: argparse.Namespace, lens):
    """read_boxes of --boxes (and --detector), checked against lens, in the camera's pixels; its ValueError naming
    the flag."""
    try:
        return read_boxes(args.boxes, args.detector, lens, undistort=False)
    except ValueError as e:
        raise ValueError(f"--boxes {e}") from None


def handle_apply(args: argparse.Namespace) -> int:
    fields, rows, cols, lines = read_points_csv(args.points, ("u", "v"), finite=False,
                                                optional=("t",) if args.correction.is_dir() else ())
    if args.correction.is_dir():
        stretches = watch_corrections(args.correction)
        if args.at is None and "t" not in cols:
            raise ValueError(f"{args.correction} is a watch folder: give --at SECONDS or a t column in {args.points}")
        t = np.full(len(rows), args.at) if args.at is not None else cols["t"]
        bad = np.flatnonzero(~(np.abs(t) <= 1e12))
        if bad.size:
            raise ValueError(f"{args.points}, line {lines[bad[0]]}: t is not a finite number of seconds")
        which = correction_at(stretches, t)
        correctors = load_stretches(args.correction)
        refused = np.flatnonzero([isinstance(correctors[k], str) for k in which])
        if refused.size:
            i = int(refused[0])
            raise ValueError(f"{args.points}, line {lines[i]}: t = {t[i]:g} s has no correction in {args.correction}: "
                             f"{correctors[which[i]]}")
        corrector = correctors[int(np.bincount(which, minlength=len(correctors)).argmax())]
    else:
        if args.at is not None:
            raise ValueError(f"--at: for a homocal watch folder, not the file {args.correction}")
        corrector = load_corrector(args.correction)
        correctors, which = [corrector], np.zeros(len(rows), np.int64)
    to_stdout = str(args.out) == "-"
    if not to_stdout:
        check_output_file(args.out, lambda p: (csv_header(p) or [])[-4:] == list(APPLIED),
                          f"CSV written by homocal apply (header ending {','.join(APPLIED)})")
    q = np.column_stack([cols["u"], cols["v"]])
    bad_input = ~(np.abs(q) <= MAX_COORDINATE).all(axis=1)  # nan, inf, or an overflow
    q[bad_input] = np.nan
    xy, sigma = np.full((len(q), 2), np.nan), np.full(len(q), np.nan)
    for k in np.unique(which):
        rows_k, lens = which == k, correctors[k].lens_
        q_k = q[rows_k] if lens is None else lens.undistort_points(q[rows_k])  # the undistorted image it maps
        bad_input[rows_k] |= np.isnan(q_k).any(axis=1) & ~np.isnan(q[rows_k]).any(axis=1)  # beyond the lens's fold
        xy[rows_k] = correctors[k].transform_points(q_k)
        sigma[rows_k] = sigma_radius(correctors[k].ground_uncertainty(q_k, args.click_sigma_px, args.point_sigma_px))
    status = np.where(bad_input, "bad_input", np.where(np.isnan(xy).any(axis=1), "beyond_horizon", "ok"))
    out_fields = [f for f in fields if f not in APPLIED] + list(APPLIED)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(out_fields)
    for row, (x, y), sm, st in zip(rows, xy, sigma, status):
        row = {**row, **{k: _metres(v, args.decimals) for k, v in (("x", x), ("y", y), ("sigma_m", sm))}, "status": st}
        writer.writerow([row[f] for f in out_fields])
    if to_stdout:
        sys.stdout.write(buffer.getvalue())
    else:
        write_text_atomic(args.out, buffer.getvalue())
    beyond = int((status == "beyond_horizon").sum())
    bad_lines = [lines[i] for i in np.flatnonzero(bad_input)]
    bad = (f"; {len(bad_lines)} with u or v nan, inf or beyond 1e9{'' if corrector.lens_ is None else ' or the lens'} (status bad_input, line"
           f"{'s' if len(bad_lines) > 1 else ''} {_line_list(bad_lines)})" if bad_lines else "")
    print(f"homocal apply: {len(rows)} points mapped with the {label(corrector)} correction of {args.correction} "
          f"and written to {'stdout' if to_stdout else args.out}; {beyond} on or above the horizon (status "
          f"beyond_horizon){bad}; x, y, sigma_m = nan for those. The correction was fitted with {quality(corrector)}.",
          file=sys.stderr if to_stdout else sys.stdout)
    return 0


def _metres(value: float, decimals: int | None) -> str:
    """A length (m) as homocal apply writes it: every digit of the float (repr), or rounded to decimals (--decimals)."""
    return repr(float(value)) if decimals is None else f"{value:.{decimals}f}"


def _line_list(lines: list[int], most: int = 10) -> str:
    shown = ", ".join(map(str, lines[:most]))
    return shown + (f" and {len(lines) - most} more" if len(lines) > most else "")

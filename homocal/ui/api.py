"""The page's JSON API: each endpoint takes the request's JSON object and returns the response's.

Bad input raises ValueError naming the request's field (the server answers 400 with its message),
FileExistsError (409, the page asks before replacing) or ``Refused`` (409, never replaced). Every
computation goes through the library: the trapezoid's ViewTransformer is built as ``homocal fit`` builds it
from the saved trapezoid.json, and the correction is made from the method catalogue as ``homocal fit`` does.
Bounds: at most MAX_REFERENCE_POINTS points, coordinates within +/-MAX_COORDINATE, sigmas up to MAX_SIGMA_PX,
seeds in [0, 2**64), the hybrid's threshold in [0, 100] percent; a checkerboard's those of ``homocal lens
--checkerboard`` (homocal.lens.checkerboard), its photographs within the server's MAX_BOARD_BODY. A method fitted from
people's boxes reads the session's boxes file (named at launch: a request names only one of its detectors, never
a path).
"""
from __future__ import annotations

import base64
import csv
import glob
import io
import math
import os
import shlex
import tempfile
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

from homocal.arguments import within
from homocal.correctors.base import MAX_REFERENCE_POINTS, Corrector, load_corrector
from homocal.correctors.catalogue import Method, fit_note, get_method, method_of, quality
from homocal.correctors.hybrid import DEFAULT_THRESHOLD
from homocal.correctors.pedestrians import SETTINGS as PEDESTRIAN_SETTINGS
from homocal.correctors.pedestrians import BOX_STATUS, PedestrianCorrector
from homocal.correctors.serialization import float_or_none
from homocal.files import read_json, read_points_csv, write_atomic, write_json_atomic, write_text_atomic
from homocal.geometry import MAX_COORDINATE, SiteMap, ViewTransformer, signed_area, validate_quad
from homocal.lens.checkerboard import MAX_FRAMES, MAX_SQUARE_M, calibrate_board, parse_pattern
from homocal.lens.lines import DEFAULT_HFOV_DEG, DEFAULT_TERMS, TERMS, check_lines, fit_lines, intrinsics
from homocal.ui import overlay
from homocal.ui.errorbars import error_bars
from homocal.ui.session import Session, undistorted, use_lens
from homocal.watch import OnlineCalibrator
from homocal.watch.calibrator import PERSON_BOXES, by_frame, camera_of, stretch_correction
from homocal.watch.cli import CALIBRATOR_SETTINGS, WATCH_SETTINGS
from homocal.watch.folder import correction_at

TRAPEZOID_FILE, POINTS_FILE, CORRECTION_FILE = "trapezoid.json", "reference_points.csv", "correction.json"
LINES_FILE, LENS_FILE = "lines.json", "lens.json"  # the line tool's: homocal lens --lines LINES_FILE -o LENS_FILE
BOARD_DIR = "checkerboard"  # the checkerboard's photographs: homocal lens --checkerboard 'BOARD_DIR/*' -o LENS_FILE
CAMERA_FILE = "camera_intrinsics.json"  # Save's --camera-json of a fit from boxes (not camera.json: a dataset's)
MAX_SIGMA_PX = 100.0  # the error bars' sigmas (pixels): a clicking error beyond this is no click
MAX_TOLERANCE_M = 1e6
MAX_SEED = 2**64 - 1
NOT_WATCHS = tuple(PEDESTRIAN_SETTINGS[k].flag for k in PEDESTRIAN_SETTINGS if k not in WATCH_SETTINGS)  # fit's, not watch's
MAX_DRAWN_BOXES = 5000  # people's boxes a fit answers for the page to draw (every k-th beyond it)
MAX_PLOT_POINTS = 2000  # points of each curve of the horizon over time the page is sent (every k-th beyond it)


class Refused(Exception):
    """A request the server refuses whatever the page says (409, no "Replace?")."""


# ---- request fields -------------------------------------------------------------------------------
def _number(req: dict, key: str, default: float | None, low: float, high: float, low_open: bool = False) -> float:
    """The request's field ``key`` (``default`` if absent; None: required): a finite number in [low, high] ((low,
    high] if low_open)."""
    value = req.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{key}: expected a finite number, got {value!r}")
    if not within(value, low, high, low_open):
        raise ValueError(f"{key}: expected a number in {'(' if low_open else '['}{low:g}, {high:g}], got {value!r}")
    return float(value)


def _flag_text(value) -> str:
    """A setting's value as a command line takes it back exactly: yes or no, a word (auto), or the number's repr."""
    return ("yes" if value else "no") if isinstance(value, bool) else value if isinstance(value, str) else repr(value)


def _points(value, name: str, width: int, most: int | None = None) -> np.ndarray:
    """A list of points of ``width`` finite numbers within +/-MAX_COORDINATE each, as (N, width) float64."""
    if not isinstance(value, list) or (most is not None and len(value) > most):
        raise ValueError(f"{name}: expected a list of " + (f"at most {most:,} " if most else "") + "points")
    for i, p in enumerate(value):
        if (not isinstance(p, list) or len(p) != width
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and abs(x) <= MAX_COORDINATE
                           for x in p)):
            raise ValueError(f"{name}[{i}]: expected {width} finite numbers within +/-{MAX_COORDINATE:g}, got {p!r}")
    return np.array(value, dtype=np.float64).reshape(len(value), width)


def _camera_origin(req: dict) -> np.ndarray:
    return _points([req.get("camera_origin")], "camera_origin", 2)[0]


def trapezoid(req: dict) -> tuple[np.ndarray, np.ndarray]:
    """The clicked corners so far: image (<= 4, 2) px and site map (<= 4, 2) map px, in order TL, TR, BR, BL."""
    trap = req.get("trapezoid")
    if not isinstance(trap, dict):
        raise ValueError('trapezoid: expected {"image": [[u, v], ...], "map": [[px, py], ...]}')
    return _points(trap.get("image"), "trapezoid image", 2, 4), _points(trap.get("map"), "trapezoid map", 2, 4)


def check_corner_order(quad: np.ndarray, side: str) -> None:
    """Refuse a convex quad (4, 2) (pixels, y down) whose corners TL, TR, BR, BL do not go clockwise on screen
    with TL, TR above BR, BL. On the site map (map up = forward, data_schema.md) that is a mirrored or an
    upside-down map; in the image, corners clicked out of order."""
    clockwise = signed_area(quad) > 0  # clockwise as drawn in a y-down frame
    top_above = quad[0, 1] + quad[1, 1] < quad[2, 1] + quad[3, 1]
    if side == "map" and not clockwise:
        raise ValueError("map corners: mirrored (TL, TR, BR, BL must go clockwise on the map, as in the image); "
                         "is the map image flipped?")
    if side == "map" and not top_above:
        raise ValueError("map corners: upside down (the far edge TL-TR must be above the near edge BL-BR: "
                         "map up = forward, away from the camera); is the map image turned?")
    if not (clockwise and top_above):
        raise ValueError("image corners: click them in the order TL, TR, BR, BL (top-left first, clockwise)")


def transformer_of(session: Session, image: np.ndarray, map_px: np.ndarray) -> ViewTransformer | None:
    """The ViewTransformer of a complete trapezoid (as ``homocal fit`` builds it from trapezoid.json), None if
    a side has fewer than 4 corners; ValueError for a degenerate, mirrored or upside-down quad."""
    for quad, side in ((image, "image"), (map_px, "map")):
        if len(quad) == 4:
            check_corner_order(validate_quad(quad, f"{side} corners"), side)
    if len(image) < 4 or len(map_px) < 4:
        return None
    image = validate_quad(undistorted(session, validate_quad(image, "image"), "image corners"), "image (undistorted)")
    return ViewTransformer(image, session.site_map.to_metres(validate_quad(map_px, "map")))


def _complete_transformer(session: Session, req: dict) -> ViewTransformer:
    transformer = transformer_of(session, *trapezoid(req))
    if transformer is None:
        raise ValueError("click all 4 image corners and all 4 map corners first")
    return transformer


def method_request(req: dict) -> tuple[Method, dict]:
    """The request's method (the catalogue's name) and the settings the page gives it: seed (an integer in
    [0, 2**64)), threshold (percent, [0, 100]), the pedestrian settings (PEDESTRIAN_SETTINGS' names, bounds and
    units; the constructor checks them), homocal fit's defaults if absent."""
    method = get_method(req.get("method"))
    seed = _number(req, "seed", 0, 0, MAX_SEED)
    if seed != int(seed):
        raise ValueError(f"seed: expected an integer, got {req.get('seed')!r}")
    page = {"seed": int(req.get("seed", 0)), "threshold": _number(req, "threshold", DEFAULT_THRESHOLD, 0, 100),
            **{k: req[k] for k in PEDESTRIAN_SETTINGS if req.get(k) is not None}}
    return method, {k: v for k, v in page.items() if k in method.settings}


def _fitted(session: Session, req: dict) -> tuple[Corrector, ViewTransformer, np.ndarray, list, dict | None]:
    """Fit the request's method as ``homocal fit`` does; return it with the transformer, the points (N, 4) u,v,x,y
    (from reference points: at least 3; from boxes: any, they only check the fit), the library's warnings and,
    for a fit from boxes, the ``_box_settings`` it used (None otherwise)."""
    transformer = _complete_transformer(session, req)
    points = _points(req.get("points"), "points", 4, MAX_REFERENCE_POINTS)
    points[:, :2] = undistorted(session, points[:, :2], "points")
    method, settings = method_request(req)
    corrector = method.make(**settings)
    corrector.lens_ = session.lens
    box_settings = None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if method.evidence == "boxes" and req.get("at_s") is not None:
            corrector, box_settings = _stretch(session, req)
        elif method.evidence == "boxes":
            box_settings = _fit_boxes(session, req, corrector, transformer, points)
        else:
            corrector.fit(transformer, points[:, :2], points[:, 2:], _camera_origin(req))
    return corrector, transformer, points, [str(w.message) for w in caught], box_settings


def _box_settings(session: Session, req: dict) -> dict:
    """What a fit from the session's boxes uses besides the trapezoid and the height prior: "detector" (the
    request's, one of the session's detectors; default segmentation if it has one, else the first; None for a
    file without detectors), "camera_height_m" (the request's; None: from the clicked mapping), "boxes" (the
    PersonBoxes read), "image_size" (the boxes file's, else the frame's) and "K" (the boxes file's, else None:
    from the mapping)."""
    if session.boxes is None:
        raise ValueError("method: pedestrians fits from people's boxes: start homocal ui with --boxes FILE (or a "
                         "dataset folder)")
    detector = req.get("detector")
    if session.detectors:
        default = "segmentation" if "segmentation" in session.detectors else session.detectors[0]
        detector = default if detector is None else detector
        if detector not in session.detectors:
            raise ValueError(f"detector: expected one of {', '.join(session.detectors)}, got {detector!r}")
    elif detector is not None:
        raise ValueError(f"detector: {session.boxes.name} has no detectors to choose from")
    height = req.get("camera_height_m")
    height = None if height is None else PEDESTRIAN_SETTINGS["camera_height_m"].check("camera_height_m", height)
    boxes = session.person_boxes(detector)
    return {"detector": detector, "camera_height_m": height, "boxes": boxes,
            "image_size": boxes.image_size or session.frame_size, "K": boxes.K}


def _fit_boxes(session: Session, req: dict, corrector, transformer: ViewTransformer, points: np.ndarray) -> dict:
    """Fit a PedestrianCorrector on the session's boxes with _box_settings, and return those; the points, if any,
    check it."""
    settings = _box_settings(session, req)
    boxes = settings["boxes"]
    check = {"image_points": points[:, :2], "ground_points": points[:, 2:]} if len(points) else {}
    corrector.fit(transformer, boxes.xyxy, convention="homocal", frames=boxes.frames, track_ids=boxes.track_ids,
                  camera_height_m=settings["camera_height_m"], K=settings["K"], image_size=settings["image_size"],
                  camera_origin=_camera_origin(req), lens=session.lens, **check)
    return settings


def _sigmas(req: dict) -> dict:
    return {key: _number(req, key, default, 0, MAX_SIGMA_PX)
            for key, default in (("click_sigma_px", 1.5), ("point_sigma_px", 1.0), ("map_sigma_px", 0.0))}


def _tolerance(req: dict) -> float:
    return _number(req, "tolerance_m", 0.5, 0, MAX_TOLERANCE_M)


# ---- endpoints ------------------------------------------------------------------------------------
def view(session: Session, req: dict) -> dict:
    """Horizon, ground grid, footprint, error bars and trustworthy range of the trapezoid clicked so far
    ("errorbars": false leaves the last two out: the page asks so while a corner is dragged)."""
    transformer = transformer_of(session, *trapezoid(req))
    if transformer is None:
        return {"complete": False}
    origin = _camera_origin(req)
    (w, h), (mw, mh) = session.frame_size, session.map_size
    map_corners = session.site_map.to_metres(np.array([[-0.5, -0.5], [mw - 0.5, -0.5], [mw - 0.5, mh - 0.5],
                                                       [-0.5, mh - 0.5]]))
    max_range = float(np.hypot(*(map_corners - origin).T).max())
    field = overlay.sample_mapping(transformer.transform_points, transformer, w, h, session.lens)
    return {
        "complete": True,
        "horizon": overlay.through_lens(overlay.horizon_segment(transformer, w, h), session.lens),
        "grid": overlay.ground_grid(field, origin),
        "footprint": overlay.footprint(transformer, w, h, session.site_map, origin, max_range, session.lens),
        "errorbars": None if req.get("errorbars") is False else error_bars(
            session, transformer, overlay.grid_nodes(field, transformer, lens=session.lens), origin,
            _tolerance(req), **_sigmas(req)),
    }


def fit(session: Session, req: dict) -> dict:
    """Fit the chosen method on the reference points (or the session's boxes); errors before/after, per-point
    residuals, the corrected grid, the horizon of the mapping the correction maps with (Corrector.mapping: the
    clicked one for the regressions), the trustworthy range of the correction's own error model
    (Corrector.ground_uncertainty), for a fit from boxes the boxes it read by their part in it (drawn_boxes)
    and the correction's JSON (what Save writes; its calibration_improvement is negative for a correction that
    makes the reference, or check, points worse)."""
    corrector, transformer, points, caught, box_settings = _fitted(session, req)
    mapped = transformer.transform_points(points[:, :2])
    corrected = corrector.transform_points(points[:, :2])
    w, h = session.frame_size
    tolerance = _tolerance(req)
    trust = error_bars(session, corrector.mapping, np.zeros((0, 2)), _camera_origin(req), tolerance, **_sigmas(req),
                       uncertainty=corrector.ground_uncertainty)["trustworthy_range_m"]
    trust_note = (f" With its mapping the 1-sigma error stays under {tolerance:g} m out to "
                  + ("any range" if trust is None else f"{trust:.1f} m") + " straight ahead.")
    return {
        "summary": f"{method_of(corrector).name}: {quality(corrector)}.{fit_note(corrector)}{trust_note}",
        "warnings": caught,
        "error_before": float_or_none(corrector.error_before_),  # None: no check points (pedestrians)
        "error_after": float_or_none(corrector.error_after_),
        "mapped": mapped.tolist(),
        "corrected": corrected.tolist(),
        "residual_before": np.hypot(*(mapped - points[:, 2:]).T).tolist(),
        "residual_after": np.hypot(*(corrected - points[:, 2:]).T).tolist(),
        "corrected_grid": overlay.ground_grid(overlay.sample_mapping(corrector.transform_points, transformer, w, h,
                                                                     session.lens), _camera_origin(req)),
        "horizon": overlay.through_lens(overlay.horizon_segment(corrector.mapping, w, h), session.lens),
        "boxes": None if box_settings is None or "stretch" in box_settings else drawn_boxes(
            box_settings["boxes"].xyxy, corrector.box_status_),
        "correction": corrector.to_dict(),
    }


def drawn_boxes(xyxy: np.ndarray, status: np.ndarray) -> dict:
    """The boxes (N, 4) x1, y1, x2, y2 px (the frame's pixels, as the file gave them) a fit from boxes read, by their
    part in it (status (N,), one of BOX_STATUS), for the page to draw on the frame: {"used":
    [outline, ...], "outlier": [...], "border": [...], "hidden": [...], "total": N, "step": k}, each outline the box's 4 corners and 4 side
    midpoints (from the top-left, clockwise); every k-th box of each kind, at most MAX_DRAWN_BOXES in all."""
    step = max(1, math.ceil(len(xyxy) / MAX_DRAWN_BOXES))
    out = {}
    for kind in BOX_STATUS:
        x1, y1, x2, y2 = xyxy[status == kind][::step].T
        xc, yc = (x1 + x2) / 2, (y1 + y2) / 2
        outline = np.stack([np.column_stack(p) for p in ((x1, y1), (xc, y1), (x2, y1), (x2, yc), (x2, y2), (xc, y2),
                                                         (x1, y2), (x1, yc))], axis=1)  # (n, 8, 2)
        out[kind] = np.round(outline, 1).tolist()
    return {**out, "total": len(xyxy), "step": step}


def _watched(session: Session, req: dict) -> dict:
    """Run homocal.watch's OnlineCalibrator over the session's boxes (of the request's detector, at its camera
    height and height prior, K and the camera height as homocal watch takes them: watch.camera_of), in time order at
    the session's fps. Returns {"states": [State per frame], "moves": [Move], "stretches": [(start_s, horizon row,
    1-sigma px, people, roll degrees, its 1-sigma, outlier people)] (as homocal watch's corrections/: each stretch's estimate when it ended, the last one's
    at the end of the boxes; stretches of fewer than 3 people left out), "K", "camera_height_m", "transformer",
    "calibrator" (the OnlineCalibrator after them: its prior and settings)}."""
    if session.fps is None:
        raise ValueError(f"fps: {session.boxes.name if session.boxes else 'the boxes'} does not say its frame rate: "
                         "start homocal ui with --fps")
    transformer = _complete_transformer(session, req)
    settings = _box_settings(session, req)
    prior = PedestrianCorrector(**{k: req[k] for k in CALIBRATOR_SETTINGS if req.get(k) is not None})
    K, height = camera_of(transformer, settings["image_size"], settings["K"], settings["camera_height_m"])
    calibrator = OnlineCalibrator(K, height, session.fps, settings["image_size"], prior.height_mean_m,
                                  prior.height_sd_m, lens=session.lens, estimate_roll=prior.estimate_roll,
                                  box_margin_px=prior.box_margin_px)
    boxes = settings["boxes"]
    states = [calibrator.update(*frame) for frame in by_frame(boxes.frames, boxes.xyxy, boxes.track_ids,
                                                              str(session.boxes))]
    moves = [s.move for s in states if s.move is not None]
    stretches = [(start, m.horizon_before, m.sigma_before, m.n_before, m.roll_before_deg, m.roll_sigma_before_deg,
                  m.n_outliers_before)
                 for start, m in zip([0.0] + [m.t_s for m in moves], moves)]
    if states:
        last = states[-1]
        stretches.append((last.stretch_start_s, last.horizon_row, last.horizon_sigma_px, last.n_people, last.roll_deg,
                          last.roll_sigma_deg, last.n_outliers))
    return {"states": states, "moves": moves, "stretches": [s for s in stretches if s[3] >= 3], "K": K,
            "camera_height_m": height, "transformer": transformer, "calibrator": calibrator}


def _stretch(session: Session, req: dict) -> tuple[PedestrianCorrector, dict]:
    """The correction of the stretch of the session's boxes that time "at_s" (s) falls in (``_watched``; the stretch
    picked as ``homocal apply WATCH_DIR --at`` picks it: homocal.watch.folder.correction_at), made as homocal watch
    writes its corrections/<start_s>.json; with the _box_settings it used and "stretch": (start_s, at_s)."""
    at = _number(req, "at_s", 0, 0, 1e9)
    run = _watched(session, req)
    if not run["stretches"]:
        raise ValueError("at_s: no stretch of the boxes has 3 people yet")
    picked = correction_at([(s[0], None) for s in run["stretches"]], np.array([at]))[0]
    stretch = run["stretches"][int(picked)]
    corrector = _stretch_corrector(run, stretch, _camera_origin(req))
    corrector.lens_ = session.lens
    return corrector, {**_box_settings(session, req), "stretch": (stretch[0], at)}


def _stretch_corrector(run: dict, stretch: tuple, camera_origin) -> PedestrianCorrector:
    """One of ``_watched``'s stretches' correction (homocal.watch.calibrator.stretch_correction, as homocal watch
    writes it); ValueError with its refusal where homocal watch refuses it (its people mostly outliers)."""
    _, row, sigma, n, roll, roll_sigma, outliers = stretch
    return stretch_correction(run["transformer"], run["calibrator"], row, sigma, roll, roll_sigma, n, camera_origin,
                              outliers)


def _refusal(run: dict, stretch: tuple, camera_origin) -> str | None:
    """Why homocal watch refuses a stretch's correction (``_stretch_corrector``'s ValueError), None if it does not."""
    try:
        _stretch_corrector(run, stretch, camera_origin)
    except ValueError as e:
        return str(e)
    return None


def watch(session: Session, req: dict) -> dict:
    """The camera's horizon over time from the session's boxes (``_watched``: the request as a pedestrians fit's),
    for the page's time plot: "people" {"t": s, "row": px} (each person's implied horizon row), "estimate" {"t",
    "row", "sigma"} (the running estimate and its 1-sigma after each person), each at most MAX_PLOT_POINTS (every
    k-th beyond), "moves" (Move.to_dict), "stretches" [{"start_s", "horizon_row", "sigma_px", "n_people", "roll_deg",
    "roll_sigma_deg", "n_outliers", "refused" (why homocal watch refuses its correction, or None)}],
    "clicked_row" (the clicked mapping's horizon row) and "column" (the principal column all rows are at),
    undistorted pixels; "summary" in words."""
    run = _watched(session, req)
    people = [(s.t_s, row) for s in run["states"] for row in s.person_rows]
    estimate = [(s.t_s, s.horizon_row, s.horizon_sigma_px) for s in run["states"] if s.person_rows]
    if not people:
        raise ValueError(f"{session.boxes.name}: no person gave a horizon row (each needs {PERSON_BOXES} boxes off "
                         "the border, standing below the horizon)")

    def thinned(rows: list) -> dict:
        step = max(1, math.ceil(len(rows) / MAX_PLOT_POINTS))
        rows = rows[::step] + ([rows[-1]] if (len(rows) - 1) % step else [])
        return dict(zip(("t", "row", "sigma"), ([float_or_none(v) for v in col] for col in zip(*rows))))

    cx, origin = float(run["K"][0, 2]), _camera_origin(req)
    moves, stretches = run["moves"], run["stretches"]
    return {"people": thinned(people), "estimate": thinned(estimate), "moves": [m.to_dict() for m in moves],
            "stretches": [{"start_s": a, "horizon_row": b, "sigma_px": c, "n_people": n, "roll_deg": r,
                           "roll_sigma_deg": float_or_none(rs), "n_outliers": k,
                           "refused": _refusal(run, (a, b, c, n, r, rs, k), origin)}
                          for a, b, c, n, r, rs, k in stretches],
            "clicked_row": float(run["transformer"].horizon_row(cx)), "column": cx,
            "summary": f"{len(people)} people over {run['states'][-1].t_s:.1f} s: {len(moves)} move"
                       f"{'' if len(moves) == 1 else 's'} detected" + "".join(
                           f"; at {m.t_s:.1f} s the horizon row went {m.horizon_before:.1f} -> {m.horizon_after:.1f} px"
                           + (f", the roll {m.roll_before_deg:.2f} -> {m.roll_after_deg:.2f} degrees"
                              if run["calibrator"].estimate_roll else "") for m in moves)}


def _terms(req: dict) -> str:
    """The request's "terms": the distortion coefficients fitted, a key of TERMS (default DEFAULT_TERMS)."""
    terms = req.get("terms", DEFAULT_TERMS)
    if not isinstance(terms, str) or terms not in TERMS:
        raise ValueError(f"terms: expected one of {', '.join(TERMS)}, got {terms!r}")
    return terms


def _use_fitted_lens(session: Session, fit, files: dict, command: str) -> dict:
    """Use the lens the page fitted (``fit``: a LensFit or a BoardFit) from now on (use_lens: every click, box and
    overlay goes through it), with the files Save writes and the command that writes the same lens.json from them
    (Session.lens_fit); the lens and its lens.json "fit" for the page."""
    use_lens(session, fit.lens, session.out_dir / LENS_FILE)
    session.lens_fit = {"files": {session.out_dir / LENS_FILE: fit.to_json(), **files}, "command": command}
    return {"lens": fit.lens.to_dict(), "fit": fit.to_json()["fit"]}


def lens(session: Session, req: dict) -> dict:
    """Fit the lens that makes the request's "lines" (polylines [[u, v], ...] of the frame's pixels, along edges
    straight in the world) straight, as ``homocal lens --lines`` does (homocal.lens.lines: check_lines, fit_lines
    with "terms" (default DEFAULT_TERMS) and the focal length of "hfov_deg" (default DEFAULT_HFOV_DEG)), and use it
    for the session from now on (``_use_fitted_lens``). Answers the lens, the fit's diagnostics ("fit": lens.json's)
    and a summary."""
    terms = _terms(req)
    hfov = _number(req, "hfov_deg", DEFAULT_HFOV_DEG, 1, 179)
    try:
        size, lines = check_lines(list(session.frame_size), req.get("lines"))
        fit = fit_lines(size, lines, intrinsics(size, hfov), terms)
    except ValueError as e:
        raise ValueError(f"lines: {e}") from None
    lines_path, lens_path = session.out_dir / LINES_FILE, session.out_dir / LENS_FILE
    command = (f"homocal lens --lines {shlex.quote(str(lines_path))} -o {shlex.quote(str(lens_path))} "
               f"--hfov {hfov!r} --terms {terms}")
    lines_json = {"image_size": list(size), "lines": [line.tolist() for line in lines]}
    answer = _use_fitted_lens(session, fit, {lines_path: lines_json}, command)
    k1, k2, p1, p2, k3 = fit.lens.distortion
    return {**answer,
            "summary": f"{fit.lines} lines, {fit.points} points: straightness RMS {fit.rms_before_px:.2f} px before, "
                       f"{fit.rms_after_px:.2f} px after; k1 {k1:.4f} +- {fit.sigma[0]:.4f}, k2 {k2:.4f}, f "
                       f"{fit.lens.K[0, 0]:.1f} px; the frame's corner moves {fit.corner_displacement_px:.1f} px"}


def _photos(req: dict) -> list[tuple[str, bytes]]:
    """The request's "photos" [{"name": a file name, "data": its bytes in base64}], sorted by name (the order of
    the command's glob); the first MAX_FRAMES + 1 (calibrate_board refuses more, as the command reads its glob).
    ValueError naming the bad one: not a list, a name that is a path or starts with a dot (a glob's * skips it),
    a name given twice, data that is not base64."""
    photos = req.get("photos")
    if not isinstance(photos, list):
        raise ValueError('photos: expected a list of {"name": file name, "data": base64}')
    out = {}
    for i, photo in enumerate(photos[:MAX_FRAMES + 1]):
        name = photo.get("name") if isinstance(photo, dict) else None
        if (not isinstance(name, str) or not name.isprintable() or name != Path(name).name or name.startswith(".")
                or "\\" in name or len(name.encode()) > 255):
            raise ValueError(f"photos[{i}]: expected a file name (no folder, not starting with a dot), got {name!r}")
        if name in out:
            raise ValueError(f"photos[{i}]: {name} is given twice")
        try:
            out[name] = base64.b64decode(photo.get("data"), validate=True)
        except (TypeError, ValueError):
            raise ValueError(f"photos[{i}]: {name}'s data is not base64") from None
    return sorted(out.items())


def checkerboard(session: Session, req: dict) -> dict:
    """Calibrate the lens from the request's checkerboard "photos" (``_photos``; of the frame's size) of a board of
    "pattern" ("COLSxROWS" inner corners) with squares of "square_m" metres, as ``homocal lens --checkerboard`` does
    (homocal.lens.checkerboard: parse_pattern, calibrate_board with "terms" (default DEFAULT_TERMS) and its bounds),
    and use it for the session from now on (``_use_fitted_lens``). Save writes the photographs into BOARD_DIR for
    the command. Answers the lens, the fit's diagnostics (lens.json's "fit", photographs by name) and a summary."""
    terms = _terms(req)
    try:
        pattern = parse_pattern(req.get("pattern"))
    except ValueError as e:
        raise ValueError(f"pattern: {e}") from None
    square = _number(req, "square_m", None, 0, MAX_SQUARE_M, low_open=True)
    photos = _photos(req)
    with tempfile.TemporaryDirectory() as tmp:
        for name, data in photos:
            (Path(tmp) / name).write_bytes(data)
        try:
            fit = calibrate_board([Path(tmp) / name for name, _ in photos], pattern, square, terms, session.frame_size)
        except ValueError as e:
            raise ValueError("photos: " + str(e).replace(tmp + os.sep, "")) from None
    folder, lens_path = session.out_dir / BOARD_DIR, session.out_dir / LENS_FILE
    saved = replace(fit, frames=[str(folder / Path(p).name) for p in fit.frames],
                    missing=[str(folder / Path(p).name) for p in fit.missing])  # as the command's glob names them
    command = (f"homocal lens --checkerboard {shlex.quote(os.path.join(glob.escape(str(folder)), '*'))} --pattern "
               f"{pattern[0]}x{pattern[1]} --square-m {square!r} --terms {terms} -o {shlex.quote(str(lens_path))}")
    answer = _use_fitted_lens(session, saved, {folder / name: data for name, data in photos}, command)
    found, missing = ([Path(p).name for p in paths] for paths in (fit.frames, fit.missing))
    k1, k2, p1, p2, k3 = fit.lens.distortion
    return {**answer, "fit": {**answer["fit"], "frames": found, "missing": missing},
            "summary": f"board found in {len(found)} of {len(photos)} photographs"
                       + (f" (not in {', '.join(missing)})" if missing else "")
                       + f", RMS reprojection error {fit.rms_px:.3f} px; k1 {k1:.4f}, k2 {k2:.4f}, f {fit.lens.K[0, 0]:.1f} px"}


def _lens_files(session: Session) -> tuple[dict, dict]:
    """The files of the lens fitted on the page (Session.lens_fit; none otherwise) with their contents, and the
    ``homocal lens`` command that writes the same lens.json from them."""
    if session.lens_fit is None:
        return {}, {}
    return session.lens_fit["files"], {"lens_command": session.lens_fit["command"]}


def _board_leftovers(session: Session, paths: list) -> list:
    """The files in BOARD_DIR besides ``paths`` (the command's glob would read them too): those this server wrote and
    that are still what it wrote, which Save removes; ``Refused`` for the folder being a link or holding another."""
    folder = session.out_dir / BOARD_DIR
    if folder not in {p.parent for p in paths} or not (folder.is_dir() or folder.is_symlink()):
        return []
    if folder.is_symlink():
        raise Refused(f"{BOARD_DIR} in {session.out_dir}: a symbolic link, which Save never writes into (remove it, or "
                      "save to another folder)")
    others = [p for p in folder.iterdir() if p not in paths]
    foreign = [p.name for p in others if _identity(p) != session.written.get(p)]
    if foreign:
        raise Refused(f"{', '.join(sorted(foreign))} in {folder}: not a photograph of this calibration, which "
                      "the command's glob would read (remove it, or save to another folder)")
    return others


def _write_lens_files(session: Session, files: dict, leftovers: list) -> None:
    """Write the lens's files (JSON objects or bytes), then remove the leftovers (``_board_leftovers``)."""
    for path, data in files.items():
        if isinstance(data, bytes):
            write_atomic(path, lambda tmp, data=data: tmp.write_bytes(data))
        else:
            write_json_atomic(path, data)
    for path in leftovers:
        path.unlink()
        session.written.pop(path, None)


def _check_replace(session: Session, paths: list, req: dict) -> None:
    """Refuse to replace a symbolic link (``Refused``), or without "overwrite": true a file this server did not
    write (or that was replaced since: FileExistsError, the page asks)."""
    links = [p.name for p in paths if p.is_symlink()]
    if links:
        raise Refused(f"{', '.join(links)} in {session.out_dir}: a symbolic link, which Save never replaces "
                      "(remove it, or save to another folder)")
    foreign = [p for p in paths if p.exists() and _identity(p) != session.written.get(p)]
    if foreign and req.get("overwrite") is not True:
        raise FileExistsError(f"{', '.join(p.name for p in foreign)} already in {session.out_dir} "
                              "(not written by this homocal ui)")


def save_lens(session: Session, req: dict) -> dict:
    """Write the lens fitted on the page and what it was fitted from (LENS_FILE with LINES_FILE, or with the
    photographs in BOARD_DIR: the files of ``homocal lens``) to the session's folder, asking before replacing a
    file this server did not write (as save); answer the files and the command that writes the same lens.json."""
    contents, command = _lens_files(session)
    if not contents:
        raise ValueError("lens: fit it from lines, or calibrate it from a checkerboard, first")
    _check_replace(session, list(contents), req)
    _write_lens_files(session, contents, _board_leftovers(session, list(contents)))
    session.written.update({p: _identity(p) for p in contents})
    return {"written": [str(p) for p in contents], "command": command["lens_command"]}


def locate(session: Session, req: dict) -> dict:
    """The ground position of one image point with its 1-sigma error ellipse ("errorbars", the clicked
    trapezoid's) and, given a fitted "correction", its corrected position with the correction's own error
    ellipse ("corrected_errorbars": Corrector.ground_uncertainty; None beyond the corrected horizon)."""
    transformer = _complete_transformer(session, req)
    point = undistorted(session, _points([req.get("point")], "point", 2), "point")
    ground = transformer.transform_points(point)[0]
    if not np.isfinite(ground).all():
        raise ValueError(f"the point {point[0].tolist()} is on or above the horizon: it has no ground position")
    origin = _camera_origin(req)
    out = {"ground": ground.tolist(), "distance": float(np.hypot(*(ground - origin))), "corrected": None,
           "corrected_errorbars": None}
    if req.get("correction") is not None:
        if not isinstance(req["correction"], dict):
            raise ValueError("correction: expected the object /api/fit answered with")
        corrector = Corrector.from_dict(req["correction"], "correction")
        corrected = corrector.transform_points(point)[0]
        if np.isfinite(corrected).all():
            out["corrected"] = corrected.tolist()
            out["corrected_errorbars"] = error_bars(session, corrector.mapping, point, origin, None, **_sigmas(req),
                                                    uncertainty=corrector.ground_uncertainty,
                                                    transform=corrector.transform_points)
    out["errorbars"] = error_bars(session, transformer, point, origin, None, **_sigmas(req))
    return out


def save(session: Session, req: dict) -> dict:
    """Write trapezoid.json, reference_points.csv and correction.json (the formats of ``homocal fit --help``) to
    the session's folder, and for a fit from boxes camera_intrinsics.json (CAMERA_FILE: the image size and K the
    fit used, as --camera-json); answer the files and the ``homocal fit`` command that gives the same correction
    from them. A file this server did not write (or that was replaced since) is overwritten only with
    "overwrite": true (the page asks first; otherwise FileExistsError); a symbolic link is never replaced
    (``Refused``)."""
    corrector, _, _, _, box_settings = _fitted(session, req)
    points = _points(req.get("points"), "points", 4, MAX_REFERENCE_POINTS)  # as clicked: the frame's pixels
    method = method_of(corrector)
    image, map_px = trapezoid(req)
    names = (TRAPEZOID_FILE, POINTS_FILE, CORRECTION_FILE) + ((CAMERA_FILE,) if method.evidence == "boxes" else ())
    paths = [session.out_dir / name for name in names]
    lens_files, lens_command = _lens_files(session)  # the lens the flags name, when fitted on the page
    _check_replace(session, paths + list(lens_files), req)
    leftovers = _board_leftovers(session, list(lens_files))
    site = {"scale_px_per_m": session.site_map.scale_px_per_m, "origin_px": list(session.site_map.origin_px)}
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["u", "v", "x", "y"])
    writer.writerows([[repr(float(x)) for x in row] for row in points])
    params = corrector.get_params()
    flags = [f"--{k} {params[k]!r}" for k in ("seed", "threshold") if k in method.settings]
    if session.lens is not None:
        flags.append(f"--camera-json {shlex.quote(str(session.camera_file))}")
    if method.evidence == "boxes":
        (width, height), K = box_settings["image_size"], box_settings["K"]
        camera = {"width": width, "height": height, **({} if K is None else {"K": K.tolist()}),
                  **({} if session.lens is None else {"distortion": session.lens.distortion.tolist()})}
        detector, camera_height = box_settings["detector"], box_settings["camera_height_m"]
        given = {"--detector": None if detector is None else shlex.quote(detector),
                 PEDESTRIAN_SETTINGS["camera_height_m"].flag: None if camera_height is None else repr(camera_height)}
        flags = [f"--boxes {shlex.quote(str(session.boxes))}", *(f"{k} {v}" for k, v in given.items() if v is not None),
                 f"--camera-json {shlex.quote(str(paths[3]))}",
                 *(f"{PEDESTRIAN_SETTINGS[k].flag} {_flag_text(params[k])}" for k in method.settings)]
    stretch = box_settings.get("stretch") if box_settings else None
    if stretch is not None:  # homocal watch writes it, as the stretch's corrections/<start_s>.json
        flags = [f for f in flags if not f.startswith(NOT_WATCHS)]
        command = (f"homocal watch --trapezoid {shlex.quote(str(paths[0]))} --fps {session.fps!r} "
                   f"--camera-origin={','.join(repr(float(x)) for x in corrector.camera_origin_)} -o WATCH_DIR "
                   + " ".join(flags) + f" (its corrections/{stretch[0]:.2f}.json; homocal apply WATCH_DIR --at "
                   f"{stretch[1]!r} maps with it)")
    size = {} if session.lens is None else {"image_size": list(session.frame_size)}  # checked against the lens's
    write_json_atomic(paths[0], {"image": image.tolist(), "map": map_px.tolist(), "site_map": site, **size})
    write_text_atomic(paths[1], buffer.getvalue())
    corrector.save(paths[2])
    if method.evidence == "boxes":
        write_json_atomic(paths[3], camera)
    _write_lens_files(session, lens_files, leftovers)
    paths += list(lens_files)
    session.written.update({p: _identity(p) for p in paths})
    points_flag = f" --points {shlex.quote(str(paths[1]))}" if len(points) else ""
    if stretch is not None:
        return {"written": [str(p) for p in paths], "method": method.name, **lens_command, "command": command}
    return {"written": [str(p) for p in paths], "method": method.name, **lens_command,
            "command": f"homocal fit --trapezoid {shlex.quote(str(paths[0]))}{points_flag} --method {method.name} "
                       f"-o CORRECTION.json --camera-origin={','.join(repr(float(x)) for x in corrector.camera_origin_)}"
                       + "".join(" " + f for f in flags)}


def _identity(path) -> tuple[int, int, int, int] | None:
    """(device, inode, size, modification time ns) of the file at ``path`` itself (a link is not followed), None
    if there is none: a file replaced since differs in one of them, even if its inode number was reused."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return None
    return st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns


def load(session: Session, req: dict) -> dict:
    """Read back what Save wrote in the session's folder: the trapezoid (map corners converted to this
    session's site map), the reference points and, if present, the correction's method and settings."""
    folder = session.out_dir
    data = read_json(folder / TRAPEZOID_FILE)
    try:
        image = validate_quad(data["image"], f"{TRAPEZOID_FILE} image")
        map_px = validate_quad(data["map"], f"{TRAPEZOID_FILE} map")
        site = None if data.get("site_map") is None else SiteMap.from_dict(data["site_map"], f"{TRAPEZOID_FILE} site_map")
    except KeyError as e:
        raise ValueError(f"{folder / TRAPEZOID_FILE}: missing key {e}") from None
    if site != session.site_map:  # metres (no site_map) or another map's pixels: to this map's pixels
        map_px = session.site_map.to_pixels(map_px if site is None else site.to_metres(map_px))
    out = {"trapezoid": {"image": image.tolist(), "map": map_px.tolist()},
           "points": [], "fit": None, "loaded": [TRAPEZOID_FILE]}
    if (folder / POINTS_FILE).is_file():
        _, _, cols, _ = read_points_csv(folder / POINTS_FILE, ("u", "v", "x", "y"), finite=True,
                                      most=MAX_REFERENCE_POINTS)
        out["points"] = np.column_stack([cols[c] for c in ("u", "v", "x", "y")]).tolist()
        out["loaded"].append(POINTS_FILE)
    if (folder / CORRECTION_FILE).is_file():
        corrector = load_corrector(folder / CORRECTION_FILE)
        params = corrector.get_params()
        out["fit"] = {"method": method_of(corrector).name,
                      "camera_origin": corrector.camera_origin_.tolist(),
                      "seed": params.get("seed", 0), "threshold": params.get("threshold", DEFAULT_THRESHOLD),
                      "error_before": float_or_none(corrector.error_before_),
                      "error_after": float_or_none(corrector.error_after_)}
        out["loaded"].append(CORRECTION_FILE)
    return out


ENDPOINTS = {"view": view, "fit": fit, "watch": watch, "lens": lens, "checkerboard": checkerboard, "save_lens": save_lens,
             "locate": locate, "save": save, "load": load}

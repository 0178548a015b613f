"""The page's JSON API: each endpoint takes the request's JSON object and returns the response's.

Bad input raises ValueError (the server answers 400 with its message) or FileExistsError (409). Every
computation goes through the library: the trapezoid's ViewTransformer is built as ``homocal fit`` builds it
from the saved trapezoid.json, and the correction is fitted with ``homocal fit``'s METHODS.
"""
from __future__ import annotations

import argparse
import csv
import io
import math
import warnings

import numpy as np

from homocal.correctors import cli as corrector_cli
from homocal.correctors.base import Corrector, load_corrector
from homocal.correctors.hybrid import DEFAULT_THRESHOLD, HybridCorrector
from homocal.files import read_json, write_json_atomic, write_text_atomic
from homocal.geometry import SiteMap, ViewTransformer, signed_area, validate_quad
from homocal.ui import overlay
from homocal.ui.errorbars import error_bars
from homocal.ui.session import Session

TRAPEZOID_FILE, POINTS_FILE, CORRECTION_FILE = "trapezoid.json", "reference_points.csv", "correction.json"


# ---- request fields -------------------------------------------------------------------------------
def _number(req: dict, key: str, default: float | None = None, positive: bool = False) -> float:
    value = req.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{key}: expected a finite number, got {value!r}")
    if positive and value < 0:
        raise ValueError(f"{key}: expected a number >= 0, got {value!r}")
    return float(value)


def _points(value, name: str, width: int, most: int | None = None) -> np.ndarray:
    """A list of points of ``width`` finite numbers each, as (N, width) float64."""
    if not isinstance(value, list) or (most is not None and len(value) > most):
        raise ValueError(f"{name}: expected a list of " + (f"at most {most} " if most else "") + "points")
    for i, p in enumerate(value):
        if (not isinstance(p, list) or len(p) != width
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in p)):
            raise ValueError(f"{name}[{i}]: expected {width} finite numbers, got {p!r}")
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
    return ViewTransformer(validate_quad(image, "image"), session.site_map.to_metres(validate_quad(map_px, "map")))


def _complete_transformer(session: Session, req: dict) -> ViewTransformer:
    transformer = transformer_of(session, *trapezoid(req))
    if transformer is None:
        raise ValueError("click all 4 image corners and all 4 map corners first")
    return transformer


def _fitted(session: Session, req: dict) -> tuple[Corrector, ViewTransformer, np.ndarray, argparse.Namespace, list]:
    """Fit the request's method as ``homocal fit`` does; return it with the transformer, the points (N, 4) u,v,x,y,
    homocal fit's arguments and the library's warnings (texts)."""
    transformer = _complete_transformer(session, req)
    points = _points(req.get("points"), "points", 4)
    args = fit_arguments(req)
    corrector = corrector_cli.METHODS[args.method](args)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        corrector.fit(transformer, points[:, :2], points[:, 2:], _camera_origin(req))
    return corrector, transformer, points, args, [str(w.message) for w in caught]


def fit_arguments(req: dict) -> argparse.Namespace:
    """``homocal fit``'s parsed arguments for the request's method, seed and threshold (its defaults otherwise)."""
    method = req.get("method")
    if method not in corrector_cli.METHODS:
        raise ValueError(f"method: expected one of {', '.join(corrector_cli.METHODS)}, got {method!r}")
    seed = _number(req, "seed", 0.0, positive=True)
    if seed != int(seed):
        raise ValueError(f"seed: expected an integer, got {seed!r}")
    parser = argparse.ArgumentParser()
    corrector_cli.add_parser(parser.add_subparsers())
    return parser.parse_args(["fit", "--trapezoid", TRAPEZOID_FILE, "--points", POINTS_FILE, "-o", CORRECTION_FILE,
                              "--method", method, "--seed", str(int(seed)),
                              "--threshold", repr(_number(req, "threshold", DEFAULT_THRESHOLD))])


def _sigmas(req: dict) -> dict:
    return {key: _number(req, key, default, positive=True)
            for key, default in (("click_sigma_px", 1.5), ("point_sigma_px", 1.0), ("map_sigma_px", 0.0))}


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
    field = overlay.sample_mapping(transformer.transform_points, transformer, w, h)
    return {
        "complete": True,
        "horizon": overlay.horizon_segment(transformer, w, h),
        "grid": overlay.ground_grid(field, origin),
        "footprint": overlay.footprint(transformer, w, h, session.site_map, origin, max_range),
        "errorbars": None if req.get("errorbars") is False else error_bars(
            session, transformer, overlay.grid_nodes(field, transformer), origin,
            _number(req, "tolerance_m", 0.5, positive=True), **_sigmas(req)),
    }


def fit(session: Session, req: dict) -> dict:
    """Fit the chosen method on the reference points; errors before/after, per-point residuals, the
    corrected grid and the correction's JSON (what Save writes)."""
    corrector, transformer, points, args, caught = _fitted(session, req)
    mapped = transformer.transform_points(points[:, :2])
    corrected = corrector.transform_points(points[:, :2])
    w, h = session.frame_size
    tolerance = _number(req, "tolerance_m", 0.5, positive=True)
    trust = error_bars(session, corrector_cli._mapping(corrector), np.zeros((0, 2)), _camera_origin(req), tolerance,
                       **_sigmas(req))["trustworthy_range_m"]
    trust_note = (f" With its mapping the 1-sigma error stays under {tolerance:g} m out to "
                  + ("any range" if trust is None else f"{trust:.1f} m") + " straight ahead.")
    return {
        "summary": f"{args.method}: {corrector_cli._quality(corrector)}."
                   f"{corrector_cli._method_note(corrector)}{trust_note}",
        "warnings": caught,
        "error_before": corrector.error_before_,
        "error_after": corrector.error_after_,
        "mapped": mapped.tolist(),
        "corrected": corrected.tolist(),
        "residual_before": np.hypot(*(mapped - points[:, 2:]).T).tolist(),
        "residual_after": np.hypot(*(corrected - points[:, 2:]).T).tolist(),
        "corrected_grid": overlay.ground_grid(overlay.sample_mapping(corrector.transform_points, transformer, w, h),
                                              _camera_origin(req)),
        "correction": corrector.to_dict(),
    }


def locate(session: Session, req: dict) -> dict:
    """The ground position of one image point (plain and, given a fitted "correction", corrected) with its
    1-sigma error ellipse."""
    transformer = _complete_transformer(session, req)
    point = _points([req.get("point")], "point", 2)
    ground = transformer.transform_points(point)[0]
    if not np.isfinite(ground).all():
        raise ValueError(f"the point {point[0].tolist()} is on or above the horizon: it has no ground position")
    origin = _camera_origin(req)
    out = {"ground": ground.tolist(), "distance": float(np.hypot(*(ground - origin))), "corrected": None}
    if req.get("correction") is not None:
        corrector = Corrector.from_dict(req["correction"], "correction")
        corrected = corrector.transform_points(point)[0]
        out["corrected"] = corrected.tolist() if np.isfinite(corrected).all() else None
    out["errorbars"] = error_bars(session, transformer, point, origin, None, **_sigmas(req))
    return out


def save(session: Session, req: dict) -> dict:
    """Write trapezoid.json, reference_points.csv and correction.json (the formats of ``homocal fit --help``)
    to the session's folder. A file this server did not write is overwritten only with "overwrite": true
    (the page asks first); otherwise FileExistsError."""
    corrector, _, points, args, _ = _fitted(session, req)
    image, map_px = trapezoid(req)
    paths = [session.out_dir / name for name in (TRAPEZOID_FILE, POINTS_FILE, CORRECTION_FILE)]
    foreign = [p for p in paths if p.exists() and p not in session.written]
    if foreign and req.get("overwrite") is not True:
        raise FileExistsError(f"{', '.join(p.name for p in foreign)} already in {session.out_dir} "
                              "(not written by this homocal ui)")
    site = {"scale_px_per_m": session.site_map.scale_px_per_m, "origin_px": list(session.site_map.origin_px)}
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["u", "v", "x", "y"])
    writer.writerows([[repr(float(x)) for x in row] for row in points])
    write_json_atomic(paths[0], {"image": image.tolist(), "map": map_px.tolist(), "site_map": site})
    write_text_atomic(paths[1], buffer.getvalue())
    corrector.save(paths[2])
    session.written.update(paths)
    return {"written": [str(p) for p in paths], "method": args.method,
            "command": f"homocal fit --trapezoid {paths[0]} --points {paths[1]} --method {args.method} "
                       f"-o CORRECTION.json --camera-origin={','.join(repr(float(x)) for x in corrector.camera_origin_)}"
                       + (f" --seed {args.seed}" if "seed" in corrector.get_params() else "")
                       + (f" --threshold {args.threshold!r}" if "threshold" in corrector.get_params() else "")}


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
        _, _, cols, _ = corrector_cli.read_points_csv(folder / POINTS_FILE, ("u", "v", "x", "y"), finite=True)
        out["points"] = np.column_stack([cols[c] for c in ("u", "v", "x", "y")]).tolist()
        out["loaded"].append(POINTS_FILE)
    if (folder / CORRECTION_FILE).is_file():
        corrector = load_corrector(folder / CORRECTION_FILE)
        params = corrector.get_params()
        out["fit"] = {"method": "hybrid" if isinstance(corrector, HybridCorrector) else corrector_cli._label(corrector),
                      "camera_origin": corrector.camera_origin_.tolist(),
                      "seed": params.get("seed", 0), "threshold": params.get("threshold", DEFAULT_THRESHOLD),
                      "error_before": corrector.error_before_, "error_after": corrector.error_after_}
        out["loaded"].append(CORRECTION_FILE)
    return out


ENDPOINTS = {"view": view, "fit": fit, "locate": locate, "save": save, "load": load}

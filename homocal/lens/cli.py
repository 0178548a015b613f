"""``homocal lens``: estimate a camera's lens (K and OpenCV's distortion) and write lens.json, which every
``--camera-json`` reads."""
from __future__ import annotations

import argparse
import glob
from pathlib import Path

from homocal.arguments import number
from homocal.files import check_output_file, json_format, read_json, write_json_atomic
from homocal.lens.checkerboard import MAX_FRAMES, MAX_SEARCH_PIXELS, MAX_SQUARE_M, calibrate_board, parse_pattern
from homocal.lens.edges import fit_frame
from homocal.lens.lines import DEFAULT_HFOV_DEG, DEFAULT_TERMS, TERMS, fit_lines, intrinsics, read_lines_file

EPILOG = f"""\
LINES.json: {{"image_size": [W, H], "lines": [[[u, v], ...], ...]}}: polylines of image pixels (3 or more points
each) along things that are straight in the world: kerbs, lane markings, poles, building edges. Click them
along their whole length, out to the frame's edges, where the lens bends them most; lines through the image
centre say nothing of the distortion. The principal point is taken at the image centre and the focal length
from --focal, else --hfov (default {DEFAULT_HFOV_DEG:g} degrees): straight lines fix the distortion in pixels, not
the focal length, so the undistorted pixels do not depend on it (the coefficients scale with it).
--checkerboard: photographs of a flat board with --pattern COLSxROWS inner corners, --square-m apart, at
several angles and over the whole frame (at least 3 where the board is found, at most {MAX_FRAMES}, and at most
{MAX_SEARCH_PIXELS:,} pixels in all: the board search's time).
--frame: one image; straight edges are found in it (no click) and fitted as lines.
lens.json: {{"K": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], "distortion": [k1, k2, p1, p2, k3], "image_size": [W, H],
"fit": {{...}}}} (OpenCV's model and order; "fit" holds how it was estimated and how well)."""


def _pattern(text: str) -> tuple[int, int]:
    """argparse type: COLSxROWS inner corners (parse_pattern)."""
    try:
        return parse_pattern(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Register ``lens``."""
    lens = subparsers.add_parser(
        "lens", help="estimate the lens distortion (lines, a checkerboard or a frame) and write lens.json",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Estimate a camera's lens distortion from clicked straight lines, checkerboard photographs or "
                    "the straight edges of one frame, and write lens.json.")
    source = lens.add_mutually_exclusive_group(required=True)
    source.add_argument("--lines", type=Path, metavar="LINES.json", help="polylines straight in the world (see below)")
    source.add_argument("--checkerboard", metavar="GLOB", help="checkerboard photographs, a quoted glob ('frames/*.png')")
    source.add_argument("--frame", type=Path, metavar="FRAME.png", help="one frame whose straight edges are found")
    lens.add_argument("-o", "--out", required=True, type=Path, metavar="LENS.json", help="the lens file to write")
    focal = lens.add_mutually_exclusive_group()
    focal.add_argument("--hfov", type=number(float, 1, 179), metavar="DEG",
                       help=f"--lines, --frame: horizontal field of view, degrees (default {DEFAULT_HFOV_DEG:g})")
    focal.add_argument("--focal", type=number(float, 1, 1e6), metavar="PX", help="--lines, --frame: focal length, pixels")
    lens.add_argument("--terms", choices=TERMS, default=DEFAULT_TERMS, metavar="TERMS",
                      help=f"the distortion coefficients fitted, the others 0: {' or '.join(TERMS)} (default %(default)s)")
    lens.add_argument("--pattern", type=_pattern, metavar="COLSxROWS", help="--checkerboard: inner corners, e.g. 9x6")
    lens.add_argument("--square-m", type=number(float, 0, MAX_SQUARE_M, low_open=True), metavar="M",
                      help="--checkerboard: side of one square, metres")
    lens.set_defaults(handler=handle_lens)


def _ours(path: Path) -> bool:
    """Whether path is a lens.json this command wrote (its "fit" names a method)."""
    try:
        return json_format(path) is None and isinstance(read_json(path).get("fit", {}).get("method"), str)
    except (OSError, ValueError, AttributeError):
        return False


def _naming(path: Path, fit, *args):
    """fit(*args), its ValueError naming the file the lines come from."""
    try:
        return fit(*args)
    except ValueError as e:
        raise ValueError(str(e) if str(e).startswith(f"{path}:") else f"{path}: {e}") from None


def handle_lens(args: argparse.Namespace) -> int:
    board_flags = [flag for flag, value in (("--pattern", args.pattern), ("--square-m", args.square_m)) if value is not None]
    if args.checkerboard is None and board_flags:
        raise ValueError(f"{board_flags[0]}: only with --checkerboard")
    if args.checkerboard is not None:
        missing = [flag for flag in ("--pattern", "--square-m") if flag not in board_flags]
        if missing:
            raise ValueError(f"{missing[0]}: required with --checkerboard")
        if args.hfov is not None or args.focal is not None:
            raise ValueError(f"{'--hfov' if args.hfov is not None else '--focal'}: not with --checkerboard (the board "
                             "fixes the focal length)")
    check_output_file(args.out, _ours, "lens.json of homocal lens")
    if args.checkerboard is not None:
        paths = sorted(Path(p) for p in glob.glob(args.checkerboard))[:MAX_FRAMES + 1]
        if not paths:
            raise ValueError(f"--checkerboard: {args.checkerboard!r} matches no file")
        fit = calibrate_board(paths, args.pattern, args.square_m, args.terms)
        summary = (f"board found in {len(fit.frames)} of {len(paths)} frames, RMS reprojection error "
                   f"{fit.rms_px:.3f} px")
    else:
        if args.lines is not None:
            size, lines = read_lines_file(args.lines)
            fit = _naming(args.lines, fit_lines, size, lines, intrinsics(size, args.hfov, args.focal), args.terms)
        else:
            fit = _naming(args.frame, fit_frame, args.frame, args.terms, args.hfov, args.focal)
        summary = (f"{fit.lines} lines, {fit.points} points: straightness RMS {fit.rms_before_px:.2f} px before, "
                   f"{fit.rms_after_px:.2f} px after; the frame's corner moves {fit.corner_displacement_px:.1f} px")
    write_json_atomic(args.out, fit.to_json())
    k1, k2, p1, p2, k3 = fit.lens.distortion
    print(f"homocal lens: {summary}; k1 {k1:.4f}, k2 {k2:.4f}, p1 {p1:.5f}, p2 {p2:.5f}, k3 {k3:.4f}, "
          f"f {fit.lens.K[0, 0]:.1f} px; written to {args.out}")
    return 0

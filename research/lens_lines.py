"""How well `homocal lens --lines` recovers a wide lens from clicked straight ground lines, and what it leaves in
the ground mapping (docs/real-camera.md, "A lens without a checkerboard").

Run: python research/lens_lines.py [--camera-json CAMERA.json] [--seeds N] [--noise-px PX] [--terms T]

The camera is CAMERA.json's (K, R, t, distortion, width, height: a simgen dataset's), else the stand-in of the
card's camera: 1280x720, hfov 95, 4 m high, 15 degrees down, roll 1 degree, yaw 8 degrees, k1 = -0.2, k2 = 0.04.
The street crosses the view at STREET_DEG to the optical axis: its two kerbs and its lane lines (LANES, metres
from the centre line, from 2 m to 80 m along it) and three stop lines across it are projected through the lens,
and CLICKS points spread along each visible part are clicked with Gaussian noise of --noise-px on each coordinate.
For each seed: `homocal lens --lines` on them (with the true focal length, --focal), then
  - k1 and the corner displacement (how far the lens moves the frame's corner pixel) against the true ones;
  - the ground mapping of a trapezoid (TRAPEZOID, metres; its corners clicked with the same noise, then
    undistorted) at test points 5-50 m from the camera (every metre of range, every 5 degrees of bearing, those
    in the frame; their exact distorted pixels undistorted): the median relative range error with the true
    lens and with the estimated one, and their ratio.
Prints one row per seed and the mean and range of each column.
"""
from __future__ import annotations

import argparse
import json
import math
import tempfile
from pathlib import Path

import cv2
import numpy as np

from homocal.cli import main as homocal_main
from homocal.files import read_json
from homocal.geometry import PinholeCamera, ViewTransformer
from homocal.geometry.lens import Lens

STREET_DEG = 25.0  # the street's direction, degrees from the optical axis's ground direction
LANES = (-7.0, -5.25, -1.75, 1.75, 5.25, 7.0)  # kerbs at +/-7 m, lane lines, metres from the street's centre line
STOP_LINES = (8.0, 14.0, 20.0)  # lines across the street, metres along it from the camera's foot
CLICKS = 12  # points clicked along each visible line
TRAPEZOID = np.array([[-3.0, 25.0], [3.0, 25.0], [3.0, 8.0], [-3.0, 8.0]])  # TL, TR, BR, BL, metres


def stand_in() -> tuple[np.ndarray, np.ndarray, np.ndarray, Lens]:
    """R (3, 3), t (3,), rvec (3,), Lens of the card's camera with roll 1 deg, yaw 8 deg, k1 -0.2, k2 0.04."""
    cam = PinholeCamera()
    rot = lambda deg: cv2.Rodrigues(np.array([0.0, 0.0, math.radians(deg)]))[0]
    R = rot(1.0) @ cam.R @ rot(-8.0)  # roll about the optical axis after the tilt, yaw about the vertical before it
    return R, -R @ cam.position, Lens(cam.K, [-0.2, 0.04, 0.0, 0.0, 0.0], (cam.width, cam.height))


def from_camera_json(path: Path) -> tuple[np.ndarray, np.ndarray, Lens]:
    c = read_json(path)
    return np.array(c["R"]), np.array(c["t"]), Lens(c["K"], c["distortion"], (c["width"], c["height"]))


def project(X: np.ndarray, R: np.ndarray, t: np.ndarray, lens: Lens) -> np.ndarray:
    """World points (N, 3) -> distorted pixels (N, 2) (cv2.projectPoints with the lens's K and distortion)."""
    p, _ = cv2.projectPoints(X, cv2.Rodrigues(R)[0], t, lens.K, lens.distortion)
    return p.reshape(-1, 2)


def in_frame(p: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    return (p[:, 0] >= 0) & (p[:, 0] <= size[0] - 1) & (p[:, 1] >= 0) & (p[:, 1] <= size[1] - 1)


def street_lines(R, t, lens: Lens) -> list[np.ndarray]:
    """The visible parts of the street's lines, each as dense distorted pixels (M, 2) ordered along it."""
    a = math.radians(STREET_DEG)
    along, across = np.array([math.sin(a), math.cos(a), 0.0]), np.array([math.cos(a), -math.sin(a), 0.0])
    s = np.linspace(-80.0, 80.0, 4001)
    worlds = [off * across + s[:, None] * along for off in LANES]
    worlds += [d * along + np.linspace(-7.0, 7.0, 701)[:, None] * across for d in STOP_LINES]
    out = []
    for X in worlds:
        X = X[(R @ X.T + t[:, None])[2] > 0.5]  # in front of the camera
        p = project(X, R, t, lens)
        p = p[in_frame(p, lens.image_size)]
        if len(p) >= CLICKS and np.linalg.norm(p[-1] - p[0]) > 100:
            out.append(p)
    return out


def range_error(lens: Lens, corners_px: np.ndarray, test_px: np.ndarray, test_xy: np.ndarray) -> float:
    """Median |mapped range - true range| / true range of the test points through the trapezoid, both undistorted
    with ``lens``."""
    vt = ViewTransformer(lens.undistort_points(corners_px), TRAPEZOID)
    mapped = vt.transform_points(lens.undistort_points(test_px))
    return float(np.nanmedian(np.abs(np.hypot(*mapped.T) - np.hypot(*test_xy.T)) / np.hypot(*test_xy.T)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--camera-json", type=Path)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--noise-px", type=float, default=1.0)
    parser.add_argument("--terms", default="k1,k2")
    args = parser.parse_args()
    R, t, true = from_camera_json(args.camera_json) if args.camera_json else stand_in()
    corner = np.zeros((1, 2))
    true_corner = float(np.linalg.norm(true.undistort_points(corner) - corner))
    lines = street_lines(R, t, true)
    ranges, bearings = np.meshgrid(np.arange(5.0, 50.5), np.radians(np.arange(-60.0, 61.0, 5.0)))
    test_xy = np.column_stack([(ranges * np.sin(bearings)).ravel(), (ranges * np.cos(bearings)).ravel()])
    test_px = project(np.column_stack([test_xy, np.zeros(len(test_xy))]), R, t, true)
    keep = in_frame(test_px, true.image_size)
    test_xy, test_px = test_xy[keep], test_px[keep]
    exact_corners = project(np.column_stack([TRAPEZOID, np.zeros(4)]), R, t, true)
    print(f"camera: {'%s' % args.camera_json if args.camera_json else 'stand-in'}; true k1 {true.distortion[0]:.4f}, "
          f"corner displacement {true_corner:.1f} px; {len(lines)} lines, {len(test_xy)} test points; "
          f"--noise-px {args.noise_px:g}, --terms {args.terms}")
    print("| seed | k1 | k1 error % | corner px | corner error % | RMS after px | range err known % | "
          "range err estimated % | ratio | exact trapezoid: estimated % |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            rng = np.random.default_rng(seed)
            clicks = []
            for p in lines:
                picked = p[np.linspace(0, len(p) - 1, CLICKS).round().astype(int)]
                clicks.append(np.clip(picked + rng.normal(0.0, args.noise_px, picked.shape), -0.5,
                                      np.array(true.image_size) - 0.5).tolist())
            lines_json, lens_json = Path(tmp) / f"lines{seed}.json", Path(tmp) / f"lens{seed}.json"
            lines_json.write_text(json.dumps({"image_size": list(true.image_size), "lines": clicks}))
            code = homocal_main(["lens", "--lines", str(lines_json), "-o", str(lens_json), "--terms", args.terms,
                                 "--focal", repr(float(true.K[0, 0]))])
            assert code == 0
            out = read_json(lens_json)
            est = Lens(out["K"], out["distortion"], tuple(out["image_size"]))
            clicked = exact_corners + rng.normal(0.0, args.noise_px, exact_corners.shape)
            known, estimated = (range_error(lens, clicked, test_px, test_xy) for lens in (true, est))
            k1 = est.distortion[0]
            row = [seed, k1, 100 * (k1 / true.distortion[0] - 1), out["fit"]["corner_displacement_px"],
                   100 * (out["fit"]["corner_displacement_px"] / true_corner - 1), out["fit"]["rms_after_px"],
                   100 * known, 100 * estimated, estimated / known, 100 * range_error(est, exact_corners, test_px, test_xy)]
            rows.append(row)
            print("| " + " | ".join(f"{v:.4g}" if isinstance(v, float) else str(v) for v in row) + " |")
    a = np.array(rows)[:, 1:]
    for name, f in (("mean", np.mean), ("min", np.min), ("max", np.max)):
        print(f"| {name} | " + " | ".join(f"{v:.4g}" for v in f(a, axis=0)) + " |")


if __name__ == "__main__":
    main()

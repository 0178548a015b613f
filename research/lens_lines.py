"""How well `homocal lens --lines` recovers a wide lens from clicked straight ground lines, and what it leaves in
the ground mapping (docs/real-camera.md, "A lens without a checkerboard").

Run: python research/lens_lines.py [--dataset DATASET] [--seeds N] [--noise-px PX] [--terms T]

The camera is DATASET's camera.json (K, R, t, distortion, width, height: a simgen dataset of scene3), else a
stand-in of scene3's camera (scenes/scene3/scene.toml: 1280x720, hfov 95, 4 m high, 15 degrees down, yaw 8 degrees
towards -x, roll 1 degree lowering its right side, distortion STAND_IN). The lines are scene3's street (scene1's):
the sidewalks' outer edges, the kerbs, the road's edge lines and its centre line (ALONG, x in metres, from y = 0
to 80 m), the zebra crossings' edges across the road (ACROSS, y in metres, x from -3.5 to 3.5 m) and, with
--buildings, the houses' facades along the street (FACADES: the two vertical edges, the roof line and the foot of
each; coplanar, so none hides another). Each is
projected through the lens, and CLICKS points spread along its visible part are clicked with Gaussian noise of
--noise-px on each coordinate (--clicks points, default CLICKS). For each seed: `homocal lens --lines` on them (with the true focal length,
--focal), then
  - k1 and the corner displacement (how far the lens moves the frame's corner pixel) against the true ones;
  - the ground mapping of scene3's trapezoid (TRAPEZOID, metres) at test points 5-50 m from the camera (every
    metre of range, every 5 degrees of bearing, those in the frame; their exact distorted pixels undistorted):
    the median relative range error with the true lens and with the estimated one, from the trapezoid's corners
    clicked with the same noise and (last column) from its exact corners.
Prints one row per seed and the mean and range of each column. --write-lines FILE also writes seed 0's clicks as
LINES.json (examples/lens/lines.json is `--buildings --write-lines examples/lens/lines.json` on the stand-in).
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
from homocal.geometry.camera_file import read_camera
from homocal.geometry.lens import Lens

STAND_IN = [-0.30678, 0.0825017, 0.0028784, -0.00015829, 0.0]  # scenes/scene3/scene.toml's distortion
ALONG = (-7.5, -3.5, -3.25, 0.0, 3.25, 3.5, 7.5)  # x, metres: sidewalk edges, kerbs, edge lines, centre line
ACROSS = (7.0, 10.0, 22.0, 26.0)  # y, metres: the zebra crossings' near and far edges
FACADES = ((10.0, 5.0, 19.0, 10.0), (10.0, 26.0, 46.0, 14.0), (10.0, 52.0, 80.0, 8.0),  # x, y from, y to, height (m):
           (-10.0, 7.0, 25.0, 12.0), (-10.0, 32.0, 56.0, 16.0), (-10.0, 64.0, 88.0, 10.0))  # scene3's houses, scene.xml
CLICKS = 12  # points clicked along each visible line (default of --clicks)
TRAPEZOID = np.array([[-3.25, 40.0], [3.25, 40.0], [3.25, 10.0], [-3.25, 10.0]])  # scene3's, TL, TR, BR, BL, metres


def stand_in() -> tuple[np.ndarray, np.ndarray, Lens]:
    """R (3, 3), t (3,) and Lens of scene3's camera (module docstring)."""
    cam = PinholeCamera()
    R = _about_z(-1.0) @ cam.R @ _about_z(-8.0)  # rolled about the optical axis after the tilt, yawed about the vertical before
    return R, -R @ cam.position, Lens(cam.K, STAND_IN, (cam.width, cam.height))


def _about_z(deg: float) -> np.ndarray:
    """(3, 3) rotation by deg degrees about the z axis of its frame."""
    return cv2.Rodrigues(np.array([0.0, 0.0, math.radians(deg)]))[0]


def from_dataset(path: Path) -> tuple[np.ndarray, np.ndarray, Lens]:
    camera = read_camera(path / "camera.json")
    return camera.R, camera.t, camera.lens


def project(X: np.ndarray, R: np.ndarray, t: np.ndarray, lens: Lens) -> np.ndarray:
    """World points (N, 3) -> distorted pixels (N, 2) (cv2.projectPoints with the lens's K and distortion)."""
    p, _ = cv2.projectPoints(X, cv2.Rodrigues(R)[0], t, lens.K, lens.distortion)
    return p.reshape(-1, 2)


def in_frame(p: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    return (p[:, 0] >= 0) & (p[:, 0] <= size[0] - 1) & (p[:, 1] >= 0) & (p[:, 1] <= size[1] - 1)


def street_lines(R, t, lens: Lens, buildings: bool, clicks: int) -> list[np.ndarray]:
    """The visible parts of the street's lines, each as dense distorted pixels (M, 2) ordered along it."""
    y, x = np.linspace(0.0, 80.0, 4001), np.linspace(-3.5, 3.5, 701)
    worlds = [np.column_stack([np.full_like(y, a), y, np.zeros_like(y)]) for a in ALONG]
    worlds += [np.column_stack([x, np.full_like(x, a), np.zeros_like(x)]) for a in ACROSS]
    if buildings:
        s = np.linspace(0.0, 1.0, 1001)[:, None]
        for x, y0, y1, h in FACADES:
            worlds += [np.array([x, y, 0.0]) + s * [0.0, 0.0, h] for y in (y0, y1)]
            worlds += [np.array([x, y0, z]) + s * [0.0, y1 - y0, 0.0] for z in (0.0, h)]
    out = []
    for X in worlds:
        X = X[(R @ X.T + t[:, None])[2] > 0.5]  # in front of the camera
        p = project(X, R, t, lens)
        p = p[in_frame(p, lens.image_size)]
        if len(p) >= clicks and np.linalg.norm(p[-1] - p[0]) > 100:
            out.append(p)
    return out


def test_points(R, t, lens: Lens) -> tuple[np.ndarray, np.ndarray]:
    """Ground points 5-50 m from the camera (every metre, every 5 degrees of bearing) seen in the frame: their
    distorted pixels (N, 2) and ground metres (N, 2)."""
    ranges, bearings = np.meshgrid(np.arange(5.0, 50.5), np.radians(np.arange(-60.0, 61.0, 5.0)))
    xy = np.column_stack([(ranges * np.sin(bearings)).ravel(), (ranges * np.cos(bearings)).ravel()])
    px = project(np.column_stack([xy, np.zeros(len(xy))]), R, t, lens)
    keep = in_frame(px, lens.image_size)
    return px[keep], xy[keep]


def range_error(lens: Lens, corners_px: np.ndarray, ground: np.ndarray, test_px: np.ndarray, test_xy: np.ndarray) -> float:
    """Median |mapped range - true range| / true range of the test points through the trapezoid (image corners,
    ground corners in metres), both undistorted with ``lens``."""
    vt = ViewTransformer(lens.undistort_points(corners_px), ground)
    mapped = vt.transform_points(lens.undistort_points(test_px))
    return float(np.nanmedian(np.abs(np.hypot(*mapped.T) - np.hypot(*test_xy.T)) / np.hypot(*test_xy.T)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--dataset", type=Path)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--noise-px", type=float, default=1.0)
    parser.add_argument("--terms", default="k1,k2")
    parser.add_argument("--buildings", action="store_true")
    parser.add_argument("--clicks", type=int, default=CLICKS)
    parser.add_argument("--write-lines", type=Path)
    args = parser.parse_args()
    R, t, true = from_dataset(args.dataset) if args.dataset else stand_in()
    corner = np.zeros((1, 2))
    true_corner = float(np.linalg.norm(true.undistort_points(corner) - corner))
    lines = street_lines(R, t, true, args.buildings, args.clicks)
    test_px, test_xy = test_points(R, t, true)
    exact_corners = project(np.column_stack([TRAPEZOID, np.zeros(4)]), R, t, true)
    print(f"camera: {args.dataset or 'stand-in'}; true k1 {true.distortion[0]:.4f}, "
          f"corner displacement {true_corner:.1f} px; {len(lines)} lines, {len(test_xy)} test points; "
          f"--noise-px {args.noise_px:g}, --clicks {args.clicks}, --terms {args.terms}{', --buildings' if args.buildings else ''}")
    print("| seed | k1 | k1 error % | corner px | corner error % | RMS after px | range err known % | "
          "range err estimated % | ratio | exact trapezoid: estimated % |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            rng = np.random.default_rng(seed)
            clicks = []
            for p in lines:
                picked = p[np.linspace(0, len(p) - 1, args.clicks).round().astype(int)]
                clicks.append(np.clip(picked + rng.normal(0.0, args.noise_px, picked.shape), -0.5,
                                      np.array(true.image_size) - 0.5).tolist())
            lines_json, lens_json = Path(tmp) / f"lines{seed}.json", Path(tmp) / f"lens{seed}.json"
            lines_json.write_text(json.dumps({"image_size": list(true.image_size), "lines": clicks}))
            if seed == 0 and args.write_lines:
                rounded = [[[round(u, 1), round(v, 1)] for u, v in line] for line in clicks]  # as a page saves clicks
                args.write_lines.write_text(json.dumps({"image_size": list(true.image_size), "lines": rounded}) + "\n")
            code = homocal_main(["lens", "--lines", str(lines_json), "-o", str(lens_json), "--terms", args.terms,
                                 "--focal", repr(float(true.K[0, 0]))])
            assert code == 0
            out = read_json(lens_json)
            est = Lens(out["K"], out["distortion"], tuple(out["image_size"]))
            clicked = exact_corners + rng.normal(0.0, args.noise_px, exact_corners.shape)
            known, estimated = (range_error(lens, clicked, TRAPEZOID, test_px, test_xy) for lens in (true, est))
            k1 = est.distortion[0]
            row = [seed, k1, 100 * (k1 / true.distortion[0] - 1), out["fit"]["corner_displacement_px"],
                   100 * (out["fit"]["corner_displacement_px"] / true_corner - 1), out["fit"]["rms_after_px"],
                   100 * known, 100 * estimated, estimated / known, 100 * range_error(est, exact_corners, TRAPEZOID, test_px, test_xy)]
            rows.append(row)
            print("| " + " | ".join(f"{v:.4g}" if isinstance(v, float) else str(v) for v in row) + " |")
    a = np.array(rows)[:, 1:]
    for name, f in (("mean", np.mean), ("min", np.min), ("max", np.max)):
        print(f"| {name} | " + " | ".join(f"{v:.4g}" for v in f(a, axis=0)) + " |")


if __name__ == "__main__":
    main()

"""How often `homocal lens --frame` finds a dataset's lens from one frame with no click (docs/real-camera.md,
"A lens without a checkerboard").

Run: python research/lens_frames.py DATASET [DATASET ...] [--every N] [--terms TERMS]

Every N-th frame (default 10) of each DATASET's video.mp4 is written as a PNG and given to `homocal lens --frame`
with the dataset's focal length (--focal, from camera.json's K). A frame "works" when the command writes a lens
whose corner displacement (how far it moves the frame's corner pixel) is within 5 % of the true one, or within
TOLERANCE_PX of it where the true one is below 100 px (a pinhole camera's is 0). Prints one row per dataset: the
frames tried, those that worked, those refused, and over the frames that gave a lens, the corner displacements'
median and range and the median relative range error at 5-50 m through the dataset's exact trapezoid with the estimated
lens (research/lens_lines.py's test points; with the true lens it is 0).
"""
from __future__ import annotations

import argparse
import contextlib
import io
import tempfile
from pathlib import Path

import cv2
import numpy as np

from homocal.cli import main as homocal_main
from homocal.files import read_json
from homocal.geometry.camera_file import read_camera
from homocal.geometry.lens import Lens
from lens_lines import test_points, range_error

TOLERANCE_PX = 5.0


def corner_displacement(lens: Lens) -> float:
    corner = np.zeros((1, 2))
    return float(np.linalg.norm(lens.undistort_points(corner) - corner))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("datasets", nargs="+", type=Path)
    parser.add_argument("--every", type=int, default=10)
    parser.add_argument("--terms", default="k1,k2")
    args = parser.parse_args()
    print("| dataset | true corner px | frames | worked | refused | corner px median [min, max] | "
          "range error % median [min, max] |")
    print("|---|---|---|---|---|---|---|")
    for dataset in args.datasets:
        camera = read_camera(dataset / "camera.json")
        true_lens = camera.lens
        true = corner_displacement(true_lens)
        test_px, test_xy = test_points(camera.R, camera.t, true_lens)
        trapezoids = read_json(dataset / "trapezoids.json")
        corners, ground = np.array(trapezoids["exact"]["image"]), np.array(trapezoids["ground_m"])
        found, refused, ranges = [], 0, []
        capture = cv2.VideoCapture(str(dataset / "video.mp4"))
        with tempfile.TemporaryDirectory() as tmp:
            index = 0
            while True:
                ok, image = capture.read()
                if not ok:
                    break
                if index % args.every == 0:
                    png, out = Path(tmp) / f"{index}.png", Path(tmp) / f"{index}.json"
                    cv2.imwrite(str(png), image)
                    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
                        code = homocal_main(["lens", "--frame", str(png), "-o", str(out),
                                             "--focal", repr(float(camera.K[0, 0])), "--terms", args.terms])
                    if code == 0:
                        lens = read_camera(out).lens
                        found.append(corner_displacement(lens))
                        ranges.append(100 * range_error(lens, corners, ground, test_px, test_xy))
                    else:
                        refused += 1
                index += 1
        capture.release()
        found = np.array(found)
        worked = int(np.sum(np.abs(found - true) <= max(TOLERANCE_PX, 0.05 * true)))
        spread = (f"{np.median(found):.1f} [{found.min():.1f}, {found.max():.1f}]" if len(found) else "-")
        errors = f"{np.median(ranges):.2f} [{min(ranges):.2f}, {max(ranges):.2f}]" if ranges else "-"
        print(f"| {dataset.name} | {true:.1f} | {len(found) + refused} | {worked} | {refused} | {spread} | {errors} |")


if __name__ == "__main__":
    main()

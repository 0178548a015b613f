"""How often `homocal lens --frame` finds a dataset's lens from one frame with no click (docs/real-camera.md,
"A lens without a checkerboard").

Run: python research/lens_frames.py DATASET [DATASET ...] [--every N]

Every N-th frame (default 10) of each DATASET's video.mp4 is written as a PNG and given to `homocal lens --frame`
with the dataset's focal length (--focal, from camera.json's K). A frame "works" when the command writes a lens
whose corner displacement (how far it moves the frame's corner pixel) is within 5 % of the true one, or within
TOLERANCE_PX of it where the true one is below 100 px (a pinhole camera's is 0). Prints one row per dataset: the
frames tried, those that worked, those refused, and the corner displacements' median and range.
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
from homocal.geometry.lens import Lens

TOLERANCE_PX = 5.0


def corner_displacement(lens: Lens) -> float:
    corner = np.zeros((1, 2))
    return float(np.linalg.norm(lens.undistort_points(corner) - corner))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("datasets", nargs="+", type=Path)
    parser.add_argument("--every", type=int, default=10)
    args = parser.parse_args()
    print("| dataset | true corner px | frames | worked | refused | corner px median [min, max] |")
    print("|---|---|---|---|---|---|")
    for dataset in args.datasets:
        camera = read_json(dataset / "camera.json")
        size = (camera["width"], camera["height"])
        true = corner_displacement(Lens(camera["K"], camera.get("distortion", [0.0] * 5), size))
        found, refused = [], 0
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
                                             "--focal", repr(float(camera["K"][0][0]))])
                    if code == 0:
                        fit = read_json(out)
                        found.append(corner_displacement(Lens(fit["K"], fit["distortion"], size)))
                    else:
                        refused += 1
                index += 1
        capture.release()
        found = np.array(found)
        worked = int(np.sum(np.abs(found - true) <= max(TOLERANCE_PX, 0.05 * true)))
        spread = (f"{np.median(found):.1f} [{found.min():.1f}, {found.max():.1f}]" if len(found) else "-")
        print(f"| {dataset.name} | {true:.1f} | {len(found) + refused} | {worked} | {refused} | {spread} |")


if __name__ == "__main__":
    main()

"""research/scene3_range.py on a tiny synthetic dataset of a barrel lens (tests/synthetic_dataset.py): its
figures against OpenCV's own homography (cv2.findHomography, cv2.perspectiveTransform) and inverse
(cv2.undistortPoints with criteria that make it exact on this lens, NOTES.md)."""
import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pyarrow.parquet as pq
import pytest

from synthetic_dataset import write_dataset

SCRIPT = Path(__file__).resolve().parents[2] / "research" / "scene3_range.py"
spec = importlib.util.spec_from_file_location("scene3_range", SCRIPT)
script = importlib.util.module_from_spec(spec)
spec.loader.exec_module(script)
BARREL = [-0.2, 0.04, 5e-4, -3e-4, 0.0]


def opencv_median_error(path: Path, undistort: bool) -> tuple[int, float]:
    """(points, median relative range error %) of the exact trapezoid at 5-50 m, with OpenCV only."""
    K = np.array(json.loads((path / "camera.json").read_text())["K"])
    traps = json.loads((path / "trapezoids.json").read_text())
    gt = pq.read_table(path / "gt.parquet").to_pandas()
    gt = gt[gt["in_frame"]]
    r = np.hypot(gt["x"], gt["y"]).to_numpy()
    gt, r = gt[(r >= 5) & (r <= 50)], r[(r >= 5) & (r <= 50)]
    corners, points = np.array(traps["exact"]["image"], float), gt[["u", "v"]].to_numpy()
    if undistort:
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
        corners, points = (cv2.undistortPoints(p.reshape(-1, 1, 2), K, np.array(BARREL), P=K, criteria=criteria)[:, 0]
                           for p in (corners, points))
    H, _ = cv2.findHomography(corners, np.array(traps["ground_m"], float), 0)
    mapped = cv2.perspectiveTransform(points.reshape(-1, 1, 2), H)[:, 0]
    return len(r), 100 * float(np.median(np.abs(np.hypot(*mapped.T) - r) / r))


def test_known_and_ignored_against_opencv(tmp_path):
    path = write_dataset(tmp_path / "d", "lensy", n_calibration=12, n_test=300, distortion=BARREL)
    got = script.range_errors(path)
    points, known = opencv_median_error(path, undistort=True)
    _, ignored = opencv_median_error(path, undistort=False)
    assert got["points"] == points > 200
    assert got["known"] == pytest.approx(known, abs=1e-5) and known < 1e-5  # the exact trapezoid, the lens removed (OpenCV to 1e-6 %)
    assert abs(got["horizon_below_px"]) < 1e-6  # the exact trapezoid's horizon is the camera's
    assert got["ignored"] == pytest.approx(ignored, abs=1e-5) and ignored > 0.1  # OpenCV's homography agrees to about 1e-6 m


@pytest.mark.slow  # a Python start-up: about 3 s under load
def test_command_line(tmp_path):
    path = write_dataset(tmp_path / "d", "lensy", n_calibration=12, n_test=100, distortion=BARREL)
    done = subprocess.run([sys.executable, str(SCRIPT), str(path)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    e = script.range_errors(path)
    assert f"{e['known']:.4f} % with the lens known, {e['ignored']:.2f} % with it ignored" in done.stdout

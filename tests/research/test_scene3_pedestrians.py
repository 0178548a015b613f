"""research/scene3_pedestrians.py's two figures on tiny inputs: the horizon line's RMS against its closed form, the
median range error against OpenCV's own inverse of the lens (cv2.undistortPoints, criteria that make it exact,
NOTES.md) and homography application (cv2.perspectiveTransform)."""
import importlib.util
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from homocal.correctors.horizon import HorizonCorrector
from homocal.geometry import PinholeCamera, ViewTransformer

SCRIPT = Path(__file__).resolve().parents[2] / "research" / "scene3_pedestrians.py"
spec = importlib.util.spec_from_file_location("scene3_pedestrians", SCRIPT)
script = importlib.util.module_from_spec(spec)
spec.loader.exec_module(script)
CAM = PinholeCamera(roll_deg=1.0, yaw_deg=8.0, distortion=(-0.2, 0.04, 5e-4, -3e-4, 0.0))


@pytest.mark.parametrize("row,roll", [(202.0, 1.0), (199.0, 0.3), (210.0, -2.0)])
def test_horizon_rms_closed_form(row, roll):
    """The row difference d(u) = p + s u is linear in the column, so its mean square over u = 0..W-1 is
    p^2 + 2 p s (W - 1) / 2 + s^2 (W - 1)(2 W - 1) / 6."""
    a, b, c = CAM.horizon
    cx, W = CAM.K[0, 2], CAM.width
    s = -math.tan(math.radians(roll)) + a / b  # fitted slope minus the true one
    p = row + math.tan(math.radians(roll)) * cx + c / b  # their difference at u = 0
    expected = math.sqrt(p * p + p * s * (W - 1) + s * s * (W - 1) * (2 * W - 1) / 6)
    assert script.horizon_rms(row, roll, tuple(CAM.K[:2, 2]), CAM.horizon, W) == pytest.approx(expected, rel=1e-9)
    true_row = -(a * cx + c) / b
    assert script.horizon_rms(true_row, 1.0, tuple(CAM.K[:2, 2]), CAM.horizon, W) < 1e-9  # the camera's own line


def test_median_range_error_against_opencv():
    ground = np.array([[-3.25, 40.0], [3.25, 40.0], [3.25, 10.0], [-3.25, 10.0]])
    lens = CAM.lens
    clicked = lens.undistort_points(CAM.project_ground(ground) + [[1.0, -1.0], [0.0, 1.5], [-1.0, 0.0], [0.5, 0.5]])
    c = HorizonCorrector().fit(ViewTransformer(clicked, ground), lens.undistort_points(CAM.project_ground(
        [[0.0, 8.0], [0.0, 20.0], [0.0, 35.0]])), np.array([[0.0, 8.0], [0.0, 20.0], [0.0, 35.0]]), (0.0, 0.0))
    c.lens_ = lens
    rng = np.random.default_rng(0)
    truth = np.column_stack([rng.uniform(-7, 7, 200), rng.uniform(6, 45, 200)])
    pixels = CAM.project_ground(truth)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
    q = cv2.undistortPoints(pixels.reshape(-1, 1, 2), CAM.K, np.array(CAM.distortion), P=CAM.K, criteria=criteria)
    mapped = cv2.perspectiveTransform(q, c.m)[:, 0]
    expected = 100 * np.median(np.abs(np.hypot(*mapped.T) - np.hypot(*truth.T)) / np.hypot(*truth.T))
    got = script.median_range_error(c, pixels, truth, np.zeros(2))
    assert got == pytest.approx(expected, abs=1e-6) and got > 0.05

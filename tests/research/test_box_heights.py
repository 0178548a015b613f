"""research/box_heights.py's implied height at the true pose against the people's own heights, projected through a
rolled, yawed camera with a barrel lens (homocal.geometry.PinholeCamera.project: the world point itself)."""
import importlib.util
from pathlib import Path

import numpy as np

from homocal.geometry import PinholeCamera
from homocal.geometry.boxes import undistort_boxes

SCRIPT = Path(__file__).resolve().parents[2] / "research" / "box_heights.py"
spec = importlib.util.spec_from_file_location("box_heights", SCRIPT)
script = importlib.util.module_from_spec(spec)
spec.loader.exec_module(script)
CAM = PinholeCamera(tilt_deg=15.0, roll_deg=1.0, yaw_deg=8.0, distortion=(-0.3, 0.08, 3e-3, -2e-4, 0.0))


def test_implied_height_is_the_persons():
    """Boxes from a person's sole and crown (x1..x2 around both columns, y1 the crown's row, y2 the sole's), 10-40
    m ahead: the implied height is the person's within 0.5 % (the head row is read at the box's centre column, not
    the crown's, a few pixels aside on a bent, rolled frame: up to 2.5 % for people 5-8 m away at the frame's
    sides); read as a pinhole's, off by more than 1 %."""
    rng = np.random.default_rng(1)
    xy = np.column_stack([rng.uniform(-8, 8, 60), rng.uniform(10, 40, 60)])
    height = rng.uniform(1.5, 1.9, 60)
    sole, crown = CAM.project(np.column_stack([xy, np.zeros(60)])), CAM.project(np.column_stack([xy, height]))
    keep = np.isfinite(sole).all(axis=1) & np.isfinite(crown).all(axis=1) & (sole[:, 1] < CAM.height)
    boxes = np.column_stack([np.minimum(sole[:, 0], crown[:, 0]) - 4, crown[:, 1],
                             np.maximum(sole[:, 0], crown[:, 0]) + 4, sole[:, 1]])[keep]
    got = script.box_heights(undistort_boxes(boxes, CAM.lens), CAM.K, 15.0, 1.0, CAM.mount_height_m)
    assert keep.sum() > 40
    assert np.abs(got / height[keep] - 1).max() < 5e-3
    pinhole = script.box_heights(boxes, CAM.K, 15.0, 1.0, CAM.mount_height_m)
    assert np.abs(pinhole / height[keep] - 1).max() > 1e-2

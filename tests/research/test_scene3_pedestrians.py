"""research/scene3_pedestrians.py's two figures on tiny inputs: the horizon line's RMS against its closed form, the
median range error against OpenCV's own inverse of the lens (cv2.undistortPoints, criteria that make it exact,
NOTES.md) and homography application (cv2.perspectiveTransform); its --lens on a synthetic dataset of exact boxes
(tests/synthetic_dataset.py): known finds the camera's own horizon, ignore is the fit of the camera's pixels as a
pinhole's."""
import importlib.util
import json
import math
import shutil
from pathlib import Path

import cv2
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from homocal.correctors.horizon import HorizonCorrector
from homocal.correctors.pedestrians import PedestrianCorrector
from homocal.dataset import load_dataset
from homocal.geometry import PinholeCamera, ViewTransformer
from synthetic_dataset import write_dataset

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


def write_people(path: Path, cam: PinholeCamera, height_m: float = 1.71) -> Path:
    """A synthetic dataset of cam (write_dataset) whose detections.parquet holds exact "segmentation" boxes of 12
    people height_m tall walking 10 frames each (20 per second) across the view (5-22 m ahead, -9..8 m aside): the box spans the
    head's and the foot's projections (rows exactly; columns 5 px wider)."""
    write_dataset(path, n_test=200, camera=cam)
    starts = [(x, y) for y in (6.0, 11.0, 16.0, 21.0) for x in (-9.0, -1.0, 7.0)]
    rows = []
    for person, (x0, y0) in enumerate(starts):
        for frame in range(10):
            x, y = x0 + 0.12 * frame, y0 + (0.5 if person % 2 else -0.5) * 0.1 * frame
            foot, head = cam.project([[x, y, 0.0], [x, y, height_m]])
            rows.append((frame, person, min(foot[0], head[0]) - 5, head[1], max(foot[0], head[0]) + 5, foot[1], x, y))
    frame, agent, x1, y1, x2, y2, gx, gy = map(np.array, zip(*rows))
    pq.write_table(pa.table({"detector": ["segmentation"] * len(rows), "frame": frame.astype(np.int32), "t": frame * 0.05,
                             "agent_id": agent.astype(np.int32), "x1": x1, "y1": y1, "x2": x2, "y2": y2,
                             "u": (x1 + x2) / 2, "v": y2, "gt_x": gx, "gt_y": gy}), path / "detections.parquet")
    return path


@pytest.mark.slow  # four pedestrian fits: about 3 s under load
def test_lens_known_and_ignored(tmp_path):
    """Exact boxes of people exactly the prior's mean tall: with the lens known the fit finds the camera's horizon
    line (the boxes' only error, the head row taken at the box's centre column rather than the head's, is well
    under a pixel); ignored, its horizon is that of PedestrianCorrector fitted on the camera's own pixels as a
    pinhole's (the same K and camera height), and the bent image puts it pixels off."""
    path = write_people(tmp_path / "d", CAM)
    prior = ["--height-mean", "1.71", "--height-sd", "0.09"]
    known = script.run(path, "segmentation", prior, "yes", None, tmp_path, "known")
    ignored = script.run(path, "segmentation", prior, "yes", None, tmp_path, "ignore")
    assert known["horizon_rms_px"] < 0.5 and abs(known["roll_deg"] - 1.0) < 0.1
    boxes = pq.read_table(path / "detections.parquet").to_pandas()
    hand = np.array(json.loads((path / "trapezoids.json").read_text())["hand_placed"]["image"])
    ds = load_dataset(path)
    pinhole = PedestrianCorrector(1.71, 0.09, estimate_roll=True).fit(
        ViewTransformer(hand, ds.site_map.to_metres(ds.trapezoid_map)), boxes[["x1", "y1", "x2", "y2"]].to_numpy(),
        convention="homocal", frames=boxes["frame"].to_numpy(), camera_height_m=CAM.mount_height_m, K=CAM.K,
        image_size=(CAM.width, CAM.height))
    expected = script.horizon_rms(pinhole.horizon_row_, pinhole.roll_deg_, tuple(CAM.K[:2, 2]), CAM.horizon, CAM.width)
    assert ignored["horizon_rms_px"] == pytest.approx(expected, abs=1e-9) and expected > 2.0
    assert ignored["median_range_error_pct"] > known["median_range_error_pct"]


def test_seconds_cuts_the_recording(tmp_path):
    """--seconds S: the figures of a copy of the dataset whose detections.parquet and gt.parquet keep only the rows
    whose time is below S (cut here with pandas): the boxes of the first 6 frames of 10, the ground truth's first
    6 of 200 points."""
    path = write_people(tmp_path / "d", CAM)
    cut = Path(shutil.copytree(path, tmp_path / "cut"))
    for name in ("detections.parquet", "gt.parquet"):
        table = pq.read_table(path / name).to_pandas()
        pq.write_table(pa.Table.from_pandas(table[table["t"] < 0.275], preserve_index=False), cut / name)
    prior = ["--height-mean", "1.71", "--height-sd", "0.09"]
    folders = [tmp_path / name for name in ("a", "b")]
    for folder in folders:
        folder.mkdir()
    got = script.run(path, "segmentation", prior, "yes", None, folders[0], "known", seconds=0.275)
    expected = script.run(cut, "segmentation", prior, "yes", None, folders[1], "known")
    assert got == expected and got["boxes"] == 12 * 6

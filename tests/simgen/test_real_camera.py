"""A dataset of a real camera (scene3: lens, roll, yaw): every exact pixel it stores is cv2.projectPoints of the
ground truth through camera.json's K, R, t and distortion; the homographies are those of the undistorted image."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pyarrow.parquet as pq
import pytest

from simgen.cli import main
from simgen.scene import load_scene

from scene_copies import copy_scene
from schema_tables import schema_names

pytestmark = [pytest.mark.generate, pytest.mark.slow]  # a dataset rendered


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """scene3 at 320x180, 1 s."""
    tmp = tmp_path_factory.mktemp("real")
    folder = copy_scene(tmp, "scene3")
    assert main(["generate", str(folder), "--out", str(tmp / "out"), "--seconds", "1", "--seed", "3"]) == 0
    return load_scene(folder), tmp / "out"


def projected(camera: dict, xyz: np.ndarray) -> np.ndarray:
    """(N, 3) world metres -> (N, 2) cv2.projectPoints through camera.json's K, R, t, distortion."""
    rvec, _ = cv2.Rodrigues(np.array(camera["R"]))
    return cv2.projectPoints(xyz, rvec, np.array(camera["t"]), np.array(camera["K"]), np.array(camera["distortion"]))[0][:, 0]


def test_camera_json_carries_the_real_camera(dataset):
    scene, out = dataset
    camera = json.loads((out / "camera.json").read_text())
    assert camera["distortion"] == list(scene.camera.distortion) == [-0.30678, 0.0825017, 0.0028784, -0.00015829, 0.0]
    assert (camera["roll_deg"], camera["yaw_deg"]) == (1.0, 8.0) and "horizon_row" not in camera
    rvec, _ = cv2.Rodrigues(np.array(camera["R"]))
    xy = np.array([[-3.0, 8.0], [2.0, 15.0], [0.0, 40.0]])
    pinhole = cv2.projectPoints(np.column_stack([xy, np.zeros(3)]), rvec, np.array(camera["t"]), np.array(camera["K"]), None)[0][:, 0]
    np.testing.assert_allclose(cv2.perspectiveTransform(xy[:, None], np.array(camera["ground_to_image"]))[:, 0], pinhole, atol=1e-6)
    a, b, c = camera["horizon"]
    far = projected({**camera, "distortion": [0.0] * 5}, np.array([[-1e9, 1e9, 0.0], [1e9, 1e9, 0.0]]))
    np.testing.assert_allclose(a * far[:, 0] + b * far[:, 1] + c, 0.0, atol=1e-4)


def test_gt_pixels_are_project_points_with_the_lens(dataset):
    _, out = dataset
    camera = json.loads((out / "camera.json").read_text())
    gt = pq.read_table(out / "gt.parquet").to_pandas()
    seen = gt["u"].notna().to_numpy()
    assert seen.sum() > 20 and gt["in_frame"].any()
    xyz = np.column_stack([gt["x"], gt["y"], np.zeros(len(gt))])[seen]
    got, expected, inside = gt[["u", "v"]].to_numpy()[seen], projected(camera, xyz), gt["in_frame"].to_numpy()[seen]
    np.testing.assert_allclose(got[inside], expected[inside], rtol=0, atol=1e-6)
    np.testing.assert_allclose(got, expected, rtol=1e-12)  # beside the camera (1e11 px) float64 rounding alone is 1e-5 px


def test_calibration_and_trapezoids_are_the_distorted_pixels(dataset):
    _, out = dataset
    camera = json.loads((out / "camera.json").read_text())
    cal = pq.read_table(out / "calibration.parquet").to_pandas()
    xyz = np.column_stack([cal["x"], cal["y"], np.zeros(len(cal))])
    np.testing.assert_allclose(cal[["u_exact", "v_exact"]].to_numpy(), projected(camera, xyz), atol=1e-6)
    detected = cal[["u", "v"]].to_numpy()  # the segmentation box's foot in the distorted frame
    assert np.nanmedian(np.hypot(*(detected - cal[["u_exact", "v_exact"]].to_numpy()).T)) < 2.0
    trap = json.loads((out / "trapezoids.json").read_text())
    ground = np.column_stack([trap["ground_m"], np.zeros(4)])
    np.testing.assert_allclose(trap["exact"]["image"], projected(camera, ground), atol=1e-6)
    off = np.hypot(*(np.array(trap["hand_placed"]["image"]) - projected(camera, ground)).T)
    assert np.all(off <= 2.0 + 1e-9), off


@pytest.mark.parametrize("section", ["manifest.json", "camera.json", "gt.parquet", "detections.parquet",
                                     "calibration.parquet"])
def test_data_schema_names_every_key_once(dataset, section):
    """data_schema.md is exact: each key or column of a real camera's dataset file is in its table, once; the table
    names no other but those a pinhole's camera.json writes instead (horizon_row)."""
    _, out = dataset
    path = out / section
    written = list(pq.read_schema(path).names) if path.suffix == ".parquet" else list(json.loads(path.read_text()))
    documented = schema_names(section)
    assert sorted(set(documented)) == sorted(documented), f"named twice: {sorted({n for n in documented if documented.count(n) > 1})}"
    assert set(written) - set(documented) == set(), "written, not documented"
    assert set(documented) - set(written) <= {"horizon_row"}, "documented, not written"


def test_schema_names_reads_a_row_of_several_names():
    assert schema_names("camera.json")[:5] == ["K", "R", "t", "width", "height"]

"""homocal study --lens: known undistorts every image point of a distorted dataset before the kernels, ignore
maps the camera's pixels as a pinhole's; checked against OpenCV's own inverse and the pinhole's projection."""
import json

import cv2
import numpy as np
import pytest

from homocal.geometry import PinholeCamera
from homocal.study.engine import run_study
from homocal.study.inputs import StudyParams, StudyScene
from homocal.study.report import config_label
from synthetic_dataset import write_dataset

CAM = PinholeCamera()
BARREL = [-0.2, 0.04, 5e-4, -3e-4, 0.0]


def opencv_undistort(pixels: np.ndarray) -> np.ndarray:
    """cv2.undistortPoints with criteria that make it exact on this lens (NOTES.md: 3e-13 px at k1 = -0.2)."""
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
    out = cv2.undistortPoints(pixels.reshape(-1, 1, 2), CAM.K, np.array(BARREL), P=CAM.K, criteria=criteria)
    return out[:, 0, :]


@pytest.fixture(scope="module")
def distorted(tmp_path_factory):
    return write_dataset(tmp_path_factory.mktemp("lens") / "d", "lensy", n_calibration=12, n_test=200, distortion=BARREL)


def test_known_undistorts_every_image_point(distorted):
    ignore = StudyScene.from_dataset(distorted, StudyParams(n_test=200))
    known = StudyScene.from_dataset(distorted, StudyParams(n_test=200, lens="known"))
    # ignore: the dataset's (distorted) pixels, as far from the pinhole's as the lens moves them
    assert np.abs(ignore.cal_image - CAM.project_ground(ignore.cal_ground)).max() > 5.0
    for name in ("cal_image", "test_image", "image_quad"):
        np.testing.assert_allclose(getattr(known, name), opencv_undistort(getattr(ignore, name)), atol=1e-6)
    # the exact points undistort to the pinhole's projection of their ground truth
    np.testing.assert_allclose(known.cal_image, CAM.project_ground(known.cal_ground), atol=1e-6)
    np.testing.assert_allclose(known.test_image, CAM.project_ground(known.test_ground), atol=1e-6)


@pytest.mark.slow  # two studies through the engine
def test_both_values_run_and_say_which(distorted, tmp_path):
    params = {"n_variants": 3, "n_test": 100}
    studies = {v: run_study([str(distorted)], tmp_path / v, StudyParams(**params, lens=v), progress=False)
               for v in ("ignore", "known")}
    assert "lens" not in json.loads((tmp_path / "ignore" / "study.json").read_text())  # today's study.json keys
    assert json.loads((tmp_path / "known" / "study.json").read_text())["lens"] == "known"
    for v, study in studies.items():
        assert f"--lens {v}" in config_label({"preset": "quick", **study})
    results = {v: sorted(p.read_bytes() for p in (tmp_path / v).rglob("*.parquet")) for v in studies}
    assert results["ignore"] and results["ignore"] != results["known"]


def test_known_on_a_pinhole_dataset_changes_nothing(tmp_path):
    path = write_dataset(tmp_path / "p", "pinhole", n_calibration=12, n_test=200)
    ignore = StudyScene.from_dataset(path, StudyParams(n_test=200))
    known = StudyScene.from_dataset(path, StudyParams(n_test=200, lens="known"))
    for name in ("cal_image", "test_image", "image_quad"):
        assert getattr(known, name).tobytes() == getattr(ignore, name).tobytes()

"""The RGB-only detectors: the FunctionDetector plug-in point and OpenCV's HOG people detector on real renders."""
from __future__ import annotations

import json
import re
from importlib.metadata import version

import numpy as np
import pyarrow.parquet as pq
import pytest

from simgen.detection import FunctionDetector, HogDetector, box_iou, id_boxes

from scene_copies import SCENES, copy_scene


def test_function_detector_associates_the_boxes_it_is_given():
    ids = np.full((60, 80), -1, np.int32)
    ids[10:40, 5:20], ids[20:50, 50:70] = 5, 9  # mask boxes (4.5, 9.5, 19.5, 39.5) and (49.5, 19.5, 69.5, 49.5)
    given = np.array([[5.5, 11.5, 20.5, 41.5], [30.0, 0.0, 40.0, 10.0], [49.5, 19.5, 69.5, 49.5]])
    detector = FunctionDetector("mine", lambda rgb: (given, np.array([0.9, 0.5, 0.7])))
    batch = detector.detect(3, 0.15, np.zeros((60, 80, 3), np.uint8), ids)
    assert (batch.detector, batch.frame, batch.t) == ("mine", 3, 0.15)
    assert batch.agent_id.tolist() == [5, -1, 9]
    np.testing.assert_array_equal(batch.xyxy, given)
    np.testing.assert_array_equal(batch.foot, [[13.0, 41.5], [35.0, 10.0], [59.5, 49.5]])
    empty = FunctionDetector("none", lambda rgb: (np.zeros((0, 4)), np.zeros(0))).detect(0, 0.0, np.zeros((60, 80, 3), np.uint8), ids)
    assert len(empty) == 0


def test_a_function_detector_s_rows_do_not_depend_on_the_order_it_returns_boxes_in():
    """As OpenCV's HOG returns the same boxes in an order that varies with its threads: boxes that tie for an agent
    (the same IoU with its mask box) and equal boxes with other scores must give the same rows whatever the order."""
    ids = np.full((60, 80), -1, np.int32)
    ids[10:40, 20:30] = 5  # mask box (19.5, 9.5, 29.5, 39.5)
    boxes = np.array([[17.5, 9.5, 27.5, 39.5], [21.5, 9.5, 31.5, 39.5], [40.0, 5.0, 50.0, 20.0], [40.0, 5.0, 50.0, 20.0]])
    scores = np.array([0.6, 0.6, 0.9, 0.4])  # the first two tie for agent 5 (IoU 8 / 12 each)
    rgb = np.zeros((60, 80, 3), np.uint8)
    batches = [FunctionDetector("mine", lambda rgb, o=order: (boxes[o], scores[o])).detect(0, 0.0, rgb, ids)
               for order in ([0, 1, 2, 3], [1, 0, 3, 2], [3, 2, 1, 0])]
    for batch in batches:
        np.testing.assert_array_equal(batch.xyxy, boxes[[0, 1, 3, 2]])  # by (x1, y1, x2, y2, score)
        np.testing.assert_array_equal(batch.score, scores[[0, 1, 3, 2]])
        assert batch.agent_id.tolist() == [5, -1, -1, -1]


@pytest.mark.generate
@pytest.mark.slow  # three datasets rendered
def test_every_detector_gives_the_same_bytes_in_two_serial_runs_and_two_workers(tmp_path):
    """Issue 26's case, short: segmentation, rgb and hog; two serial runs and a --workers 2 run of 1 s."""
    from simgen.cli import main

    scene = copy_scene(tmp_path)
    files = []
    for out, extra in (("a", []), ("b", []), ("w2", ["--workers", "2"])):
        assert main(["generate", str(scene), "--out", str(tmp_path / out), "--seconds", "1", "--seed", "4", "--no-progress",
                     "--detectors", "segmentation,rgb,hog", *extra]) == 0
        files.append({str(p.relative_to(tmp_path / out)): p.read_bytes() for p in sorted((tmp_path / out).rglob("*")) if p.is_file()})
    assert files[0] == files[1] == files[2]


@pytest.mark.parametrize("kwargs", [{"upscale": 0}, {"scale": 1.0}, {"win_stride": 0}])
def test_hog_refuses_bad_parameters(kwargs):
    with pytest.raises(ValueError, match="HogDetector: need"):
        HogDetector(**kwargs)


@pytest.fixture(scope="module")
def person_frames():
    """(rgb, agent_ids) of scene1's calibration person alone at 12 m and 15 m, 1280x720."""
    from simgen.scene import load_scene
    from simgen.stage import Stage

    frames = []
    with Stage(load_scene(SCENES / "scene1"), seed=0, t_end=1.0) as stage:
        for d in (12.0, 15.0):
            stage.set_calibration((0.0, d), agent_id=4)
            frames.append((stage.rgb(), stage.agent_ids()))
    return frames


@pytest.mark.generate
@pytest.mark.parametrize("upscale, which", [(1.0, 0), pytest.param(2.0, 0, marks=pytest.mark.slow), pytest.param(2.0, 1, marks=pytest.mark.slow)])  # 1x: about 80 px at 12 m; 2x: also 66 px at 15 m
def test_hog_finds_a_rendered_person_and_its_foot_point(person_frames, upscale, which):
    rgb, ids = person_frames[which]
    batch = HogDetector(upscale=upscale).detect(0, 0.0, rgb, ids)
    _, (seg,), _ = id_boxes(ids)
    mine = batch.agent_id == 4
    assert mine.sum() == 1 and np.all((batch.score > 0.5) & (batch.score < 1.0))
    assert box_iou(batch.xyxy[mine], seg).item() > 0.5  # the PASCAL criterion
    height = seg[3] - seg[1]
    foot = batch.foot[mine][0]
    assert abs(foot[0] - (seg[0] + seg[2]) / 2) < 0.05 * height and abs(foot[1] - seg[3]) < 0.15 * height  # window steps of 8 px / upscale


@pytest.mark.generate
@pytest.mark.slow  # a dataset rendered
def test_generate_runs_the_hog_detector_when_asked(tmp_path):
    from simgen.cli import main

    scene = copy_scene(tmp_path)
    out = tmp_path / "out"
    assert main(["generate", str(scene), "--out", str(out), "--seconds", "1", "--seed", "2", "--no-progress",
                 "--detectors", "segmentation,hog"]) == 0
    assert json.loads((out / "manifest.json").read_text())["detectors"] == ["segmentation", "hog"]
    det = pq.read_table(out / "detections.parquet")
    names = set(det.column("detector").to_pylist())
    assert "segmentation" in names and names <= {"segmentation", "hog"}  # at 320x180 people are too small for HOG


def test_generate_without_opencv_hog_is_one_clear_line(tmp_path, capsys, monkeypatch):
    import cv2

    from simgen.cli import main

    monkeypatch.delattr(cv2, "HOGDescriptor", raising=False)  # as with opencv-python-headless 5 (no contrib)
    out = tmp_path / "out"
    assert main(["generate", str(SCENES / "scene1"), "--out", str(out), "--seconds", "1", "--seed", "0",
                 "--detectors", "segmentation,hog"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and err.startswith("simgen: error: --detectors: hog: "), err  # the flag
    assert REPAIR in err and "install.sh" not in err, err
    assert not out.exists()


REPAIR = f"pip install --force-reinstall --no-deps opencv-contrib-python-headless=={version('opencv-contrib-python-headless')}"


def test_hog_from_scene_toml_names_the_key(tmp_path, monkeypatch):
    import cv2

    from simgen.scene import ConfigError, load_scene

    monkeypatch.delattr(cv2, "HOGDescriptor", raising=False)
    folder = copy_scene(tmp_path)
    toml = folder / "scene.toml"
    toml.write_text(re.sub(r"(?m)^detectors = .*$", 'detectors = ["segmentation", "hog"]', toml.read_text()))
    with pytest.raises(ConfigError) as refused:
        load_scene(folder)
    assert str(refused.value).startswith("scene.toml: detection.detectors: hog: ") and REPAIR in str(refused.value)

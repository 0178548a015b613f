"""homocal fit / apply with --camera-json on a distorted camera: the lens is removed before any homography."""
import json

import numpy as np
import pytest

from cli_run import homocal_main
from homocal import load_corrector
from homocal.geometry import Lens, PinholeCamera, undistort_boxes
from homocal.geometry.boxes import box_edges

CAM = PinholeCamera()
LENS = Lens(CAM.K, [-0.2, 0.04, 5e-4, -3e-4, -0.002], (1280, 720))  # folds 1900 px out, beyond the frame
GROUND = np.array([[-3.5, 30.0], [3.5, 30.0], [3.5, 8.0], [-3.5, 8.0]])
REF = np.array([[0.0, 6.0], [2.0, 15.0], [-1.0, 25.0], [0.0, 40.0]])
FEET = np.array([[5.0, 10.0], [-6.0, 20.0], [1.0, 45.0], [8.0, 8.0], [-9.0, 6.0]])


def seen(xy: np.ndarray) -> np.ndarray:
    """The distorted pixels of ground points: cv2.projectPoints of the pinhole's rays through the lens."""
    import cv2

    rays = np.column_stack([xy, np.zeros(len(xy))]) @ CAM.R.T + CAM.t
    pixels, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), CAM.K, LENS.distortion)
    return pixels[:, 0, :]


def csv_text(columns: dict) -> str:
    rows = zip(*columns.values())
    return ",".join(columns) + "\n" + "".join(",".join(repr(float(x)) for x in row) + "\n" for row in rows)


@pytest.fixture
def work(tmp_path):
    (tmp_path / "trap.json").write_text(json.dumps({"image": seen(GROUND).tolist(), "map": GROUND.tolist(),
                                                   "image_size": [1280, 720]}))
    (tmp_path / "lens.json").write_text(json.dumps(LENS.to_dict()))
    q = seen(REF)
    (tmp_path / "ref.csv").write_text(csv_text({"u": q[:, 0], "v": q[:, 1], "x": REF[:, 0], "y": REF[:, 1]}))
    f = seen(FEET)
    (tmp_path / "feet.csv").write_text(csv_text({"u": f[:, 0], "v": f[:, 1]}))
    return tmp_path


def fit_apply(work, capsys, monkeypatch, method, *camera):
    run = lambda *a: homocal_main(*a, cwd=work, capsys=capsys, monkeypatch=monkeypatch)  # noqa: E731
    assert run("fit", "--trapezoid", "trap.json", "--points", "ref.csv", "--method", method, "-o", "c.json",
               *camera).returncode == 0
    assert run("apply", "c.json", "--points", "feet.csv", "-o", "out.csv").returncode == 0
    rows = np.genfromtxt(work / "out.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    return np.column_stack([rows["x"], rows["y"]])


@pytest.mark.parametrize("method", ["horizon", "descent", "least-change", "regression", "hybrid"])
def test_lens_known_maps_exactly(work, capsys, monkeypatch, method):
    """The trapezoid and reference points are exact projections: with the lens every method maps the feet to
    their ground truth (a homography of undistorted pixels is the camera's ground mapping)."""
    xy = fit_apply(work, capsys, monkeypatch, method, "--camera-json", "lens.json")
    np.testing.assert_allclose(xy, FEET, atol=1e-6)
    assert load_corrector(work / "c.json").lens_ == LENS


def test_lens_ignored_is_wrong(work, capsys, monkeypatch):
    xy = fit_apply(work, capsys, monkeypatch, "horizon")
    assert np.abs(xy - FEET).max() > 0.3 and load_corrector(work / "c.json").lens_ is None


def test_a_dataset_camera_json_is_a_lens(work, capsys, monkeypatch):
    camera = {**json.loads((work / "lens.json").read_text()), "R": CAM.R.tolist(), "t": CAM.t.tolist()}
    camera["width"], camera["height"] = camera.pop("image_size")
    (work / "camera.json").write_text(json.dumps(camera))
    np.testing.assert_allclose(fit_apply(work, capsys, monkeypatch, "horizon", "--camera-json", "camera.json"),
                               FEET, atol=1e-6)


@pytest.mark.parametrize("change, args, message", [
    ({"lens.json": {**LENS.to_dict(), "image_size": [1920, 1080]}}, [],
     "trap.json: image_size [1280, 720] differs from the lens's [1920, 1080]"),
    ({"lens.json": {**LENS.to_dict(), "distortion": [-0.5, 0, 0, 0, 0]}}, [], "--camera-json lens.json: distortion: "),
    ({"lens.json": {**LENS.to_dict(), "K": [[0, 0, 1], [0, 1, 0], [0, 0, 1]]}}, [], "--camera-json lens.json: K: fx and fy"),
    ({"ref.csv": "u,v,x,y\n-4000,-3000,0,6\n640,500,0,8\n600,600,1,5\n"}, [],
     "ref.csv: point 0 = [-4000.0, -3000.0] lies beyond the lens's fold"),
])
def test_bad_lens_input(work, capsys, monkeypatch, change, args, message):
    for name, content in change.items():
        (work / name).write_text(content if isinstance(content, str) else json.dumps(content))
    r = homocal_main("fit", "--trapezoid", "trap.json", "--points", "ref.csv", "-o", "c.json", "--camera-json",
                     "lens.json", *args, cwd=work, capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 2 and r.stderr.startswith("homocal: error: ") and message in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not (work / "c.json").exists()


@pytest.mark.parametrize("i, u, refused", [(2, 1280.4, False), (2, 1280.6, True), (3, -1.4, False), (3, -1.6, True)])
def test_a_trapezoid_vertex_outside_the_lens_frame(work, capsys, monkeypatch, i, u, refused):
    """The 1280 px frame spans -0.5 .. 1279.5 (homocal's pixel centres at integers); a click may lie a pixel
    beyond it, further is a trapezoid of another camera's frame."""
    trap = json.loads((work / "trap.json").read_text())
    trap["image"][i][0] = u
    (work / "trap.json").write_text(json.dumps(trap))
    r = homocal_main("fit", "--trapezoid", "trap.json", "--points", "ref.csv", "-o", "c.json", "--camera-json",
                     "lens.json", cwd=work, capsys=capsys, monkeypatch=monkeypatch)
    if refused:
        assert r.returncode == 2 and r.stderr == (f"homocal: error: trap.json: image: vertex {i} = [{u}, {trap['image'][i][1]}] "
                                                  "lies outside the lens's 1280x720 frame (--camera-json): the "
                                                  "trapezoid was clicked on another camera's frame\n")
        assert not (work / "c.json").exists()
    else:
        assert r.returncode == 0, r.stderr


def test_apply_marks_feet_beyond_the_fold(work, capsys, monkeypatch):
    fit_apply(work, capsys, monkeypatch, "horizon", "--camera-json", "lens.json")
    (work / "feet.csv").write_text("u,v\n-5000,-5000\n640,500\n")
    r = homocal_main("apply", "c.json", "--points", "feet.csv", "-o", "-", cwd=work, capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 0 and [line.split(",")[-1] for line in r.stdout.split()[1:]] == ["bad_input", "ok"]


def test_undistort_boxes_keeps_foot_and_head():
    """The foot point and head row of an undistorted box are the undistorted bottom and top centres; its width
    the undistorted bottom edge's."""
    boxes = np.array([[100.0, 300.0, 140.0, 420.0], [1000.0, 200.0, 1030.0, 290.0], [600.0, 400.0, 680.0, 700.0]])
    out = undistort_boxes(box_edges(boxes, convention="homocal"), LENS)
    x1, y1, x2, y2 = boxes.T
    foot = LENS.undistort_points(np.column_stack([(x1 + x2) / 2, y2]))
    head = LENS.undistort_points(np.column_stack([(x1 + x2) / 2, y1]))
    np.testing.assert_allclose(LENS.distort_points(np.column_stack([(out[:, 0] + out[:, 2]) / 2, out[:, 3]])),
                               np.column_stack([(x1 + x2) / 2, y2]), atol=1e-6)
    np.testing.assert_allclose(out[:, 1], head[:, 1], atol=1e-9)
    np.testing.assert_allclose(out[:, 3], foot[:, 1], atol=1e-9)
    width = np.hypot(*(LENS.undistort_points(np.column_stack([x2, y2])) - LENS.undistort_points(np.column_stack([x1, y2]))).T)
    np.testing.assert_allclose(out[:, 2] - out[:, 0], width, rtol=1e-12)
    assert undistort_boxes(boxes, None).tobytes() == boxes.tobytes()


def test_read_boxes_undistorts_with_the_lens_and_refuses_a_distorted_dataset_without_it(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    from homocal import read_boxes

    boxes = np.array([[100.0, 300.0, 140.0, 420.0], [1000.0, 200.0, 1030.0, 290.0]])
    pq.write_table(pa.table({"detector": ["segmentation"] * 2, "frame": [0, 1], **dict(zip(("x1", "y1", "x2", "y2"), boxes.T))}),
                   tmp_path / "detections.parquet")
    (tmp_path / "camera.json").write_text(json.dumps({"width": 1280, "height": 720, "K": CAM.K.tolist(),
                                                      "distortion": LENS.distortion.tolist()}))
    with pytest.raises(ValueError, match="the camera.json beside it has a lens distortion"):
        read_boxes(tmp_path / "detections.parquet")
    read = read_boxes(tmp_path / "detections.parquet", lens=LENS)
    np.testing.assert_array_equal(read.xyxy, undistort_boxes(boxes, LENS))
    assert read.lens == LENS and read.image_size == (1280, 720)
    with pytest.raises(ValueError, match=r"image size \[1280, 720\] differs from the lens's \[640, 360\]"):
        read_boxes(tmp_path / "detections.parquet", lens=Lens(CAM.K, LENS.distortion, (640, 360)))

"""homocal.dataset reads a real simgen dataset through data_schema.md alone."""
import json
import shutil

import numpy as np
import pyarrow.parquet as pq
import pytest

from homocal.dataset import load_dataset


def project(camera: dict, xy: np.ndarray) -> np.ndarray:
    """K (R X + t) for ground points, from camera.json's K, R, t (not its homographies)."""
    K, R, t = (np.asarray(camera[k], dtype=float) for k in ("K", "R", "t"))
    cam = np.column_stack([xy, np.zeros(len(xy))]) @ R.T + t
    uvw = cam @ K.T
    return uvw[:, :2] / uvw[:, 2:]


def test_calibration_points(tiny_dataset):
    ds = load_dataset(tiny_dataset)
    image, ground, distance = ds.calibration_points("exact")
    assert len(distance) == 40 and np.allclose(distance, np.arange(5.0, 45.0))
    np.testing.assert_allclose(ground, np.column_stack([np.zeros(40), distance]))
    np.testing.assert_allclose(image, project(ds.camera, ground), atol=1e-9)
    detected, _, _ = ds.calibration_points("segmentation")
    # the detected box's bottom is the near edge of the soles (data_schema.md): at most 0.125 m nearer the camera
    # than the foot point of a person standing with its feet together, on a pixel boundary (y2 = row + 0.5)
    near_soles = project(ds.camera, ground - [0.0, 0.125])
    assert np.abs(detected[:, 0] - image[:, 0]).max() < 1.0
    assert (detected[:, 1] > image[:, 1] - 1.0).all() and (detected[:, 1] < near_soles[:, 1] + 1.0).all()


@pytest.mark.parametrize("source", ["exact", "segmentation", "rgb"])
def test_test_points_map_near_their_truth(tiny_dataset, source):
    ds = load_dataset(tiny_dataset)
    image, ground = ds.test_points(source)
    H = np.asarray(ds.camera["image_to_ground"])
    p = np.column_stack([image, np.ones(len(image))]) @ H.T
    err = np.hypot(*(p[:, :2] / p[:, 2:] - ground).T)
    if source == "exact":
        assert err.max() < 1e-6
    else:
        assert np.median(err) < 1.0  # detected foot points: close, not exact


def test_subsample_is_seeded(tiny_dataset):
    ds = load_dataset(tiny_dataset)
    a, _ = ds.test_points("exact", n=50, seed=1)
    b, _ = ds.test_points("exact", n=50, seed=1)
    c, _ = ds.test_points("exact", n=50, seed=2)
    assert len(a) == 50 and np.array_equal(a, b) and not np.array_equal(a, c)


def test_hand_placed_trapezoid_is_near_exact(tiny_dataset):
    ds = load_dataset(tiny_dataset)
    exact = np.asarray(ds.trapezoids["exact"]["image"])
    assert 0 < np.abs(ds.trapezoid_image - exact).max() <= 2.5
    np.testing.assert_allclose(ds.site_map.to_metres(ds.trapezoids["exact"]["map"]), ds.trapezoids["ground_m"], atol=1e-9)


def test_unknown_detector(tiny_dataset):
    with pytest.raises(ValueError, match="no detections from detector 'yolo'"):
        load_dataset(tiny_dataset).test_points("yolo")


def break_copy(src, tmp_path, how):
    dst = tmp_path / "broken"
    shutil.copytree(src, dst)
    if how == "no calibration":
        (dst / "calibration.parquet").unlink()
    elif how == "no column":
        table = pq.read_table(dst / "gt.parquet")
        pq.write_table(table.drop(["in_frame"]), dst / "gt.parquet")
    elif how == "incomplete":
        manifest = json.loads((dst / "manifest.json").read_text())
        (dst / "manifest.json").write_text(json.dumps({**manifest, "complete": False}))
    elif how == "no trapezoid key":
        (dst / "trapezoids.json").write_text(json.dumps({"exact": {}}))
    elif how == "camera.json UTF-16":
        (dst / "camera.json").write_bytes((dst / "camera.json").read_text().encode("utf-16"))
    elif how == "gt.parquet garbage":
        (dst / "gt.parquet").write_bytes(b"PAR1 not a Parquet file")
    elif how == "calibration ground NaN":
        table = pq.read_table(dst / "calibration.parquet")
        x = table.column("x").to_numpy().copy()
        x[2] = float("nan")
        pq.write_table(table.set_column(table.schema.get_field_index("x"), "x", [x]), dst / "calibration.parquet")
    return dst


@pytest.mark.parametrize(
    "how,message",
    [("no calibration", "missing calibration.parquet"), ("no column", "missing column.*in_frame"),
     ("incomplete", "not complete"), ("no trapezoid key", "missing key 'hand_placed'"),
     ("camera.json UTF-16", r"camera.json: not valid JSON"), ("gt.parquet garbage", r"gt.parquet: not a readable Parquet file"),
     ("calibration ground NaN", r"calibration objects \[2\] have no exact foot point or no finite ground position")],
)  # fmt: skip
def test_bad_datasets_are_named(tiny_dataset, tmp_path, how, message):
    with pytest.raises(ValueError, match=message):
        load_dataset(break_copy(tiny_dataset, tmp_path, how)).calibration_points()


def test_max_distance_keeps_the_operating_range(tiny_dataset):
    ds = load_dataset(tiny_dataset)
    _, every = ds.test_points("exact")
    _, near = ds.test_points("exact", max_distance=20.0)
    d = np.hypot(*every.T)
    assert len(near) == np.sum(d <= 20.0) and 0 < len(near) < len(every)
    assert np.hypot(*near.T).max() <= 20.0

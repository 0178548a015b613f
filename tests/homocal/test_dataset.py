"""homocal.dataset reads a real simgen dataset through data_schema.md alone."""
import json
import shutil

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

from homocal.dataset import POSE_COLUMNS, calibration_source, load_dataset, read_pose_track
from synthetic_dataset import make_moving, pose_columns

TABLES = ("gt.parquet", "detections.parquet", "calibration.parquet")


def camera_json(dataset) -> dict:
    """The dataset's camera.json as plain JSON (not through homocal's reader)."""
    return json.loads((dataset / "camera.json").read_text())


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
    np.testing.assert_allclose(image, project(camera_json(tiny_dataset), ground), atol=1e-9)
    detected, _, _ = ds.calibration_points("segmentation")
    # the detected box's bottom is the near edge of the soles (data_schema.md): at most 0.125 m nearer the camera
    # than the foot point of a person standing with its feet together, on a pixel boundary (y2 = row + 0.5)
    near_soles = project(camera_json(tiny_dataset), ground - [0.0, 0.125])
    assert np.abs(detected[:, 0] - image[:, 0]).max() < 1.0
    assert (detected[:, 1] > image[:, 1] - 1.0).all() and (detected[:, 1] < near_soles[:, 1] + 1.0).all()


@pytest.mark.parametrize("source", ["exact", "segmentation", "rgb"])
def test_test_points_map_near_their_truth(tiny_dataset, source):
    ds = load_dataset(tiny_dataset)
    image, ground = ds.test_points(source)
    H = np.asarray(camera_json(tiny_dataset)["image_to_ground"])
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


@pytest.mark.parametrize("source", ["rgb", "hog", "Exact", "", "anything"])
def test_calibration_points_refuse_unknown_sources(tiny_dataset, source):
    with pytest.raises(ValueError, match=f"calibration points come from 'exact' or 'segmentation', not {source!r}"):
        load_dataset(tiny_dataset).calibration_points(source)


@pytest.mark.parametrize("foot_source,expected", [("exact", "exact"), ("segmentation", "segmentation"),
                                                  ("rgb", "segmentation"), ("hog", "segmentation")])
def test_calibration_source_of_a_foot_source(foot_source, expected):
    assert calibration_source(foot_source) == expected


def test_missing_values_are_nulls_where_the_schema_says(tiny_dataset):
    """data_schema.md: no float column holds a NaN; the missing values are nulls, exactly where a column says."""
    tables = {name: pq.read_table(tiny_dataset / name) for name in TABLES}
    for name, table in tables.items():
        for field in table.schema:
            if pa.types.is_floating(field.type):
                assert not pc.any(pc.is_nan(table.column(field.name))).as_py(), (name, field.name)
    gt, det = tables["gt.parquet"], tables["detections.parquet"]
    unseen = pc.equal(gt.column("visible_pixels"), 0)
    for c in ("x1", "y1", "x2", "y2"):
        assert pc.is_null(gt.column(c)).equals(unseen)
    assert gt.column("x1").null_count > 0  # agents out of view are in the tiny dataset
    assert not pc.any(pc.and_(pc.is_null(gt.column("u")), gt.column("in_frame"))).as_py()
    unmatched = pc.equal(det.column("agent_id"), -1)
    assert det.column("gt_t").null_count > 0
    for c in ("gt_t", "gt_x", "gt_y"):
        assert pc.is_null(det.column(c)).equals(unmatched)


def test_datasets_with_nan_read_as_with_nulls(tiny_dataset, tmp_path):
    """Datasets written before the null rule hold NaN instead: the loader gives the same points."""
    old = tmp_path / "nan"
    shutil.copytree(tiny_dataset, old)
    for name in TABLES:
        table = pq.read_table(old / name)
        for i, field in enumerate(table.schema):
            if pa.types.is_floating(field.type):
                table = table.set_column(i, field, pc.fill_null(table.column(i), np.nan))
        assert not any(table.column(i).null_count for i in range(table.num_columns))
        pq.write_table(table, old / name)
    new, before = load_dataset(tiny_dataset), load_dataset(old)
    for source in ("exact", "segmentation"):
        for a, b in zip(new.calibration_points(source), before.calibration_points(source)):
            np.testing.assert_array_equal(a, b)
    for source in ("exact", "segmentation", "rgb"):
        for a, b in zip(new.test_points(source), before.test_points(source)):
            assert len(a) > 0
            np.testing.assert_array_equal(a, b)


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
     ("camera.json UTF-16", r"camera.json: not a JSON file"), ("gt.parquet garbage", r"gt.parquet: not a readable Parquet file"),
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


# ---- camera_pose.parquet: the pose track of a camera that moves ----------------------------------
MANIFEST = {"steps_total": 6, "gt_dt": 0.05}


def test_pose_columns_are_the_ones_simgen_writes():
    from simgen.truth import CAMERA_POSE_SCHEMA

    assert POSE_COLUMNS == tuple(CAMERA_POSE_SCHEMA.names)


def test_pose_track_reads_the_table(tmp_path):
    columns = pose_columns(6)
    columns["horizon_a"], columns["horizon_b"] = np.full(6, 0.6), np.full(6, 0.8)  # a rolled camera's tilted line
    pq.write_table(pa.table(columns), tmp_path / "camera_pose.parquet")
    pose = read_pose_track(tmp_path / "camera_pose.parquet", MANIFEST)
    assert pose.step.tolist() == list(range(6)) and pose.tilt_deg.tolist() == [15.0] * 3 + [16.0] * 3
    np.testing.assert_array_equal(pose.t, columns["t"])  # the file's times, as written
    assert pose.horizon.shape == (6, 3) and not pose.horizon.flags.writeable
    rows = pose.horizon_rows(640.0)  # (640, row) lies on each line
    np.testing.assert_allclose(0.6 * 640.0 + 0.8 * rows + columns["horizon_c"], 0.0, atol=1e-9)


def _broken_pose(how: str) -> dict:
    columns = pose_columns(6)
    if how == "no column":
        del columns["horizon_c"]
    elif how == "rows":
        columns = pose_columns(5)
    elif how == "order":
        columns["step"] = columns["step"][::-1].copy()
    elif how == "t":
        columns["t"] = columns["t"] + 0.01
    elif how == "nan":
        columns["yaw_deg"][2] = np.nan
    elif how == "null":
        columns["tilt_deg"] = pa.array([15.0, None, 15.0, 16.0, 16.0, 16.0])
    elif how == "line":
        columns["horizon_b"] = np.full(6, 2.0)
    return columns


@pytest.mark.parametrize("how, message", [
    ("no column", "missing column.*horizon_c"),
    ("rows", r"one row per ground-truth step.*steps_total 6\), got 5 rows"),
    ("order", "one row per ground-truth step 0 .. steps_total - 1 in order"),
    ("t", r"t must be step \* gt_dt"),
    ("nan", "column yaw_deg has a value that is not a finite number"),
    ("null", "column tilt_deg has a value that is not a finite number"),
    ("line", r"hypot\(horizon_a, horizon_b\) = 1"),
])  # fmt: skip
def test_bad_pose_tables_are_refused_in_one_line(tmp_path, how, message):
    pq.write_table(pa.table(_broken_pose(how)), tmp_path / "camera_pose.parquet")
    with pytest.raises(ValueError, match=message) as e:
        read_pose_track(tmp_path / "camera_pose.parquet", MANIFEST)
    assert "\n" not in str(e.value) and str(e.value).startswith(str(tmp_path / "camera_pose.parquet"))


def test_a_dataset_has_a_pose_track_only_when_its_camera_moves(tiny_dataset, tmp_path):
    assert load_dataset(tiny_dataset).pose is None and not load_dataset(tiny_dataset).moving
    moving = make_moving(shutil.copytree(tiny_dataset, tmp_path / "moving"))
    steps = json.loads((tiny_dataset / "manifest.json").read_text())["steps_total"]
    ds = load_dataset(moving)
    assert ds.moving and len(ds.pose.t) == steps and ds.pose.horizon_rows(640.0)[-1] == 191.0
    (moving / "camera_pose.parquet").write_bytes(b"PAR1 not a Parquet file")
    with pytest.raises(ValueError, match="camera_pose.parquet: not a readable Parquet file"):
        load_dataset(moving)

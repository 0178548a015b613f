"""A box margin in homocal measure and GroundTracker: boxes told how much taller than their people they are give
the people's own boxes' table; a pedestrians correction's margin is the default; a box no taller is no foot."""
import json
from types import SimpleNamespace

import numpy as np
import pyarrow.parquet as pq
import pytest

from cli_run import homocal_main
from homocal.correctors import PedestrianCorrector
from homocal.correctors.base import load_corrector
from homocal.geometry import PinholeCamera, ViewTransformer
from homocal.measure import GroundTracker
from homocal.study.options import OptionError
from test_measure_cli import FPS, scene, walker_rows, write_csv  # noqa: F401 (scene: the fixture)

CAMERA = PinholeCamera()
GROUND = np.array([[-3.0, 40.0], [3.0, 40.0], [3.0, 10.0], [-3.0, 10.0]])
STATE = ["x", "y", "sigma_m", "x_smooth", "y_smooth", "vx", "vy", "speed_mps", "speed_sigma_mps"]


def taller(rows, margin):
    """The rows' boxes margin px taller, half at each end."""
    return [(f, k, x1, y1 - margin / 2, x2, y2 + margin / 2) for f, k, x1, y1, x2, y2 in rows]


def measure(scene, capsys, monkeypatch, correction, boxes, *extra):  # noqa: F811 (scene: the fixture)
    r = homocal_main("measure", correction, "--boxes", boxes, "--fps", str(FPS), "--out", "t.parquet",
                     "--foot-noise", "box-height", *extra, cwd=scene, capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 0, r.stderr
    return r.stdout, pq.read_table(scene / "t.parquet").to_pandas()


def people_boxes(margin):
    """80 standing people's boxes (80, 4) homocal edges seen by CAMERA, margin px taller than the people."""
    rng = np.random.default_rng(3)
    xy = np.column_stack([rng.uniform(-6, 6, 80), rng.uniform(8, 40, 80)])
    foot = CAMERA.project(np.column_stack([xy, np.zeros(80)]))
    head = CAMERA.project(np.column_stack([xy, rng.normal(1.65, 0.07, 80)]))
    return np.column_stack([foot[:, 0] - 10, head[:, 1] - margin / 2, foot[:, 0] + 10, foot[:, 1] + margin / 2])


def pedestrians_correction(path, margin):
    """A pedestrians correction of the walkers' camera fitted with box_margin_px=margin (its own people's boxes
    that much taller), saved to path."""
    boxes = people_boxes(margin)
    PedestrianCorrector(box_margin_px=margin).fit(
        ViewTransformer(CAMERA.project_ground(GROUND), GROUND), boxes, convention="homocal", track_ids=np.arange(80),
        K=CAMERA.K, camera_height_m=4.0, image_size=(CAMERA.width, CAMERA.height)).save(path)


def test_taller_boxes_told_their_margin_measure_as_the_people(scene, capsys, monkeypatch):  # noqa: F811 (scene: the fixture)
    """--box-margin 3 on boxes 3 px taller writes the table of the walkers' own boxes (their u, v, ground points,
    sigmas and speeds); untold, the foot points lie 1.5 px low."""
    write_csv(scene / "tall.csv", taller(walker_rows(), 3.0))
    _, own = measure(scene, capsys, monkeypatch, "trap.json", "boxes.csv")
    out, told = measure(scene, capsys, monkeypatch, "trap.json", "tall.csv", "--box-margin", "3")
    assert ", 3 px box margin at 10 fps" in out and "not measured" not in out
    np.testing.assert_allclose(told[STATE + ["u", "v"]], own[STATE + ["u", "v"]], rtol=1e-9, atol=1e-12)
    _, untold = measure(scene, capsys, monkeypatch, "trap.json", "tall.csv")
    np.testing.assert_allclose(untold.v - own.v, 1.5, atol=1e-9)


def test_fit_takes_the_margin_and_says_so(scene, capsys, monkeypatch):  # noqa: F811 (scene: the fixture)
    """homocal fit --method pedestrians --box-margin 2 on boxes 2 px taller: the fit of the people's own boxes
    (Python's, no margin), its line naming the margin, the correction keeping it."""
    boxes = people_boxes(2.0)
    rows = "".join(f"{k},{x1 + 0.5!r},{y1 + 0.5!r},{x2 + 0.5!r},{y2 + 0.5!r}\n" for k, (x1, y1, x2, y2) in enumerate(boxes.tolist()))
    (scene / "people.csv").write_text("frame,x1,y1,x2,y2\n" + rows)  # corners: homocal's edges + 0.5
    (scene / "cam.json").write_text(json.dumps({"width": CAMERA.width, "height": CAMERA.height, "K": CAMERA.K.tolist()}))
    r = homocal_main("fit", "--trapezoid", "trap.json", "--method", "pedestrians", "--boxes", "people.csv",
                     "--camera-json", "cam.json", "--camera-height", "4", "--box-margin", "2", "-o", "c.json",
                     cwd=scene, capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 0, r.stderr
    assert "Boxes: 80 read (each less a 2 px box margin)" in r.stdout
    fitted = load_corrector(scene / "c.json")
    own = PedestrianCorrector().fit(ViewTransformer(CAMERA.project_ground(GROUND), GROUND), people_boxes(0.0),
                                    convention="homocal", frames=np.arange(80), K=CAMERA.K, camera_height_m=4.0,
                                    image_size=(CAMERA.width, CAMERA.height))
    assert fitted.box_margin_px == 2.0 and fitted.horizon_row_ == pytest.approx(own.horizon_row_, abs=1e-4)


def test_a_pedestrians_corrections_margin_is_the_default(scene, capsys, monkeypatch):  # noqa: F811 (scene: the fixture)
    pedestrians_correction(scene / "c.json", 2.0)
    assert json.loads((scene / "c.json").read_text())["params"]["box_margin_px"] == 2.0
    out, by_default = measure(scene, capsys, monkeypatch, "c.json", "boxes.csv")
    assert "of c.json, 2 px box margin at 10 fps" in out
    _, given = measure(scene, capsys, monkeypatch, "c.json", "boxes.csv", "--box-margin", "0")
    np.testing.assert_allclose(given.v - by_default.v, 1.0, atol=1e-9)  # the margin's half off the bottom edge
    _, trapezoid = measure(scene, capsys, monkeypatch, "trap.json", "boxes.csv")  # a trapezoid has none
    np.testing.assert_allclose(trapezoid.v, given.v, atol=1e-9)


def test_a_box_no_taller_than_the_margin_is_no_foot(scene, capsys, monkeypatch):  # noqa: F811 (scene: the fixture)
    rows = walker_rows()
    f, k, x1, y1, x2, y2 = rows[5]
    rows[5] = (f, k, x1, y2 - 2, x2, y2)  # 2 px tall
    write_csv(scene / "short.csv", rows)
    out, table = measure(scene, capsys, monkeypatch, "trap.json", "short.csv", "--box-margin", "2")
    assert "Feet not measured (predicted through): 1 short." in out
    assert len(table) == len(rows) and table.foot.tolist() == ["used"] * 5 + ["short"] + ["used"] * (len(rows) - 6)


@pytest.mark.parametrize("value", ["nan", "inf", "-1", "65", "1e308", "two", ""])
def test_bad_margin_is_one_line_and_writes_nothing(scene, capsys, monkeypatch, value):  # noqa: F811 (scene: the fixture)
    before = sorted(p.name for p in scene.rglob("*"))
    r = homocal_main("measure", "trap.json", "--boxes", "boxes.csv", "--fps", "10", "--out", "t.parquet",
                     "--box-margin", value, cwd=scene, capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    assert f"argument --box-margin: expected a number in [0, 64] (px), got '{value}'" in r.stderr
    assert sorted(p.name for p in scene.rglob("*")) == before


def live(tracker, rows):
    """{(frame, track): (state, foot)} of GroundTracker fed the rows frame by frame."""
    rows = np.array(rows, float)
    out = {}
    for f in np.unique(rows[:, 0]):
        at = rows[:, 0] == f
        state = tracker.update(SimpleNamespace(xyxy=rows[at, 2:], tracker_id=rows[at, 1].astype(int)), int(f))
        for i, k in enumerate(state.tracker_id):
            out[(int(f), int(k))] = (state.xy_filtered[i], state.speed_mps[i], state.speed_sigma_mps[i], state.foot[i])
    return out


def test_ground_tracker_takes_the_margin(tmp_path):
    """GroundTracker(box_margin_px=3) on boxes 3 px taller: the walkers' own boxes' states; a pedestrians
    correction's margin by default; a box no taller, foot "short"; bad margins refused."""
    mapping = ViewTransformer(CAMERA.project_ground(GROUND), GROUND)
    own = live(GroundTracker(mapping, FPS, foot_noise="box-height"), walker_rows())
    told = live(GroundTracker(mapping, FPS, foot_noise="box-height", box_margin_px=3.0), taller(walker_rows(), 3.0))
    for key, (xy, speed, sigma, foot) in own.items():
        np.testing.assert_allclose(told[key][0], xy, rtol=1e-9)
        np.testing.assert_allclose(told[key][1:3], [speed, sigma], rtol=1e-9, atol=1e-12)
        assert told[key][3] == foot == "used"
    pedestrians_correction(tmp_path / "c.json", 2.0)
    assert GroundTracker(load_corrector(tmp_path / "c.json"), FPS).box_margin_px == 2.0
    rows = walker_rows()
    f, k, x1, y1, x2, y2 = rows[5]
    rows[5] = (f, k, x1, y2 - 2, x2, y2)
    assert live(GroundTracker(mapping, FPS, box_margin_px=2.0), rows)[(f, k)][3] == "short"
    for bad in (float("nan"), -1.0, 65.0, "2", True):
        with pytest.raises(OptionError, match="box_margin_px"):
            GroundTracker(mapping, FPS, box_margin_px=bad)

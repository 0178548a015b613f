"""A box cut by the frame is a property of the camera's own pixels: on a pincushion lens (k1 = +0.1: undistorted
points move inward) and on scene3's barrel lens (they move outward), every path that fits from boxes
(PedestrianCorrector.fit(lens=), homocal fit --method pedestrians --camera-json, homocal watch from a file and from
standard input, the page's fit and its horizon over time) flags exactly the boxes that the raw-pixel rule,
computed here by hand, flags."""
from __future__ import annotations

import io
import json
import tomllib
from pathlib import Path

import cv2
import numpy as np
import pyarrow.parquet as pq
import pytest
from cli_run import homocal_main

from homocal.correctors.pedestrians import PedestrianCorrector, implied_horizon_rows
from homocal.geometry.boxes import BORDER_PX
from homocal.geometry import Lens, PinholeCamera, SiteMap, ViewTransformer
from homocal.geometry.boxes import hidden_feet, undistort_boxes
from homocal.ui import api
from homocal.ui.session import from_files, use_lens
from homocal.watch import OnlineCalibrator

CAM = PinholeCamera()  # 1280x720, 95 degrees, 4 m high, 15 degrees down
W, H = CAM.width, CAM.height
SCENE3 = Path(__file__).resolve().parents[2] / "simgen" / "scenes" / "scene3" / "scene.toml"
LENSES = {"pincushion": [0.1, 0.0, 0.0, 0.0, 0.0],
          "scene3": tomllib.loads(SCENE3.read_text())["camera"]["distortion"]}
GROUND = np.array([[-3.5, 30.0], [3.5, 30.0], [3.5, 8.0], [-3.5, 8.0]])  # TL, TR, BR, BL, metres
SITE = SiteMap(10.0, (200.0, 700.0))
PEOPLE, BOXES_EACH, AT_ONCE, FPS = 150, 5, 10, 5  # each person: one box in 5 frames (the watch's PERSON_BOXES)
PRIOR = {"height_mean_m": 1.70, "height_sd_m": 0.07}


def scene(name: str, seed: int = 0):
    """(lens, boxes (PEOPLE, 4) homocal edges in the camera's pixels, clicked trapezoid's image corners (4, 2)):
    people N(1.70, 0.07) m tall on the ground ahead, their foot and head points projected by the pinhole and
    distorted by the lens (cv2.projectPoints' model), a box 0.5 m wide, clipped to the frame as a detector's
    box of a person the frame cuts."""
    lens = Lens(CAM.K, LENSES[name], (W, H))
    rng = np.random.default_rng(seed)
    n = 4 * PEOPLE
    xy = np.column_stack([rng.uniform(-14, 14, n), rng.uniform(3, 40, n)])
    foot, head = (lens.distort_points(CAM.project(np.column_stack([xy, z]))) for z in (np.zeros(n), rng.normal(1.70, 0.07, n)))
    half = 0.25 * CAM.focal_px / xy[:, 1]
    boxes = np.clip(np.column_stack([foot[:, 0] - half, head[:, 1], foot[:, 0] + half, foot[:, 1]]), -0.5,
                    [W - 0.5, H - 0.5, W - 0.5, H - 0.5])
    seen = (boxes[:, 2] - boxes[:, 0] > 2) & (boxes[:, 3] - boxes[:, 1] > 2)
    return lens, boxes[seen][:PEOPLE], lens.distort_points(CAM.project_ground(GROUND))


def cut_by_frame(boxes: np.ndarray) -> np.ndarray:
    """The raw-pixel rule by hand: an edge within BORDER_PX of the frame's edge (-0.5 .. W - 0.5, H - 0.5)."""
    x1, y1, x2, y2 = boxes.T
    return (x1 <= -0.5 + BORDER_PX) | (y1 <= -0.5 + BORDER_PX) | (x2 >= W - 0.5 - BORDER_PX) | (y2 >= H - 0.5 - BORDER_PX)


def frames_of(n: int) -> np.ndarray:
    """(n * BOXES_EACH,) frames: AT_ONCE people at a time, each in BOXES_EACH consecutive frames."""
    person = np.repeat(np.arange(n), BOXES_EACH)
    return (person // AT_ONCE) * BOXES_EACH + np.tile(np.arange(BOXES_EACH), n)


def write_inputs(folder: Path, name: str):
    """trap.json, lens.json and boxes.csv (corner pixels, track ids, in time order) of scene(name); the scene."""
    lens, boxes, image = scene(name)
    (folder / "trap.json").write_text(json.dumps({"image": image.tolist(), "map": GROUND.tolist()}))
    (folder / "lens.json").write_text(json.dumps(lens.to_dict()))
    people = np.repeat(np.arange(len(boxes)), BOXES_EACH)
    frames = frames_of(len(boxes))
    order = np.argsort(frames, kind="stable")
    text = "frame,x1,y1,x2,y2,track_id\n" + "".join(
        f"{frames[i]},{','.join(repr(float(v) + 0.5) for v in boxes[people[i]])},{people[i]}\n" for i in order)
    (folder / "boxes.csv").write_text(text)
    return lens, boxes, image


FLAGS = ["--trapezoid", "trap.json", "--camera-json", "lens.json", "--camera-height", "4", "--height-mean", "1.70",
         "--height-sd", "0.07"]


@pytest.mark.parametrize("name", LENSES)
def test_the_old_rule_differs_here(name):
    """The scenes bite: the rule applied to the undistorted boxes (the old command's, watch's and page's) flags other
    boxes than the raw-pixel rule (pincushion: cut boxes missed; barrel: whole boxes lost), and both kinds exist."""
    lens, boxes, _ = scene(name)
    raw, undistorted = cut_by_frame(boxes), cut_by_frame(undistort_boxes(boxes, lens))
    assert 0 < raw.sum() < len(boxes) // 4 and (raw != undistorted).sum() >= 3
    assert ((raw & ~undistorted) if name == "pincushion" else (undistorted & ~raw)).sum() >= 3 or raw.sum() < 3


@pytest.mark.parametrize("name", LENSES)
def test_fit_and_the_command_flag_the_raw_pixels(tmp_path, capsys, monkeypatch, name):
    """PedestrianCorrector.fit(lens=) marks exactly the hand rule's boxes "border"; homocal fit on the same boxes
    (a CSV, the lens from --camera-json) counts the same and fits the same horizon."""
    lens, boxes, image = write_inputs(tmp_path, name)
    raw = cut_by_frame(boxes)
    frames, people = frames_of(len(boxes)), np.repeat(np.arange(len(boxes)), BOXES_EACH)
    own = PedestrianCorrector(**PRIOR).fit(ViewTransformer(lens.undistort_points(image), GROUND), boxes[people],
                                          convention="homocal", frames=frames, track_ids=people, K=CAM.K,
                                          camera_height_m=4.0, image_size=(W, H), lens=lens)
    np.testing.assert_array_equal(own.box_status_ == "border", raw[people])
    r = homocal_main("fit", "--method", "pedestrians", *FLAGS, "--boxes", "boxes.csv", "-o", "c.json", cwd=tmp_path,
                     capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 0, r.stderr
    fitted = json.loads((tmp_path / "c.json").read_text())["fitted"]
    assert fitted["n_border"] == BOXES_EACH * raw.sum() == own.n_border_
    assert fitted["horizon_row"] == pytest.approx(own.horizon_row_, abs=1e-6)


def watched_rows(lens: Lens, boxes: np.ndarray) -> np.ndarray:
    """The implied horizon rows (implied_horizon_rows, of the box undistorted) of the people off the border by the
    hand rule: one per track (its boxes are one box), but a box that no tilt gives the prior's mean height (NaN)
    and a box whose feet a nearer person of its frames may hide (hidden_feet, on the raw boxes: the watch's rule)."""
    hidden = hidden_feet(boxes, np.arange(len(boxes)) // AT_ONCE)  # AT_ONCE people share their frames
    undistorted = undistort_boxes(boxes[~cut_by_frame(boxes) & ~hidden], lens)
    rows = implied_horizon_rows(undistorted[:, 3], undistorted[:, 1], CAM.focal_px, CAM.K[1, 2], 4.0, 1.70)[0]
    assert np.isfinite(rows).mean() > 0.9
    return rows[np.isfinite(rows)]


@pytest.mark.parametrize("name", LENSES)
def test_watch_flags_the_raw_pixels_from_a_file_and_standard_input(tmp_path, capsys, monkeypatch, name):
    """homocal watch gives one person per track off the border by the hand rule, whose implied horizon row is that of
    its box undistorted, from a file and from standard input."""
    lens, boxes, _ = write_inputs(tmp_path, name)
    rows = watched_rows(lens, boxes)
    watch = ["watch", *FLAGS, "--fps", str(FPS)]
    r = homocal_main(*watch, "--boxes", "boxes.csv", "--out", "file", cwd=tmp_path, capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 0, r.stderr
    monkeypatch.setattr("sys.stdin", io.StringIO((tmp_path / "boxes.csv").read_text()))
    r = homocal_main(*watch, "--boxes", "-", "--out", "stdin", cwd=tmp_path, capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 0, r.stderr
    for out in ("file", "stdin"):
        assert json.loads((tmp_path / out / "moves.json").read_text())["moves"] == []
        got = pq.read_table(tmp_path / out / "horizon.parquet").column("person_row_px").to_numpy()
        np.testing.assert_allclose(np.sort(got), np.sort(rows), atol=1e-6)


@pytest.mark.parametrize("name", LENSES)
def test_the_page_flags_the_raw_pixels(tmp_path, name):
    """The page's fit draws as "border" exactly the hand rule's boxes (as the file gave them) and counts them in its
    correction; its horizon over time has the people (implied horizon rows) homocal watch has."""
    lens, boxes, image = write_inputs(tmp_path, name)
    raw = cut_by_frame(boxes)
    cv2.imwrite(str(tmp_path / "frame.png"), np.full((H, W, 3), 90, np.uint8))
    cv2.imwrite(str(tmp_path / "map.png"), np.full((800, 400, 3), 60, np.uint8))
    (tmp_path / "out").mkdir()
    session = from_files(tmp_path / "frame.png", tmp_path / "map.png", SITE, (0.0, 0.0), tmp_path / "out",
                         boxes=tmp_path / "boxes.csv", fps=FPS)
    use_lens(session, lens, tmp_path / "lens.json")
    req = {"trapezoid": {"image": image.tolist(), "map": SITE.to_pixels(GROUND).tolist()}, "camera_origin": [0, 0],
           "points": [], "method": "pedestrians", "camera_height_m": 4.0, **PRIOR}
    fitted = api.fit(session, req)
    drawn = np.array(fitted["boxes"]["border"]).reshape(-1, 8, 2)
    corners = np.column_stack([drawn[:, 0], drawn[:, 4]])  # top-left, bottom-right: x1, y1, x2, y2
    np.testing.assert_allclose(np.unique(corners, axis=0), np.unique(np.repeat(boxes[raw], BOXES_EACH, 0), axis=0),
                               atol=0.051)  # rounded to 0.1 px
    assert len(corners) == fitted["correction"]["fitted"]["n_border"] == BOXES_EACH * raw.sum()
    np.testing.assert_allclose(np.sort(api.watch(session, req)["people"]["row"]), np.sort(watched_rows(lens, boxes)),
                               atol=1e-6)


def test_the_watch_refuses_a_box_beyond_the_lens_fold():
    """OnlineCalibrator(lens=) undistorts every box it is given (as read_boxes checks a file's): one no ray of the lens
    reaches (beyond the fold of a lens that folds 1900 px out, test_lens_cli's) is refused naming its frame."""
    folding = Lens(CAM.K, [-0.2, 0.04, 5e-4, -3e-4, -0.002], (W, H))
    calibrator = OnlineCalibrator(CAM.K, 4.0, FPS, (W, H), lens=folding)
    calibrator.update(0, np.array([[600.0, 300.0, 640.0, 400.0]]))
    with pytest.raises(ValueError, match=r"^frame 1: xyxy\[0\] = \[3000.0, 300.0, 3100.0, 500.0\] lies beyond the lens's fold"):
        calibrator.update(1, np.array([[3000.0, 300.0, 3100.0, 500.0]]))

"""homocal ui on a distorted camera: clicks are the frame's pixels, the overlays are drawn through the lens
(checked with OpenCV's own inverse and the pinhole's ground mapping)."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from homocal.geometry import Lens, PinholeCamera, SiteMap
from homocal.ui import api
from homocal.ui.session import from_files, use_lens

CAM = PinholeCamera()
LENS = Lens(CAM.K, [-0.2, 0.04, 5e-4, -3e-4, -0.002], (1280, 720))
SITE = SiteMap(10.0, (200.0, 700.0))
GROUND = np.array([[-3.5, 40.0], [3.5, 40.0], [3.5, 10.0], [-3.5, 10.0]])
REF_G = np.array([[0.0, 8.0], [1.0, 20.0], [-1.0, 35.0]])


def seen(xy):
    return LENS.distort_points(CAM.project_ground(xy))


def opencv_undistort(pixels) -> np.ndarray:
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
    q = np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
    return cv2.undistortPoints(q, CAM.K, LENS.distortion, P=CAM.K, criteria=criteria)[:, 0, :]


def pinhole_ground(undistorted_px) -> np.ndarray:
    h = np.column_stack([undistorted_px, np.ones(len(undistorted_px))]) @ CAM.image_to_ground.T
    return h[:, :2] / h[:, 2:]


@pytest.fixture
def session(tmp_path):
    frame, site_map = tmp_path / "frame.png", tmp_path / "map.png"
    cv2.imwrite(str(frame), np.full((720, 1280, 3), 90, np.uint8))
    cv2.imwrite(str(site_map), np.full((800, 400, 3), 60, np.uint8))
    (tmp_path / "out").mkdir()
    s = from_files(frame, site_map, SITE, (0.0, 0.0), tmp_path / "out")
    (tmp_path / "lens.json").write_text(json.dumps(LENS.to_dict()))
    use_lens(s, LENS, tmp_path / "lens.json")
    return s


REQ = {"trapezoid": {"image": seen(GROUND).tolist(), "map": SITE.to_pixels(GROUND).tolist()}, "camera_origin": [0, 0],
       "points": np.column_stack([seen(REF_G), REF_G]).tolist(), "method": "horizon"}


def test_grid_and_horizon_are_drawn_through_the_lens(session):
    view = api.view(session, REQ)
    a, b, c = CAM.horizon
    shown = np.asarray(view["horizon"])
    inside = shown[(shown >= -0.5).all(axis=1) & (shown <= [1279.5, 719.5]).all(axis=1)]
    assert len(inside) > 10 and np.ptp(inside[:, 1]) > 10  # curved on the frame
    assert np.abs(opencv_undistort(inside) @ [a, b] + c).max() < 0.1  # on the pinhole's horizon (rounded to 0.1 px)
    assert len(view["grid"]["major"]) > 3
    for line in view["grid"]["major"]:  # every vertex on its 10 m line to 0.3 frame px, as test_api's pinhole test
        q = np.asarray(line)
        g0, gu, gv = (pinhole_ground(opencv_undistort(q + d)) for d in ([0, 0], [0.5, 0], [0, 0.5]))
        metres_per_px = np.maximum(np.hypot(*(gu - g0).T), np.hypot(*(gv - g0).T)) / 0.5
        off = np.abs(g0 - np.round(g0 / 10.0) * 10.0).max(axis=0)
        assert (off / metres_per_px.max()).min() < 0.3, line[:3]


def test_clicks_and_points_are_undistorted(session, tmp_path):
    located = api.locate(session, {**REQ, "point": seen([[3.0, 20.0]])[0].tolist()})
    np.testing.assert_allclose(located["ground"], [3.0, 20.0], atol=1e-6)
    fitted = api.fit(session, REQ)
    np.testing.assert_allclose(fitted["mapped"], REF_G, atol=1e-6)
    assert fitted["correction"]["lens"] == LENS.to_dict()
    saved = api.save(session, REQ)
    trap = json.loads((session.out_dir / api.TRAPEZOID_FILE).read_text())
    np.testing.assert_array_equal(trap["image"], REQ["trapezoid"]["image"])
    assert trap["image_size"] == [1280, 720]
    assert f"--camera-json {tmp_path / 'lens.json'}" in saved["command"]


def test_a_lens_of_another_frame_is_refused(session):
    with pytest.raises(ValueError, match=r"lens's image size \[1920, 1080\] differs from the frame's \[1280, 720\]"):
        use_lens(session, Lens(CAM.K, LENS.distortion, (1920, 1080)), "hd.json")


def test_boxes_are_drawn_on_the_frame_in_its_pixels(session, tmp_path):
    """The people's boxes a pedestrians fit read are drawn as the file gave them, in the frame's pixels (the fit
    undistorts them): each outline's bottom midpoint is the foot point the file gave (the distorted frame's)."""
    rng = np.random.default_rng(1)
    ground = np.column_stack([rng.uniform(-4, 4, 60), rng.uniform(8, 30, 60)])
    foot = seen(ground)
    head = LENS.distort_points(CAM.project(np.column_stack([ground, rng.normal(1.75, 0.07, 60)])))
    half = 0.25 * CAM.focal_px / ground[:, 1]
    boxes = np.column_stack([foot[:, 0] - half, head[:, 1], foot[:, 0] + half, foot[:, 1]])  # homocal edges
    lines = ["frame,x1,y1,x2,y2,track_id"] + [f"0,{','.join(repr(float(x) + 0.5) for x in b)},{i}"
                                              for i, b in enumerate(boxes)]  # corner pixels
    (tmp_path / "boxes.csv").write_text("\n".join(lines) + "\n")
    s = from_files(tmp_path / "frame.png", tmp_path / "map.png", SITE, (0.0, 0.0), session.out_dir,
                   boxes=tmp_path / "boxes.csv")
    use_lens(s, LENS, tmp_path / "lens.json")
    drawn = api.fit(s, {**REQ, "points": [], "method": "pedestrians", "camera_height_m": 4.0})["boxes"]
    outlines = np.array(drawn["used"] + drawn["outlier"] + drawn["border"])
    assert outlines.shape == (60, 8, 2)
    bottom = outlines[:, 5]
    order = np.argsort(bottom[:, 0])
    np.testing.assert_allclose(bottom[order], foot[np.argsort(foot[:, 0])], atol=0.06)  # rounded to 0.1 px
    assert np.abs(opencv_undistort(foot) - foot).max() > 5  # the undistorted feet are elsewhere: the check bites


def test_error_bars_take_the_clicks_on_the_frame(session):
    """The page's error bars before any fit are the trapezoid's through the session's lens (the clicks err on the
    distorted frame): the probe's ellipse axes equal ground_uncertainty(..., lens=) at the undistorted point, and
    differ from the lens-blind ones."""
    from homocal.geometry import ViewTransformer
    from homocal.uncertainty import ground_uncertainty

    point = seen([[2.0, 30.0]])[0]
    bars = api.locate(session, {**REQ, "point": point.tolist()})["errorbars"]
    transformer = ViewTransformer(opencv_undistort(REQ["trapezoid"]["image"]), GROUND)
    q = opencv_undistort([point])
    with_lens, blind = (np.sqrt(np.linalg.eigvalsh(ground_uncertainty(transformer, q, lens=lens)[0]))[::-1]
                        for lens in (LENS, None))
    np.testing.assert_allclose(bars["sigma"][0], with_lens, rtol=1e-4)
    assert np.abs(with_lens / blind - 1).max() > 100 * 1e-4  # the lens term is far beyond the agreement above

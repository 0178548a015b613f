"""`homocal ui` without a browser: the overlays against the pinhole camera, the JSON API over real HTTP (bad
requests, save, load), and the command line's errors."""
from __future__ import annotations

import http.client
import json
import os
import re
import shlex
import socket
import subprocess
import sys
import threading
import urllib.error
import urllib.request
from pathlib import Path

import cv2
import imageio.v2 as imageio
import numpy as np
import pytest

from homocal.cli import main
from homocal.geometry import PinholeCamera, SiteMap, ViewTransformer
from homocal.ui import api, overlay
from homocal.ui.server import MAX_BODY, MAX_CONCURRENT, MAX_DEPTH, TOKEN_HEADER, UIServer
from homocal.ui.session import from_files, read_frame
from homocal.uncertainty import ground_uncertainty, max_trustworthy_range, sigma_radius

CAM = PinholeCamera()  # 1280x720, 4 m high, tilted 15 degrees down
W, H = CAM.width, CAM.height
SITE = SiteMap(10.0, (200.0, 700.0))
MAP_SIZE = (400, 800)  # covers x in [-20, 20] m, y in [-10, 70] m
GROUND = np.array([[-3.5, 40.0], [3.5, 40.0], [3.5, 10.0], [-3.5, 10.0]])  # TL, TR, BR, BL, metres
IMAGE = CAM.project_ground(GROUND)
MAP = SITE.to_pixels(GROUND)
REF_G = np.array([[0.0, 8.0], [1.0, 20.0], [-1.0, 35.0]])
REF_Q = CAM.project_ground(REF_G) + [[0.4, 1.0], [-0.3, 0.8], [0.2, 0.9]]  # feet found a little off
TRAP = {"image": IMAGE.tolist(), "map": MAP.tolist()}
POINTS = np.column_stack([REF_Q, REF_G]).tolist()


@pytest.fixture
def session(tmp_path: Path):
    frame, site_map = tmp_path / "frame.png", tmp_path / "map.png"
    cv2.imwrite(str(frame), np.full((H, W, 3), 90, np.uint8))
    cv2.imwrite(str(site_map), np.full((MAP_SIZE[1], MAP_SIZE[0], 3), 60, np.uint8))
    out = tmp_path / "out"
    out.mkdir()
    return from_files(frame, site_map, SITE, (0.0, 0.0), out)


def serving(session):
    """A UIServer of the session, serving in a thread until the generator is closed."""
    srv = UIServer(session)
    thread = threading.Thread(target=srv.serve_forever, kwargs={"poll_interval": 0.02}, daemon=True)
    thread.start()
    yield srv
    srv.shutdown()
    srv.server_close()


@pytest.fixture
def server(session):
    yield from serving(session)


def post(server: UIServer, path: str, body, content_type: str = "application/json", host: str | None = None,
         token: str | None = None) -> tuple[int, dict]:
    """POST body (JSON of an object, or bytes as they are) to the server's path with its token (or ``token``)."""
    data = body if isinstance(body, bytes) else json.dumps(body).encode()
    headers = {"Content-Type": content_type, TOKEN_HEADER: server.token if token is None else token}
    request = urllib.request.Request(server.address + path, data=data, headers=headers)
    if host:
        request.add_header("Host", host)
    try:
        with urllib.request.urlopen(request, timeout=30) as response:
            return response.status, json.loads(response.read())
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read())


def raw(server: UIServer, head: str, body: bytes = b"") -> tuple[int, dict]:
    """Send a hand-made request (``head``: its request line and headers, without the Host and token headers) and
    read the JSON answer."""
    port = server.server_address[1]
    with socket.create_connection(("127.0.0.1", port), timeout=30) as conn:
        conn.sendall(f"{head}\r\nHost: 127.0.0.1:{port}\r\n{TOKEN_HEADER}: {server.token}\r\n\r\n".encode() + body)
        response = http.client.HTTPResponse(conn)
        response.begin()
        return response.status, json.loads(response.read())


def request(**fields) -> dict:
    return {"trapezoid": TRAP, "camera_origin": [0.0, 0.0], "points": POINTS, "method": "regression-signed", **fields}


def test_a_boxes_method_needs_a_boxes_file_at_launch(server):
    status, answer = post(server, "api/fit", request(method="pedestrians"))
    assert status == 400 and answer["error"].startswith("method: pedestrians fits from people's boxes: start homocal "
                                                        "ui with --boxes FILE")


# ---- the pedestrian correction from the launch's boxes file ----------------------------------------------------
def standing_people_csv(path: Path, n: int = 80, seed: int = 0) -> Path:
    """A boxes CSV (frame,x1,y1,x2,y2, corners convention: homocal's edges + 0.5) of n people 1.65 +- 0.07 m tall
    standing 6-45 m ahead of CAM, one a frame 30 frames apart (each its own track)."""
    rng = np.random.default_rng(seed)
    xy = np.column_stack([rng.uniform(-6, 6, n), rng.uniform(6, 45, n)])
    foot = CAM.project_ground(xy)
    head = CAM.project(np.column_stack([xy, rng.normal(1.65, 0.07, n)]))
    half = CAM.focal_px * 0.2 / xy[:, 1]
    rows = [f"{30 * i},{u - h + 0.5},{t + 0.5},{u + h + 0.5},{v + 0.5}\n"
            for i, ((u, v), t, h) in enumerate(zip(foot, head[:, 1], half))]
    path.write_text("frame,x1,y1,x2,y2\n" + "".join(rows))
    return path


@pytest.fixture
def boxes_server(session, tmp_path):
    session.boxes = standing_people_csv(tmp_path / "boxes.csv").resolve()
    yield from serving(session)


def tilted_trapezoid(shift_px: float = 16.0) -> dict:
    """TRAP's image corners moved as a tilt error moves them: the clicked horizon shift_px above the camera's."""
    from homocal.study.perturb import tilt_shift

    return {"image": tilt_shift(IMAGE, CAM.K, CAM.horizon_row, shift_px).tolist(), "map": MAP.tolist()}


def test_drawn_boxes_by_kind():
    """Each box under its status (hidden feet a kind of its own), as its 8-point outline from the top-left corner."""
    xyxy = np.array([[10.0, 20.0, 30.0, 60.0], [40.0, 20.0, 50.0, 70.0], [0.0, 5.0, 9.0, 25.0], [60.0, 10.0, 64.0, 30.0]])
    drawn = api.drawn_boxes(xyxy, np.array(["used", "hidden", "border", "hidden"]))
    assert [len(drawn[k]) for k in ("used", "outlier", "border", "hidden")] == [1, 0, 1, 2] and drawn["total"] == 4
    assert drawn["hidden"][1][0] == [60.0, 10.0] and drawn["hidden"][1][4] == [64.0, 30.0]


def test_pedestrians_fit_from_the_launch_boxes(boxes_server):
    """The page's fit is the library's on read_boxes of the launch's file (image size: the frame's); the fitted
    horizon it draws is the camera's, the clicked one 16 px above it; the points only check the fit."""
    from homocal import PedestrianCorrector, read_boxes
    from homocal.correctors.pedestrians import SETTINGS as PEDESTRIAN_SETTINGS

    info = json.loads(urllib.request.urlopen(boxes_server.address + "api/session", timeout=10).read())
    assert "pedestrians" in info["methods"] and info["box_methods"] == ["pedestrians"]
    assert info["boxes"] == {"file": str(boxes_server.session.boxes), "detectors": [], "camera_height_m": None,
                             "fps": None}
    assert [(s["name"], s["id"], s["low"], s["high"]) for s in info["box_settings"]] == [
        (name, opt.flag[2:], getattr(opt.kind, "low", None), getattr(opt.kind, "high", None))
        for name, opt in PEDESTRIAN_SETTINGS.items()]  # declared once
    trap = tilted_trapezoid()
    status, fit = post(boxes_server, "api/fit", request(trapezoid=trap, method="pedestrians", points=[],
                                                        camera_height_m=4.0))
    assert status == 200, fit
    clicked = ViewTransformer(np.array(trap["image"]), SITE.to_metres(MAP))
    boxes = read_boxes(boxes_server.session.boxes)
    reference = PedestrianCorrector().fit(clicked, boxes.xyxy, convention="homocal", frames=boxes.frames,
                                          camera_height_m=4.0, image_size=(W, H))
    assert fit["correction"] == json.loads(json.dumps(reference.to_dict()))
    drawn = fit["boxes"]  # every box it read, by its part in the fit (the reference's counts)
    assert drawn["total"] == reference.n_boxes_ == len(boxes.xyxy) and drawn["step"] == 1
    assert (len(drawn["outlier"]), len(drawn["border"])) == (reference.n_outliers_, reference.n_border_)
    used = np.array(drawn["used"] + drawn["outlier"] + drawn["border"])  # outlines: TL corner 0, BR corner 4
    np.testing.assert_allclose(np.sort(np.hstack([used[:, 0], used[:, 4]]), axis=0), np.sort(boxes.xyxy, axis=0),
                               atol=0.05)  # rounded to 0.1 px
    assert drawn["hidden"] == []
    status, dropped = post(boxes_server, "api/fit", request(trapezoid=trap, method="pedestrians", points=[],
                                                            camera_height_m=4.0, drop_hidden_feet=True))
    own = PedestrianCorrector(drop_hidden_feet=True).fit(clicked, boxes.xyxy, convention="homocal", frames=boxes.frames,
                                                         camera_height_m=4.0, image_size=(W, H))
    assert status == 200 and dropped["correction"] == json.loads(json.dumps(own.to_dict()))
    assert own.drop_hidden_feet and len(dropped["boxes"]["hidden"]) == own.n_hidden_  # the page's setting reaches the fit
    assert [s["choices"] for s in info["box_settings"] if s["name"] == "drop_hidden_feet"] == [["yes", "no", "auto"]]
    status, auto = post(boxes_server, "api/fit", request(trapezoid=trap, method="pedestrians", points=[],
                                                         camera_height_m=4.0, drop_hidden_feet="auto"))
    assert status == 200 and auto["correction"]["params"]["drop_hidden_feet"] == "auto"
    assert auto["correction"]["fitted"]["hidden_feet"] == "kept"
    assert auto["correction"]["fitted"]["horizon_row"] == fit["correction"]["fitted"]["horizon_row"]  # it passed: the same fit
    (u0, v0), (u1, v1) = fit["horizon"]
    at_cx = v0 + (v1 - v0) * (CAM.K[0, 2] - u0) / (u1 - u0)
    assert at_cx == pytest.approx(reference.horizon_row_, abs=1e-6) and abs(at_cx - CAM.horizon_row) < 2.0
    assert clicked.horizon_row(CAM.K[0, 2]) == pytest.approx(CAM.horizon_row - 16.0, abs=0.1)
    assert "people (tracks): " in fit["summary"] and "no check points" in fit["summary"]
    trust = max_trustworthy_range(reference.mapping, 0.5, uncertainty=reference.ground_uncertainty)  # its own errors
    assert f"out to {trust:.1f} m straight ahead" in fit["summary"] and trust < max_trustworthy_range(reference.mapping, 0.5)
    status, checked = post(boxes_server, "api/fit", request(trapezoid=trap, method="pedestrians", camera_height_m=4.0))
    assert status == 200 and checked["correction"]["fitted"] == fit["correction"]["fitted"]
    assert checked["error_after"] < checked["error_before"] and "check points" in checked["summary"]


@pytest.mark.parametrize("fields,message", [
    ({"detector": "segmentation"}, "detector: boxes.csv has no detectors to choose from"),
    ({"camera_height_m": 0}, "camera_height_m 0: expected a number in [0.5, 100] (m) or none"),
    ({"camera_height_m": 1e-9}, "camera_height_m 1e-09: expected a number in [0.5, 100] (m) or none"),
    ({"camera_height_m": 1e6}, "camera_height_m 1000000.0: expected a number in [0.5, 100] (m) or none"),
    ({"camera_height_m": "4"}, "camera_height_m '4': expected a number in [0.5, 100] (m) or none"),
    ({"height_sd_m": 0}, "height_sd_m 0: expected a number in [0.01, 0.625] (m)"),
    ({"height_sd_m": 0.5}, "height_sd_m 0.5: expected at most height_mean_m / 4 = 0.4125 m"),
    ({"height_sd_m": "0.1"}, "height_sd_m '0.1': expected a number in [0.01, 0.625] (m)"),
    ({"height_mean_m": 20}, "height_mean_m 20: expected a number in [0.5, 2.5] (m)"),
    ({"height_mean_m": True}, "height_mean_m True: expected a number"),
    ({"height_mean_m": float("nan")}, "height_mean_m nan: expected a number"),
    ({"height_mean_sigma_m": -0.1}, "height_mean_sigma_m -0.1: expected a number in [0, 0.5] (m)"),
    ({"camera_height_m": float("inf")}, "camera_height_m inf: expected a number"),
    ({"box_margin_px": -1}, "box_margin_px -1: expected a number in [0, 64] (px)"),
    ({"box_margin_px": 65}, "box_margin_px 65: expected a number in [0, 64] (px)"),
    ({"box_margin_px": "2"}, "box_margin_px '2': expected a number in [0, 64] (px)"),
    ({"box_margin_px": float("nan")}, "box_margin_px nan: expected a number in [0, 64] (px)"),
    ({"height_mean_m": [1.7]}, "height_mean_m [1.7]: expected a number"),
    ({"camera_height_m": True}, "camera_height_m True: expected a number"),
    ({"detector": 3}, "detector: boxes.csv has no detectors to choose from"),
    ({"boxes": "/etc/passwd", "camera_height_m": 40.0}, "no tilt makes the median"),  # a path in a request is not read
])  # fmt: skip
def test_pedestrians_bad_requests(boxes_server, fields, message):
    status, answer = post(boxes_server, "api/fit", request(trapezoid=tilted_trapezoid(), method="pedestrians",
                                                           points=[], **fields))
    assert status == 400 and message in answer["error"], answer


def _parquet_boxes(session, tmp_path: Path, K: np.ndarray | None = None) -> tuple[Path, tuple[str, ...]]:
    """standing_people_csv's boxes as an "rgb" detector's rows of a detections.parquet (with a camera.json of
    the frame's size and K beside it when K is given); the session's boxes file and detectors of it."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from homocal.ui.session import _boxes_file

    table = np.loadtxt(standing_people_csv(tmp_path / "b.csv"), delimiter=",", skiprows=1)
    n = len(table)
    pq.write_table(pa.table({"detector": ["rgb"] * n, "frame": table[:, 0].astype(np.int32),
                             **{c: table[:, i + 1] - 0.5 for i, c in enumerate(("x1", "y1", "x2", "y2"))}}),
                   tmp_path / "detections.parquet")
    if K is not None:
        (tmp_path / "camera.json").write_text(json.dumps({"width": W, "height": H, "K": K.tolist()}))
    return _boxes_file(tmp_path / "detections.parquet")


def test_pedestrians_detector_of_a_dataset_parquet(session, tmp_path):
    """A detections.parquet: the page picks one of its detectors by name, and no other."""
    session.boxes, session.detectors = _parquet_boxes(session, tmp_path)
    assert session.detectors == ("rgb",)
    req = request(trapezoid=tilted_trapezoid(), method="pedestrians", points=[], camera_height_m=4.0)
    assert abs(api.fit(session, req)["correction"]["fitted"]["horizon_row"] - CAM.horizon_row) < 2.0
    with pytest.raises(ValueError, match="detector: expected one of rgb, got '../x'"):
        api.fit(session, {**req, "detector": "../x"})


def test_pedestrians_probe_has_the_corrections_own_error_bar(session, tmp_path):
    """locate with a pedestrians correction: the corrected position's ellipse is the correction's own error model
    (its fitted horizon's uncertainty on top of the corrected trapezoid's), at the request's sigmas."""
    from homocal import load_corrector

    session.boxes = standing_people_csv(tmp_path / "boxes.csv").resolve()
    req = request(trapezoid=tilted_trapezoid(), method="pedestrians", points=[], camera_height_m=4.0,
                  click_sigma_px=0.5, point_sigma_px=0.8)
    correction = api.fit(session, req)["correction"]
    (tmp_path / "c.json").write_text(json.dumps(correction))
    corrector = load_corrector(tmp_path / "c.json")
    q = CAM.project_ground([[2.0, 30.0]])
    answer = api.locate(session, {**req, "point": q[0].tolist(), "correction": correction})
    own = answer["corrected_errorbars"]
    np.testing.assert_array_equal(own["points"], corrector.transform_points(q))
    assert own["points"][0] == answer["corrected"]
    cov = corrector.ground_uncertainty(q, 0.5, 0.8)[0]
    np.testing.assert_allclose(own["sigma"][0], np.sqrt(np.linalg.eigvalsh(cov))[::-1], rtol=1e-9)
    assert own["sigma"][0][0] > sigma_radius(ground_uncertainty(corrector.mapping, q, 0.5, 0.8))[0]
    assert api.locate(session, {**req, "point": q[0].tolist()})["corrected_errorbars"] is None


def run_printed_command(command: str, out: Path) -> dict:
    """Run the ``homocal fit`` command Save printed (in process), writing to ``out``; its correction's JSON."""
    args = shlex.split(command)
    assert args[:2] == ["homocal", "fit"] and args.count("CORRECTION.json") == 1
    assert main([str(out) if a == "CORRECTION.json" else a for a in args[1:]]) == 0
    return json.loads(out.read_text())


@pytest.mark.parametrize("fields", [{"camera_height_m": 4.0}, {}, {"camera_height_m": 4.0, "height_mean_m": 1.7,
                                                                   "height_sd_m": 0.08, "drop_hidden_feet": "auto"}])
def test_pedestrians_save_prints_the_command_that_reproduces_it(boxes_server, tmp_path, fields):
    """A boxes CSV has no image size or K: Save writes the frame's size to camera_intrinsics.json and names it in
    the command with every other setting of the page's fit, and the command's correction is the saved one."""
    status, saved = post(boxes_server, "api/save", request(trapezoid=tilted_trapezoid(), method="pedestrians",
                                                           **fields))
    assert status == 200, saved
    out = boxes_server.session.out_dir
    assert saved["written"][-1] == str(out / api.CAMERA_FILE)
    assert json.loads((out / api.CAMERA_FILE).read_text()) == {"width": W, "height": H}
    command = saved["command"]
    assert f"--boxes {boxes_server.session.boxes}" in command and f"--camera-json {out / api.CAMERA_FILE}" in command
    assert ("--camera-height 4.0" in command) == ("camera_height_m" in fields) and "--points " in command
    correction = json.loads((out / "correction.json").read_text())
    assert run_printed_command(command, tmp_path / "cli.json") == correction
    status, loaded = post(boxes_server, "api/load", {})
    assert status == 200 and loaded["fit"]["method"] == "pedestrians"


def test_pedestrians_save_asks_before_replacing_a_camera_file_it_did_not_write(boxes_server):
    foreign = boxes_server.session.out_dir / api.CAMERA_FILE
    foreign.write_text('{"width": 1, "height": 1}')
    req = request(trapezoid=tilted_trapezoid(), method="pedestrians", camera_height_m=4.0)
    status, answer = post(boxes_server, "api/save", req)
    assert status == 409 and f"{api.CAMERA_FILE} already in" in answer["error"]
    assert [p.name for p in boxes_server.session.out_dir.iterdir()] == [api.CAMERA_FILE]  # nothing written
    assert post(boxes_server, "api/save", {**req, "overwrite": True})[0] == 200
    assert json.loads(foreign.read_text()) == {"width": W, "height": H}


def test_pedestrians_save_names_the_pages_detector(session, tmp_path):
    """A detections.parquet without segmentation rows: the page fits its first detector, and so does the command
    (homocal fit's default would be segmentation); its camera.json's K and size go to camera_intrinsics.json."""
    session.boxes, session.detectors = _parquet_boxes(session, tmp_path, K=CAM.K)
    saved = api.save(session, request(trapezoid=tilted_trapezoid(), method="pedestrians", points=[]))
    assert "--detector rgb" in saved["command"] and "--points" not in saved["command"]
    assert json.loads((session.out_dir / api.CAMERA_FILE).read_text()) == {"width": W, "height": H, "K": CAM.K.tolist()}
    correction = json.loads((session.out_dir / "correction.json").read_text())
    assert correction["fitted"]["focal_source"] == "given"
    assert run_printed_command(saved["command"], tmp_path / "cli.json") == correction


# ---- overlays against the camera they should show ----------------------------------------------------
def test_horizon_is_the_cameras(session):
    view = api.view(session, request())
    (u0, v0), (u1, v1) = view["horizon"]
    assert (u0, u1) == (-W, 2 * W)
    np.testing.assert_allclose([v0, v1], CAM.horizon_row, atol=1e-6)


def test_grid_lines_and_rings_lie_on_the_ground_lines_they_name(session):
    """Every traced vertex, back-projected by the camera (a ray meeting the ground, independent of the
    trapezoid homography), is on a grid line (x or y a multiple of the spacing) or on its range ring, to 0.3 px."""
    grid = api.view(session, request())["grid"]
    assert len(grid["minor"]) > 20 and len(grid["major"]) > 5 and [r["r"] for r in grid["rings"]][:3] == [10, 20, 30]
    for key, spacing in (("minor", 1.0), ("major", 10.0)):
        for line in grid[key]:
            g = CAM.ray_to_ground(np.array(line))
            off = np.abs(g - np.round(g / spacing) * spacing).max(axis=0)  # worst offset along x and along y
            px = off / _metres_per_px(line).max()
            assert px.min() < 0.3, (key, line[:3])
    for ring in grid["rings"]:
        for line in ring["lines"]:
            r = np.hypot(*CAM.ray_to_ground(np.array(line)).T)
            assert (np.abs(r - ring["r"]) / _metres_per_px(line)).max() < 0.3


def _metres_per_px(line) -> np.ndarray:
    """Ground metres per image pixel at each vertex, by finite differences of the camera's back-projection."""
    q = np.array(line)
    g0, gu, gv = (CAM.ray_to_ground(q + d) for d in ([0, 0], [0.5, 0], [0, 0.5]))
    return np.maximum(np.hypot(*(gu - g0).T), np.hypot(*(gv - g0).T)) / 0.5


def test_footprint_is_the_frame_border_on_the_map(session):
    """Each footprint vertex projects (camera) onto the frame's border or the horizon margin, or lies on the
    range cap (the map corner farthest from the camera). Vertices are rounded to 0.1 map px (1 cm): within
    1 image px of the border near the camera."""
    footprint = np.array(api.view(session, request())["footprint"])
    ground = SITE.to_metres(footprint)
    q = CAM.project_ground(ground)
    on_border = (np.isclose(q[:, 0], -0.5, atol=1) | np.isclose(q[:, 0], W - 0.5, atol=1)
                 | np.isclose(q[:, 1], H - 0.5, atol=1)
                 | np.isclose(q[:, 1], CAM.horizon_row + overlay.HORIZON_MARGIN_PX, atol=1))
    cap = np.hypot(*SITE.to_metres(np.array([[-0.5, -0.5], [MAP_SIZE[0] - 0.5, -0.5]])).T).max()
    on_cap = np.isclose(np.hypot(*ground.T), cap, atol=0.05)
    assert (on_border | on_cap).all() and on_border.sum() > 50 and on_cap.sum() > 10


def test_error_bar_nodes_are_on_the_10_m_grid(session):
    field = overlay.sample_mapping(CAM.ray_to_ground, ViewTransformer(IMAGE, GROUND), W, H)
    nodes = overlay.grid_nodes(field, ViewTransformer(IMAGE, GROUND))
    g = CAM.ray_to_ground(nodes)
    assert len(nodes) >= 5
    np.testing.assert_allclose(g, np.round(g / 10) * 10, atol=1e-6)


# ---- corner order --------------------------------------------------------------------------------------
MIRRORED = MAP[[1, 0, 3, 2]]
UPSIDE_DOWN = 2 * MAP.mean(axis=0) - MAP  # turned 180 degrees: still clockwise


@pytest.mark.parametrize("image, map_px, message", [
    (IMAGE, MIRRORED, "map corners: mirrored"),
    (IMAGE, UPSIDE_DOWN, "map corners: upside down"),
    (IMAGE[[0, 3, 2, 1]], MAP, "image corners: click them in the order TL, TR, BR, BL"),
    (IMAGE[[2, 3, 0, 1]], MAP, "image corners: click them in the order TL, TR, BR, BL"),
    (IMAGE[[0, 2, 1, 3]], MAP, "image corners: the trapezoid is self-intersecting"),
    (IMAGE[:2], MIRRORED, "map corners: mirrored"),  # refused before the image side is complete
])  # fmt: skip
def test_corner_order_is_refused(server, image, map_px, message):
    status, answer = post(server, "api/view", request(trapezoid={"image": image.tolist(), "map": map_px.tolist()}))
    assert status == 400 and answer["error"].startswith(message)


# ---- bad requests over HTTP ------------------------------------------------------------------------------
@pytest.mark.parametrize("path, body, kind, host, status, message", [
    ("api/view", request(), "text/plain", None, 415, "send JSON"),
    ("api/view", b"{not json", "application/json", None, 400, "not valid JSON"),
    ("api/view", [1, 2], "application/json", None, 400, "expected a JSON object"),
    ("api/nothing", {}, "application/json", None, 404, "no such endpoint"),
    ("api/view", request(), "application/json", "attacker.example:80", 403, "unexpected Host header"),
    ("api/view", {"camera_origin": [0, 0]}, "application/json", None, 400, "trapezoid: expected"),
    ("api/view", request(trapezoid={"image": IMAGE.tolist() + [[1, 2]], "map": []}), "application/json", None, 400,
     "trapezoid image: expected a list of at most 4 points"),
    ("api/view", b'{"trapezoid": {"image": [[NaN, 1]], "map": []}, "camera_origin": [0, 0]}', "application/json",
     None, 400, "trapezoid image[0]: expected 2 finite numbers"),
    ("api/view", request(click_sigma_px=-1), "application/json", None, 400, "click_sigma_px: expected a number in [0, 100], got -1"),
    ("api/view", request(camera_origin=[0]), "application/json", None, 400, "camera_origin[0]: expected 2 finite"),
    ("api/fit", request(points=POINTS[:2]), "application/json", None, 400, "need at least 3 reference points"),
    ("api/fit", request(method="magic"), "application/json", None, 400, "method: expected one of regression,"),
    ("api/fit", request(seed=1.5, method="descent"), "application/json", None, 400, "seed: expected an integer"),
    ("api/fit", request(trapezoid={"image": IMAGE.tolist(), "map": MAP[:3].tolist()}), "application/json", None,
     400, "click all 4 image corners and all 4 map corners first"),
    ("api/fit", request(points=POINTS[:2] + [[640.0, 100.0, 0.0, 50.0]]), "application/json", None, 400,
     "image_points[2] = [640.0, 100.0] is on or above the horizon"),
    ("api/locate", request(point=[640.0, 100.0]), "application/json", None, 400, "is on or above the horizon"),
    ("api/load", {}, "application/json", None, 400, "trapezoid.json: no such file"),
])  # fmt: skip
def test_bad_requests_get_4xx_and_a_message(server, path, body, kind, host, status, message):
    got_status, answer = post(server, path, body, kind, host)
    assert got_status == status and message in answer["error"]


NESTED = ("[" * 100_000 + "]" * 100_000).encode()


@pytest.mark.parametrize("head, body, status, message", [
    ("POST /api/view HTTP/1.1\r\nContent-Type: application/json\r\nContent-Length: abc", b"{}", 400,
     "Content-Length: expected a number of bytes, got 'abc'"),
    ("POST /api/view HTTP/1.1\r\nContent-Type: application/json\r\nContent-Length: -5", b"{}", 400,
     "Content-Length: expected a number of bytes, got '-5'"),
    ("POST /api/view HTTP/1.1\r\nContent-Type: application/json\r\nContent-Length: 99999999999999999999", b"", 400,
     "Content-Length: expected a number of bytes"),
    (f"POST /api/view HTTP/1.1\r\nContent-Type: application/json\r\nContent-Length: {MAX_BODY + 1}", b"", 413,
     f"Content-Length: expected a JSON body of 1 byte to {MAX_BODY} bytes"),
    ("POST /api/view HTTP/1.1\r\nContent-Type: application/json", b"", 400, "Content-Length: expected a number"),
])  # fmt: skip
def test_malformed_http_gets_4xx_json(server, head, body, status, message):
    got, answer = raw(server, head, body)
    assert got == status and message in answer["error"]
    assert post(server, "api/view", request())[0] == 200  # and it keeps serving


@pytest.mark.parametrize("body, status, message", [
    (NESTED, 400, f"body: JSON nested deeper than {MAX_DEPTH} levels"),
    (b'{"a": ' + b'{"b": ' * 30 + b"1" + b"}" * 31, 400, "nested deeper"),
    (b'{"seed": ' + b"9" * 5000 + b"}", 400, "body: an integer of 5000 digits (at most 20)"),
    (b'{"s": "[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[", "trapezoid": 1}', 400, "trapezoid: expected"),  # brackets in a string
    (json.dumps(request(seed=1e30, method="descent")).encode(), 400, "seed: expected a number in [0, 1.84467e+19]"),
    (json.dumps(request(seed=2**64, method="descent")).encode(), 400, "seed: expected a number in [0"),
    (json.dumps(request(seed=-1, method="descent")).encode(), 400, "seed: expected a number in [0"),
    (json.dumps(request(method=["regression"])).encode(), 400, "method: expected one of regression,"),
    (json.dumps(request(method={"a": 1})).encode(), 400, "method: expected one of"),
    (json.dumps(request(method=None)).encode(), 400, "method: expected one of"),
    (json.dumps(request(click_sigma_px=1e308)).encode(), 400, "click_sigma_px: expected a number in [0, 100]"),
    (json.dumps(request(point_sigma_px=True)).encode(), 400, "point_sigma_px: expected a finite number, got True"),
    (json.dumps(request(tolerance_m=1e300)).encode(), 400, "tolerance_m: expected a number in [0, 1e+06]"),
    (json.dumps(request(threshold=1e9, method="hybrid")).encode(), 400, "threshold: expected a number in [0, 100]"),
    (b'{"trapezoid": {"image": [[1e999, 1]], "map": []}, "camera_origin": [0, 0]}', 400, "trapezoid image[0]: expected 2"),
    (json.dumps(request(camera_origin=[1e300, 0])).encode(), 400, "camera_origin[0]: expected 2 finite numbers within"),
    (json.dumps(request(points=[[1.0, 2.0, 3.0, 4.0]] * 100_001)).encode(), 400, "points: expected a list of at most 100,000"),
    (json.dumps(request(point=[640.0, 600.0], correction=[1])).encode(), 400, "correction: expected the object"),
    (json.dumps(request(point=[640.0, 600.0], correction={"format": "homocal.correction", "format_version": 1,
                                                         "method": [1]})).encode(), 400, "correction: unknown method"),
    (b'"just a string"', 400, "body: expected a JSON object"),
    (b'{"trapezoid": "\xff"}', 400, "body: not valid JSON"),
])  # fmt: skip
def test_malformed_json_gets_4xx_naming_the_field(server, capsys, body, status, message):
    path = "api/locate" if b'"point"' in body else "api/fit" if b'"method"' in body else "api/view"
    got, answer = post(server, path, body)
    assert got == status and message in answer["error"], answer
    assert "Traceback" not in capsys.readouterr().err
    assert post(server, "api/view", request())[0] == 200


@pytest.mark.parametrize("token", ["", "wrong", None])
def test_a_post_without_the_token_is_refused(server, session, token):
    headers = {"Content-Type": "application/json"} | ({} if token is None else {TOKEN_HEADER: token})
    req = urllib.request.Request(server.address + "api/save", data=json.dumps(request()).encode(), headers=headers)
    with pytest.raises(urllib.error.HTTPError) as e:
        urllib.request.urlopen(req, timeout=30)
    assert e.value.code == 403 and TOKEN_HEADER in json.loads(e.value.read())["error"]
    assert list(session.out_dir.iterdir()) == []  # nothing saved
    assert server.url == f"{server.address}?token={server.token}" and len(server.token) >= 32


def test_requests_over_the_concurrency_bound_get_503(server):
    server.queue_seconds = 0.2
    for _ in range(MAX_CONCURRENT):  # as if MAX_CONCURRENT requests were being answered
        server.slots.acquire()
    try:
        status, answer = post(server, "api/view", request())
        assert status == 503 and "busy" in answer["error"]
    finally:
        for _ in range(MAX_CONCURRENT):
            server.slots.release()
    assert post(server, "api/view", request())[0] == 200


def test_pages_are_served(server):
    for path, kind in (("", "text/html"), ("app.js", "text/javascript"), ("frame.png", "image/png"),
                       ("map.png", "image/png"), ("api/session", "application/json")):
        with urllib.request.urlopen(server.address + path, timeout=10) as response:
            assert response.headers["Content-Type"].startswith(kind)
    info = json.loads(urllib.request.urlopen(server.address + "api/session", timeout=10).read())
    assert info["frame"] == {"width": W, "height": H} and info["map"]["scale_px_per_m"] == 10.0
    assert "regression-signed" in info["methods"] and info["dataset"] is None
    assert "pedestrians" not in info["methods"]  # fitted from boxes, which the page does not load
    assert info["default_method"] == "least-change" and info["default_method"] in info["methods"]  # fit's default
    with pytest.raises(urllib.error.HTTPError, match="404"):
        urllib.request.urlopen(server.address + "nothing.html", timeout=10)


def test_locate_maps_a_point_and_corrects_it(session):
    correction = api.fit(session, request())["correction"]
    q = CAM.project_ground([[2.0, 25.0]])[0]
    answer = api.locate(session, request(point=q.tolist(), correction=correction))
    np.testing.assert_allclose(answer["ground"], [2.0, 25.0], atol=1e-9)  # the exact trapezoid maps exactly
    assert answer["distance"] == pytest.approx(np.hypot(2.0, 25.0))
    fitted = api._fitted(session, request())[0]
    np.testing.assert_array_equal(answer["corrected"], fitted.transform_points(q[None])[0])


# ---- save and load ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("method", ["regression-signed", "regression-intercept", "horizon",
                                    pytest.param("hybrid", marks=pytest.mark.slow)])  # hybrid: descent too
def test_saved_files_give_homocal_fits_correction(server, session, tmp_path, capsys, method):
    status, answer = post(server, "api/save", request(method=method, seed=3, threshold=80.0))
    assert status == 200, answer
    out = session.out_dir
    cli = tmp_path / "cli.json"
    assert main(["fit", "--trapezoid", str(out / "trapezoid.json"), "--points", str(out / "reference_points.csv"),
                 "--method", method, "-o", str(cli), "--seed", "3", "--threshold", "80"]) == 0
    assert json.loads(cli.read_text()) == json.loads((out / "correction.json").read_text())
    _, fitted = post(server, "api/fit", request(method=method, seed=3, threshold=80.0))
    assert fitted["correction"] == json.loads(cli.read_text())
    printed = capsys.readouterr().out  # fit's summary and trustworthy range at its default sigmas, as the page's
    assert re.search(r"mean calibration error .*? %\)", printed).group(0) in fitted["summary"]
    assert re.search(r"stays under 0\.5 m out to [\d.]+ m", printed).group(0) in fitted["summary"]
    status, loaded = post(server, "api/load", {})
    assert status == 200
    assert loaded["trapezoid"] == TRAP and loaded["points"] == POINTS
    assert loaded["fit"]["method"] == method and loaded["fit"]["camera_origin"] == [0.0, 0.0]


def test_save_asks_before_replacing_a_file_it_did_not_write(server, session):
    foreign = session.out_dir / "reference_points.csv"
    foreign.write_text("u,v,x,y\n1,2,3,4\n")
    status, answer = post(server, "api/save", request())
    assert status == 409 and "reference_points.csv already in" in answer["error"]
    assert foreign.read_text() == "u,v,x,y\n1,2,3,4\n" and sorted(p.name for p in session.out_dir.iterdir()) == [
        "reference_points.csv"]  # nothing written
    assert post(server, "api/save", request(overwrite=True))[0] == 200
    assert foreign.read_text().startswith("u,v,x,y\n") and len(foreign.read_text().splitlines()) == 4
    assert post(server, "api/save", request())[0] == 200  # its own files: replaced without asking


@pytest.mark.parametrize("overwrite", [False, True])
def test_save_never_replaces_a_symlink(server, session, tmp_path, overwrite):
    assert post(server, "api/save", request())[0] == 200
    victim = tmp_path / "victim.txt"
    victim.write_text("the user's")
    link = session.out_dir / "correction.json"
    link.unlink()
    link.symlink_to(victim)
    status, answer = post(server, "api/save", request(overwrite=overwrite))
    assert status == 409 and "correction.json in" in answer["error"] and "symbolic link" in answer["error"]
    assert "exists" not in answer  # the page does not offer to replace it
    assert link.is_symlink() and victim.read_text() == "the user's"


def test_save_asks_before_replacing_a_file_swapped_in_since(server, session):
    assert post(server, "api/save", request())[0] == 200
    swapped = session.out_dir / "trapezoid.json"
    swapped.unlink()
    swapped.write_text("{}")  # the user's file now, though the name is one the server wrote
    status, answer = post(server, "api/save", request())
    assert status == 409 and answer["exists"] is True and swapped.read_text() == "{}"


def test_load_converts_a_trapezoid_in_metres_to_map_pixels(session):
    (session.out_dir / "trapezoid.json").write_text(json.dumps({"image": IMAGE.tolist(), "map": GROUND.tolist()}))
    loaded = api.load(session, {})
    np.testing.assert_allclose(loaded["trapezoid"]["map"], MAP, atol=1e-9)
    assert loaded["points"] == [] and loaded["fit"] is None and loaded["loaded"] == ["trapezoid.json"]


# ---- the command line ------------------------------------------------------------------------------------
def test_a_video_frame_is_read(tmp_path):
    video = tmp_path / "clip.mp4"
    imageio.mimwrite(video, [np.full((64, 96, 3), 40 * k, np.uint8) for k in range(4)], fps=10, macro_block_size=1)
    png, size = read_frame(video, 2)
    assert size == (96, 64)
    assert abs(cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_GRAYSCALE).mean() - 80) < 4
    with pytest.raises(ValueError, match="no frame 4 \\(the video has 4 frames"):
        read_frame(video, 4)


@pytest.mark.parametrize("args, message", [
    ([], "give a DATASET folder, or --frame, --site-map and --scale (missing --frame, --site-map, --scale)"),
    (["--frame", "f.png", "--site-map", "m.png"], "(missing --scale)"),
    (["DS", "--frame", "f.png"], "give either DATASET or --frame/--site-map/--scale, not both (--frame)"),
    (["--frame", "none.png", "--site-map", "m.png", "--scale", "10"], "none.png: no such file"),
    (["--frame", "f.png", "--site-map", "m.png", "--scale", "-2"], "argument --scale: must be a finite number > 0, got -2"),
    (["--frame", "f.png", "--site-map", "m.png", "--scale", "nan"], "argument --scale: must be a finite number > 0, got nan"),
    (["--frame", "f.png", "--site-map", "m.png", "--scale", "10", "--port", "70000"], "argument --port: must be an integer in [0, 65535]"),
    (["--frame", "f.png", "--site-map", "m.png", "--scale", "10", "--frame-index", "-1"], "argument --frame-index: must be an integer >= 0"),
    (["--frame", "f.png", "--site-map", "m.png", "--scale", "10", "--out", "no/where"],
     "no/where: its parent folder"),
    (["--frame", "f.png", "--site-map", "m.png", "--scale", "10", "--out", "f.txt"], "f.txt: exists and is not a folder"),
    (["--frame", "f.png", "--site-map", "f.txt", "--scale", "10"], "f.txt: not a readable image"),
    (["NODATA"], "NODATA: not a dataset folder"),
])  # fmt: skip
def test_bad_command_lines(tmp_path, monkeypatch, capsys, args, message):
    monkeypatch.chdir(tmp_path)
    cv2.imwrite("f.png", np.zeros((8, 8, 3), np.uint8))
    cv2.imwrite("m.png", np.zeros((8, 8, 3), np.uint8))
    Path("f.txt").write_text("not an image")
    Path("DS").mkdir()
    try:
        code = main(["ui", *args])
    except SystemExit as e:  # refused by argparse
        code = e.code
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith("homocal: error: ") and message in err and err.count("\n") == 1


@pytest.mark.slow  # homocal ui in a subprocess
def test_the_printed_url_carries_the_token_and_out_is_made(tmp_path):
    """`homocal ui --out NEW` makes the one missing folder; its printed URL's token opens the API."""
    cv2.imwrite(str(tmp_path / "f.png"), np.zeros((8, 8, 3), np.uint8))
    out = tmp_path / "calib"
    proc = subprocess.Popen([sys.executable, "-m", "homocal.cli", "ui", "--frame", str(tmp_path / "f.png"),
                             "--site-map", str(tmp_path / "f.png"), "--scale", "10", "--out", f"{out}/"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=os.environ)
    try:
        line = proc.stdout.readline()
        match = re.search(r"(http://127\.0\.0\.1:\d+/)\?token=([\w-]+)", line)
        assert match, line + (proc.stderr.read() if proc.poll() is not None else "")
        assert out.is_dir() and list(out.iterdir()) == []
        body = json.dumps({"trapezoid": {"image": [], "map": []}, "camera_origin": [0, 0]}).encode()
        for token, status in (("", 403), (match.group(2), 200)):
            req = urllib.request.Request(match.group(1) + "api/view", data=body,
                                         headers={"Content-Type": "application/json", TOKEN_HEADER: token})
            try:
                got = urllib.request.urlopen(req, timeout=30).status
            except urllib.error.HTTPError as e:
                got = e.code
            assert got == status
    finally:
        proc.terminate()
        proc.wait(timeout=10)


# ---- error bars ------------------------------------------------------------------------------------------
def test_error_ellipses_are_the_librarys_1_sigma_covariances(session):
    """Every ellipse vertex p satisfies (p - c)^T Sigma^-1 (p - c) = 1 for the library's covariance Sigma, the map
    clicking sigma being converted from map px to metres; the trustworthy range is the library's."""
    sigmas = {"click_sigma_px": 2.0, "point_sigma_px": 0.5, "map_sigma_px": 3.0}
    bars = api.view(session, request(tolerance_m=0.4, **sigmas))["errorbars"]
    transformer = ViewTransformer(IMAGE, GROUND)
    q = np.array(bars["image_points"])
    assert len(q) >= 3  # those within the trustworthy range (test_ellipses_only_within_the_trustworthy_range)
    cov = ground_uncertainty(transformer, q, 2.0, 0.5, 3.0 / SITE.scale_px_per_m)
    for c, sigma, ellipse_map, s in zip(bars["points"], bars["sigma"], bars["map"], cov):
        d = SITE.to_metres(np.array(ellipse_map)) - c
        rounding = 0.005 * np.sqrt(2) / SITE.scale_px_per_m  # vertices are rounded to 0.01 map px
        tolerance = 2 * rounding / sigma[1] + (rounding / sigma[1]) ** 2
        np.testing.assert_allclose(np.einsum("ni,ij,nj->n", d, np.linalg.inv(s), d), 1.0, atol=tolerance)
        np.testing.assert_allclose(sigma[0], sigma_radius(s), rtol=1e-9)
    expected = max_trustworthy_range(transformer, 0.4, click_sigma_px=2.0, point_sigma_px=0.5, map_sigma_px=0.3)
    assert bars["trustworthy_range_m"] == pytest.approx(expected, rel=1e-12)
    for line in bars["trustworthy_image"]:
        np.testing.assert_allclose(np.hypot(*transformer.transform_points(np.array(line)).T), expected, rtol=2e-3)
    assert api.view(session, request(errorbars=False))["errorbars"] is None


def test_ellipses_only_within_the_trustworthy_range(session):
    """The grid nodes whose ellipses are answered are those within the trustworthy range of the camera ground point
    (the others counted in "beyond"): with a tolerance no node exceeds, all of them."""
    every = api.view(session, request(tolerance_m=1e6))["errorbars"]
    bars = api.view(session, request(tolerance_m=0.4))["errorbars"]
    within = np.hypot(*np.array(every["points"]).T) <= bars["trustworthy_range_m"]  # camera ground point (0, 0)
    assert every["beyond"] == 0 and bars["beyond"] == np.count_nonzero(~within) > 0
    np.testing.assert_array_equal(bars["points"], np.array(every["points"])[within])


def test_fit_passes_on_the_librarys_warnings(session):
    behind = [*REF_Q[2], 0.0, -35.0]
    answer = api.fit(session, request(points=POINTS[:2] + [behind]))
    assert len(answer["warnings"]) == 1 and "ground_points[2] = [0.0, -35.0] is behind the camera" in answer["warnings"][0]
    assert api.fit(session, request())["warnings"] == []

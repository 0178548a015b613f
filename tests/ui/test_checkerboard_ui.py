"""The page's checkerboard: photographs uploaded to /api/checkerboard are calibrated by homocal lens --checkerboard's
calibrate_board, the session then maps through that lens, Save lens writes what the printed command reproduces;
each bad input is one 4xx line and leaves the session as it was. The photographs are boards rendered through a
known lens by OpenCV (tests/lens_photos.py, shared with homocal lens's tests), never through the Lens under test."""
from __future__ import annotations

import base64
import functools
import json
import shlex

import cv2
import numpy as np
import pytest
from cli_run import homocal_main
from lens_photos import EXACT, K, POSES, SIZE, TRUE, render_board
from selenium.webdriver.common.by import By
from test_api import post, raw, serving
from test_browser import browser, idle, js, ui_server, wait_for  # noqa: F401 (browser: the fixture)

from homocal.geometry import SiteMap
from homocal.lens.checkerboard import MAX_FRAMES
from homocal.ui import api
from homocal.ui.server import MAX_BOARD_BODY, MAX_BODY
from homocal.ui.session import from_files, undistorted

SITE = SiteMap(10.0, (200.0, 700.0))
K1_RTOL = 0.05  # k1 within 5 % of the true one: the lens tests' tolerance (and issue 32's target for --lines)


def png(image: np.ndarray) -> bytes:
    return cv2.imencode(".png", image)[1].tobytes()


@functools.cache
def board_pngs() -> tuple[bytes, ...]:
    """The PNG of each of POSES' boards seen through TRUE."""
    return tuple(png(render_board(pose)) for pose in POSES)


def photos(*images: bytes, names=None) -> list[dict]:
    return [{"name": name, "data": base64.b64encode(data).decode()}
            for name, data in zip(names or [f"{i}.png" for i in range(len(images))], images)]


GREY = png(np.full((SIZE[1], SIZE[0]), 128, np.uint8))  # a frame with no board


@pytest.fixture
def session(tmp_path):
    """A 640x360 frame (lens_photos' SIZE) on a site map, saving to tmp_path / "out"."""
    cv2.imwrite(str(tmp_path / "frame.png"), np.full((SIZE[1], SIZE[0], 3), 90, np.uint8))
    cv2.imwrite(str(tmp_path / "map.png"), np.full((800, 400, 3), 60, np.uint8))
    (tmp_path / "out").mkdir()
    return from_files(tmp_path / "frame.png", tmp_path / "map.png", SITE, (0.0, 0.0), tmp_path / "out")


@pytest.fixture
def server(session):
    yield from serving(session)


def request(**fields) -> dict:
    return {"photos": photos(GREY, GREY, GREY), "pattern": "9x6", "square_m": 0.025, **fields}


BAD = [  # (request fields, the start of the one-line message)
    ({"photos": []}, "photos: no frame to read"),
    ({"photos": None}, 'photos: expected a list of {"name": file name, "data": base64}'),
    ({"photos": photos(b"not an image", GREY, GREY)}, "photos: 0.png: not a readable image"),
    ({"photos": photos(png(np.zeros((180, 320), np.uint8)))},
     "photos: 0.png: 320x180, the camera's frame is 640x360 (one camera, one image size)"),
    ({}, "photos: the 9x6 board was found in 0 of 3 frames; calibration needs it in at least 3"),
    ({"photos": photos(*[GREY] * (MAX_FRAMES + 5))}, f"photos: {MAX_FRAMES + 1} frames, more than {MAX_FRAMES}"),
    ({"photos": photos(GREY, names=["../0.png"])}, "photos[0]: expected a file name (no folder, not starting with"),
    ({"photos": photos(GREY, names=[".0.png"])}, "photos[0]: expected a file name"),
    ({"photos": photos(GREY, GREY, names=["a.png", "a.png"])}, "photos[1]: a.png is given twice"),
    ({"photos": [{"name": "a.png", "data": "not base64!"}]}, "photos[0]: a.png's data is not base64"),
    ({"pattern": "0x5"}, "pattern: each count must be in [2, 100], got '0x5'"),
    ({"pattern": "9x"}, "pattern: expected COLSxROWS inner corners such as 9x6, got '9x'"),
    ({"pattern": "1e9x2"}, "pattern: expected COLSxROWS inner corners such as 9x6, got '1e9x2'"),
    ({"pattern": None}, "pattern: expected COLSxROWS inner corners such as 9x6, got None"),
    ({"square_m": 0}, "square_m: expected a number in (0, 100], got 0"),
    ({"square_m": -0.025}, "square_m: expected a number in (0, 100], got -0.025"),
    ({"square_m": float("nan")}, "square_m: expected a finite number, got nan"),
    ({"square_m": None}, "square_m: expected a finite number, got None"),
    ({"terms": []}, "terms: expected one of k1, k1,k2"),
]


@pytest.mark.parametrize("fields, message", BAD)
def test_bad_input_is_one_line_and_sets_nothing(server, session, fields, message):
    status, answer = post(server, "api/checkerboard", request(**fields))
    assert status == 400 and answer["error"].startswith(message) and "\n" not in answer["error"], answer
    assert "/tmp" not in answer["error"]  # the photographs' temporary folder is not the user's business
    assert session.lens is None and session.lens_fit is None and session.camera_file is None
    assert not any(session.out_dir.iterdir())


def test_a_body_over_the_servers_bound_is_refused(server, session):
    """An upload over MAX_BOARD_BODY is refused from its Content-Length (413), before a byte of it is read."""
    status, answer = raw(server, f"POST /api/checkerboard HTTP/1.1\r\nContent-Type: application/json\r\n"
                                 f"Content-Length: {MAX_BOARD_BODY + 1}")
    assert status == 413 and answer["error"] == (f"Content-Length: expected a JSON body of 1 byte to {MAX_BOARD_BODY} "
                                                 f"bytes, got {MAX_BOARD_BODY + 1}")
    assert session.lens is None and session.lens_fit is None


def test_photographs_over_the_other_endpoints_bound_are_read(server, session):
    """A body between MAX_BODY and MAX_BOARD_BODY reaches the checkerboard (its first photograph, not an image, is
    what it refuses: the body was read whole) and is refused (413) by every other endpoint from its length."""
    body = json.dumps(request(photos=photos(b"\0" * (MAX_BODY * 3 // 4 + 2**20), GREY, GREY))).encode()
    assert MAX_BODY < len(body) <= MAX_BOARD_BODY
    status, answer = post(server, "api/checkerboard", body)
    assert status == 400 and answer["error"].startswith("photos: 0.png: not a readable image"), answer
    for endpoint in set(api.ENDPOINTS) - {"checkerboard"}:
        status, answer = raw(server, f"POST /api/{endpoint} HTTP/1.1\r\nContent-Type: application/json\r\n"
                                     f"Content-Length: {len(body)}")
        assert status == 413 and answer["error"] == (f"Content-Length: expected a JSON body of 1 byte to {MAX_BODY} "
                                                     f"bytes, got {len(body)}"), endpoint


@pytest.mark.slow  # the boards are rendered (3 s)
def test_calibration_recovers_the_lens_and_the_session_maps_through_it(session, tmp_path, capsys, monkeypatch):
    """Boards rendered through TRUE plus one without a board: k1 within K1_RTOL and every frame pixel undistorted by
    the session within 1 px of OpenCV's undistortion through TRUE (the lens tests' bound); the no-board photograph
    is named; Save lens writes lens.json and the photographs, and the command it prints writes the same lens.json."""
    images = [*board_pngs(), GREY]
    names = [f"board{i}.png" for i in range(len(POSES))] + ["empty.png"]
    answer = api.checkerboard(session, {"photos": photos(*images, names=names), "pattern": "9x6", "square_m": 0.025})
    k1 = answer["lens"]["distortion"][0]
    assert abs(k1 - TRUE[0]) < K1_RTOL * abs(TRUE[0]), k1
    assert answer["fit"]["frames"] == sorted(names[:-1]) and answer["fit"]["missing"] == ["empty.png"]
    assert 0 < answer["fit"]["rms_px"] < 0.5  # rendered corners: bilinear sampling, sub-pixel corner refinement
    assert answer["summary"].startswith(f"board found in {len(POSES)} of {len(names)} photographs (not in empty.png), "
                                        f"RMS reprojection error {answer['fit']['rms_px']:.3f} px")
    grid = np.stack(np.meshgrid(np.linspace(0, SIZE[0] - 1, 9), np.linspace(0, SIZE[1] - 1, 5)), -1).reshape(-1, 2)
    truth = cv2.undistortPoints(grid.reshape(-1, 1, 2), K, TRUE, criteria=EXACT).reshape(-1, 2)  # normalised
    mine = undistorted(session, grid, "grid")  # the session's undistorted pixels, in its lens's K
    mine = (mine - session.lens.K[:2, 2]) / session.lens.K[[0, 1], [0, 1]]
    assert np.abs(mine - truth).max() * K[0, 0] < 1.0
    assert session.camera_file == session.out_dir / api.LENS_FILE

    saved = api.save_lens(session, {})
    lens_json = json.loads((session.out_dir / api.LENS_FILE).read_text())
    assert lens_json["distortion"] == answer["lens"]["distortion"]
    assert sorted(p.name for p in (session.out_dir / api.BOARD_DIR).iterdir()) == sorted(names)
    args = shlex.split(saved["command"])
    assert args[:3] == ["homocal", "lens", "--checkerboard"]
    args[args.index("-o") + 1] = str(tmp_path / "cli_lens.json")
    r = homocal_main(*args[1:], cwd=tmp_path, capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "cli_lens.json").read_text()) == lens_json

    # Save again after another calibration: the photographs it wrote and no longer names are removed (the glob
    # would read them); a file it did not write in that folder is refused
    api.checkerboard(session, {"photos": photos(*board_pngs()[:4]), "pattern": "9x6", "square_m": 0.025})
    api.save_lens(session, {})
    assert sorted(p.name for p in (session.out_dir / api.BOARD_DIR).iterdir()) == [f"{i}.png" for i in range(4)]
    trapezoid = {"image": [[200.0, 150.0], [440.0, 150.0], [600.0, 330.0], [40.0, 330.0]],
                 "map": SITE.to_pixels(np.array([[-3.0, 30.0], [3.0, 30.0], [3.0, 8.0], [-3.0, 8.0]])).tolist()}
    fit = api.save(session, {"trapezoid": trapezoid, "camera_origin": [0, 0], "method": "least-change",
                             "points": [[320.0, 300.0, 0.0, 9.0], [300.0, 200.0, 0.5, 20.0], [340.0, 170.0, -0.5, 27.0]]})
    assert str(session.out_dir / api.LENS_FILE) in fit["written"] and fit["lens_command"] == api.save_lens(session, {})["command"]
    assert f"--camera-json {session.out_dir / api.LENS_FILE}" in fit["command"]
    (session.out_dir / api.BOARD_DIR / "mine.png").write_bytes(GREY)
    with pytest.raises(api.Refused, match=r"mine.png in .*: not a photograph of this calibration"):
        api.save_lens(session, {})
    assert (session.out_dir / api.BOARD_DIR / "mine.png").read_bytes() == GREY


@pytest.mark.browser
@pytest.mark.slow
def test_checkerboard_in_a_browser(browser, session, tmp_path):  # noqa: F811
    """Choose the photographs in the page's file input, Calibrate: the session's lens is the calibration's (k1
    within K1_RTOL of TRUE), the page shows the summary; photographs over the server's bound are refused on the
    page before any request, in the status line."""
    folder = tmp_path / "photos"
    folder.mkdir()
    for i, data in enumerate(board_pngs()):
        (folder / f"{i}.png").write_bytes(data)
    with open(folder / "huge.png", "wb") as f:  # its size over the bound (sparse: the page refuses it unread)
        f.truncate(MAX_BOARD_BODY)
    d = browser
    with ui_server("--frame", str(tmp_path / "frame.png"), "--site-map", str(tmp_path / "map.png"), "--scale", "10",
                   "--origin", "200,700", "--out", str(session.out_dir)) as url:
        d.get(url)
        wait_for(d, "document.body.dataset.ready === '1'")
        chooser = d.find_element(By.ID, "board-photos")
        chooser.send_keys(str(folder / "huge.png"))
        d.find_element(By.ID, "calibrate").click()
        wait_for(d, "document.getElementById('message').textContent.startsWith('photos: ')")
        assert "MiB of photographs; the server takes at most" in d.find_element(By.ID, "message").text
        assert js(d, "window.homocalUI.S.lens") is None

        chooser.clear()
        chooser.send_keys("\n".join(str(folder / f"{i}.png") for i in range(len(POSES))))
        d.find_element(By.ID, "board-pattern").clear()
        d.find_element(By.ID, "board-pattern").send_keys("9x6")
        d.find_element(By.ID, "calibrate").click()
        wait_for(d, "window.homocalUI.S.lens !== null", timeout=30)
        idle(d)
        fit = js(d, "window.homocalUI.S.lens")
        k1 = fit["lens"]["distortion"][0]
        assert abs(k1 - TRUE[0]) < K1_RTOL * abs(TRUE[0]), k1
        assert fit["fit"]["frames"] == [f"{i}.png" for i in range(len(POSES))] and fit["fit"]["missing"] == []
        assert d.find_element(By.ID, "message").text.startswith(f"lens calibrated: board found in {len(POSES)} of "
                                                                f"{len(POSES)} photographs, RMS reprojection error")
        d.find_element(By.ID, "save-lens").click()
        wait_for(d, "document.getElementById('lens-summary').textContent.startsWith('wrote')")
        assert json.loads((session.out_dir / api.LENS_FILE).read_text())["distortion"] == fit["lens"]["distortion"]
        assert "homocal lens --checkerboard" in d.find_element(By.ID, "lens-summary").text
        assert [e for e in d.get_log("browser") if e["source"] == "javascript"] == []

"""The page's line tool: polylines clicked along edges straight in the world give the lens (homocal lens --lines's
fit), which the session then uses; Save writes lines.json and lens.json as that command does. The lines are
scene3's straight ground lines seen through its camera.json's lens (cv2.projectPoints, not the Lens under test)."""
from __future__ import annotations

import json
import shlex
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import Select
from test_browser import ENV, browser, click, idle, js, ui_server, wait_for  # noqa: F401 (browser: the fixture)

from homocal.geometry import SiteMap
from homocal.ui import api
from homocal.ui.session import from_files
from simgen.scene import load_scene

CAM = load_scene(Path(__file__).resolve().parents[2] / "simgen" / "scenes" / "scene3").camera  # camera.json's
SIZE = (CAM.width, CAM.height)
TRUE = np.array(CAM.distortion, dtype=float)  # [k1, k2, p1, p2, k3]
SITE = SiteMap(10.0, (200.0, 700.0))
GROUND_LINES = [((x, 2.0), (x, 80.0)) for x in (-8.0, -4.0, 4.0, 8.0)] + [((-30.0, y), (30.0, y)) for y in (6.0, 9.0, 14.0)]
PER_LINE = 8
MARGIN_PX = 2.0  # clicks stay this far inside the frame


def seen(ground: np.ndarray) -> np.ndarray:
    """Ground points (N, 2) m -> the distorted frame's pixels, by cv2.projectPoints with camera.json's pose and lens."""
    world = np.column_stack([ground, np.zeros(len(ground))])
    p, _ = cv2.projectPoints(world, cv2.Rodrigues(CAM.R)[0], CAM.t.astype(float), CAM.K, TRUE)
    return p.reshape(-1, 2)


def clicked_lines() -> list[np.ndarray]:
    """PER_LINE points of each ground line, evenly along the part in front of the camera and inside the frame."""
    out = []
    for a, b in GROUND_LINES:
        g = np.linspace(a, b, 4000)
        p = seen(g)
        depth = (np.column_stack([g, np.zeros(len(g))]) @ CAM.R.T + CAM.t)[:, 2]
        p = p[(depth > 0) & (p >= MARGIN_PX).all(axis=1) & (p <= np.array(SIZE) - 1 - MARGIN_PX).all(axis=1)]
        out.append(p[np.linspace(0, len(p) - 1, PER_LINE).round().astype(int)])
    return out


@pytest.fixture
def files(tmp_path) -> dict:
    """frame.png (the lines drawn curved, as the lens shows them) and map.png."""
    frame = np.full((SIZE[1], SIZE[0], 3), 90, np.uint8)
    for a, b in GROUND_LINES:
        g = np.linspace(a, b, 4000)
        depth = (np.column_stack([g, np.zeros(len(g))]) @ CAM.R.T + CAM.t)[:, 2]
        p = seen(g[depth > 0])
        cv2.polylines(frame, [np.round(p[(np.abs(p) < 1e4).all(axis=1)]).astype(np.int32)], False, (230, 230, 230), 2)
    cv2.imwrite(str(tmp_path / "frame.png"), frame)
    cv2.imwrite(str(tmp_path / "map.png"), np.full((800, 400, 3), 60, np.uint8))
    (tmp_path / "out").mkdir()
    return {"frame": tmp_path / "frame.png", "map": tmp_path / "map.png", "out": tmp_path / "out"}


@pytest.mark.parametrize("lines, message", [
    ([[[100.0, 100.0], [200.0, 120.0]]], "lines: line 0: 2 points; a line needs at least 3"),
    ([[[100.0, 100.0], [200.0, None], [300.0, 140.0]]], "lines: line 0: a point is not a finite number"),
    ([[[540.0, 260.0], [640.0, 360.0], [740.0, 460.0]], [[640.0, 200.0], [640.0, 360.0], [640.0, 500.0]]],
     "lines: every line passes within"),
    ([[[100.0, 100.0], [200.0, 120.0], [1400.0, 140.0]]], "lines: line 0: a point lies outside the 1280x720 frame"),
])
def test_bad_lines_are_one_line(files, lines, message):
    session = from_files(files["frame"], files["map"], SITE, (0.0, 0.0), files["out"])
    with pytest.raises(ValueError, match=message.replace("(", r"\(")):
        api.lens(session, {"lines": lines})
    assert session.lens is None and session.lens_fit is None


def test_save_writes_the_lens_the_fit_names(files):
    """After a lens from lines, Save writes lines.json and lens.json with the correction, and its command names them."""
    session = from_files(files["frame"], files["map"], SITE, (0.0, 0.0), files["out"])
    api.lens(session, {"lines": [line.tolist() for line in clicked_lines()], "terms": "k1,k2,p1,p2"})
    ground = np.array([[-3.0, 30.0], [3.0, 30.0], [3.0, 8.0], [-3.0, 8.0]])
    req = {"trapezoid": {"image": seen(ground).tolist(), "map": SITE.to_pixels(ground).tolist()},
           "camera_origin": [0, 0], "points": [], "method": "horizon"}
    saved = api.save(session, {**req, "method": "least-change", "points": [
        [*seen(g[None])[0], *g] for g in np.array([[0.0, 10.0], [2.0, 20.0], [-2.0, 35.0]])]})
    lens_path = files["out"] / api.LENS_FILE
    assert str(lens_path) in saved["written"] and str(files["out"] / api.LINES_FILE) in saved["written"]
    assert f"--camera-json {lens_path}" in saved["command"] and saved["lens_command"].startswith("homocal lens --lines")
    assert json.loads((files["out"] / "correction.json").read_text())["lens"] == {
        k: v for k, v in json.loads(lens_path.read_text()).items() if k != "fit"}


@pytest.mark.browser
@pytest.mark.slow
def test_line_tool_in_a_browser(browser, files):  # noqa: F811
    """Click scene3's curved ground lines with the mouse, fit k1, k2, p1, p2: k1 within 5 % of camera.json's and
    within 4 of the fit's own 1-sigma (from the clicks' scatter: a click lands on a whole CSS pixel, +-0.5 / zoom
    frame px, sd 0.29 / zoom, ~0.4 px here; 20 simulated click sets at this zoom gave k1's sd 0.0026, 0.9 % of
    it). The horizon is then drawn through the lens, and the saved lens.json is what homocal lens --lines gives
    on the saved lines.json."""
    d = browser
    with ui_server("--frame", str(files["frame"]), "--site-map", str(files["map"]), "--scale", "10", "--origin",
                   "200,700", "--out", str(files["out"])) as url:
        d.get(url)
        wait_for(d, "document.body.dataset.ready === '1'")
        d.find_element(By.ID, "mode-lines").click()
        lines = clicked_lines()
        for line in lines:
            for p in line:
                click(d, "frame", p)
            d.find_element(By.ID, "end-line").click()
        got = js(d, "window.homocalUI.S.lines.filter((l) => l.length)")
        zoom = js(d, "window.homocalUI.views.frame.zoom")
        assert [len(g) for g in got] == [PER_LINE] * len(lines)
        assert np.abs(np.concatenate(got) - np.concatenate(lines)).max() <= 0.5 / zoom + 0.05 + 1e-9
        assert d.find_element(By.ID, "lines-count").text == f"{len(lines)} lines, {PER_LINE * len(lines)} points"

        Select(d.find_element(By.ID, "lens-terms")).select_by_visible_text("k1,k2,p1,p2")
        d.find_element(By.ID, "fit-lens").click()
        wait_for(d, "window.homocalUI.S.lens !== null")
        idle(d)
        fit = js(d, "window.homocalUI.S.lens")
        k1, sigma = fit["lens"]["distortion"][0], fit["fit"]["sigma"][0]
        assert abs(k1 - TRUE[0]) < 0.05 * abs(TRUE[0]) and abs(k1 - TRUE[0]) < 4 * sigma, (k1, sigma)
        assert d.find_element(By.ID, "message").text.startswith("lens fitted: 7 lines, 56 points")

        # four corners and the view: the horizon now comes through the lens (a curve of many points)
        d.find_element(By.ID, "mode-trapezoid").click()
        ground = np.array([[-3.0, 30.0], [3.0, 30.0], [3.0, 8.0], [-3.0, 8.0]])
        for q, m in zip(seen(ground), SITE.to_pixels(ground)):
            click(d, "frame", q)
            click(d, "map", m)
            idle(d)
        assert len(js(d, "window.homocalUI.S.view.horizon")) > 10

        d.find_element(By.ID, "save-lens").click()
        wait_for(d, "document.getElementById('lens-summary').textContent.startsWith('wrote')")
        command = d.find_element(By.ID, "lens-summary").text.split("same as: ", 1)[1]
        args = shlex.split(command)
        assert args[:3] == ["homocal", "lens", "--lines"]
        saved = json.loads((files["out"] / "lens.json").read_text())
        cli_out = files["out"].parent / "cli_lens.json"
        args[args.index("-o") + 1] = str(cli_out)
        subprocess.run([sys.executable, "-m", "homocal.cli", *args[1:]], check=True, capture_output=True, text=True,
                       env=ENV)
        assert json.loads(cli_out.read_text()) == saved
        assert saved["distortion"] == fit["lens"]["distortion"]
        assert [e for e in d.get_log("browser") if e["source"] == "javascript"] == []

"""`homocal ui` with a boxes file that spans a camera move: the horizon over time and the detected moves
(homocal.watch.OnlineCalibrator over the session's boxes), from the API and as the page draws them in Chromium.
The boxes are simgen.boxstream's render-free ones of scene1's walkers (no rendering), seen by the scene's camera
and by the same camera tilted STEP_DEG further down from AT_S on."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import cv2
import numpy as np
import pytest
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import Select
from test_browser import browser, click, idle, js, ui_server, wait_for  # noqa: F401 (browser: the fixture)

from homocal.geometry import SiteMap
from homocal.ui import api
from homocal.ui.session import from_files
from simgen.boxstream import bodies, boxes_of
from simgen.scene import load_scene

slow = pytest.mark.slow  # the stream (files): ~3 s of simgen's walkers
SCENE = load_scene(Path(__file__).resolve().parents[2] / "simgen" / "scenes" / "scene1")
CAM = SCENE.camera
SECONDS, FPS, AT_S, STEP_DEG = 120, 1.0, 60.0, 2.0  # scene1 gives ~60 people in 120 s: 40 before the step
SITE = SiteMap(10.0, (200.0, 700.0))
GROUND = SCENE.trapezoid_ground
TRAP = {"image": CAM.project_ground(GROUND).tolist(), "map": SITE.to_pixels(GROUND).tolist()}
PRIOR = {"height_mean_m": 1.71, "height_sd_m": 0.09}  # simgen's people (data_schema.md)


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict:
    """frame.png, map.png, and the boxes of the moving camera (moved.csv) and of the steady one (static.csv): CSV
    with track ids, corner pixels (homocal edges + 0.5)."""
    folder = tmp_path_factory.mktemp("watch_ui")
    moved = dataclasses.replace(CAM, tilt_deg=CAM.tilt_deg + STEP_DEG)
    lines = {"moved": ["frame,x1,y1,x2,y2,track_id"], "static": ["frame,x1,y1,x2,y2,track_id"]}
    for frame, segments, radii, ids in bodies(SCENE, 0, SECONDS, FPS):
        for name, cam in (("static", CAM), ("moved", moved if frame / FPS >= AT_S else CAM)):
            xyxy, seen = boxes_of(cam, segments, radii)
            lines[name] += [f"{frame},{','.join(repr(float(x) + 0.5) for x in b)},{i}" for b, i in zip(xyxy, ids[seen])]
    out = {name: folder / f"{name}.csv" for name in lines}
    for name, path in out.items():
        path.write_text("\n".join(lines[name]) + "\n")
    out["frame"], out["map"] = folder / "frame.png", folder / "map.png"
    cv2.imwrite(str(out["frame"]), np.full((CAM.height, CAM.width, 3), 90, np.uint8))
    cv2.imwrite(str(out["map"]), np.full((800, 400, 3), 60, np.uint8))
    return out


def watched(files, tmp_path, name: str) -> dict:
    session = from_files(files["frame"], files["map"], SITE, (0.0, 0.0), tmp_path, boxes=files[name], fps=FPS)
    return api.watch(session, {"trapezoid": TRAP, "camera_origin": [0, 0], "camera_height_m": CAM.mount_height_m,
                               **PRIOR})


@slow
def test_the_api_gives_the_move_and_the_horizon_over_time(files, tmp_path):
    w = watched(files, tmp_path, "moved")
    before, after = CAM.horizon_row, dataclasses.replace(CAM, tilt_deg=CAM.tilt_deg + STEP_DEG).horizon_row
    assert len(w["moves"]) == 1
    m = w["moves"][0]
    # the change point within 10 s of the step (a person is seen for ~5 s before giving its row), found after it
    assert AT_S - 10 <= m["t_s"] <= AT_S + 10 and AT_S < m["detected_s"] < AT_S + 30
    assert abs(m["horizon_before"] - before) < 5 * m["sigma_before"]
    assert abs(m["horizon_after"] - after) < 5 * m["sigma_after"]
    assert w["column"] == pytest.approx(CAM.K[0, 2], abs=1e-6)
    assert w["clicked_row"] == pytest.approx(before, abs=1e-6)  # the true trapezoid's horizon
    assert [s["start_s"] for s in w["stretches"]] == [0.0, m["t_s"]]
    assert len(w["people"]["t"]) == len(w["people"]["row"]) > 40 and w["people"]["t"] == sorted(w["people"]["t"])
    assert f"1 move detected; at {m['t_s']:.1f} s" in w["summary"]


@slow
def test_with_the_roll_the_stretches_and_their_correction_carry_it(files, tmp_path):
    """The request's estimate_roll (the pedestrians fit's) makes the watch estimate the roll: each stretch has a roll
    with its sigma, the summary gives each move's, and the picked stretch's correction is that roll's."""
    session = from_files(files["frame"], files["map"], SITE, (0.0, 0.0), tmp_path, boxes=files["moved"], fps=FPS)
    req = {"trapezoid": TRAP, "camera_origin": [0, 0], "camera_height_m": CAM.mount_height_m, **PRIOR,
           "estimate_roll": True}
    w = api.watch(session, req)
    assert len(w["moves"]) == 1 and all(s["roll_sigma_deg"] is not None for s in w["stretches"])
    m = w["moves"][0]
    assert f"the roll {m['roll_before_deg']:.2f} -> {m['roll_after_deg']:.2f} degrees" in w["summary"]
    corrector, settings = api._stretch(session, {**req, "at_s": SECONDS - 1.0})
    assert settings["stretch"] == (m["t_s"], SECONDS - 1.0) and corrector.roll_estimated_
    assert corrector.roll_deg_ == pytest.approx(w["stretches"][-1]["roll_deg"], abs=1e-9)
    assert corrector.roll_sigma_deg_ == pytest.approx(w["stretches"][-1]["roll_sigma_deg"], rel=1e-9)


@slow
def test_a_steady_camera_shows_no_move(files, tmp_path):
    w = watched(files, tmp_path, "static")
    assert w["moves"] == [] and len(w["stretches"]) == 1
    assert abs(w["stretches"][0]["horizon_row"] - CAM.horizon_row) < 5 * w["stretches"][0]["sigma_px"]


@slow
def test_without_a_frame_rate_the_page_says_so(files, tmp_path):
    session = from_files(files["frame"], files["map"], SITE, (0.0, 0.0), tmp_path, boxes=files["moved"])
    with pytest.raises(ValueError, match="fps: moved.csv does not say its frame rate: start homocal ui with --fps"):
        api.watch(session, {"trapezoid": TRAP, "camera_origin": [0, 0]})


@slow
@pytest.mark.browser
@pytest.mark.parametrize("name, moves", [("moved", 1), ("static", 0)])
def test_the_page_draws_the_horizon_over_time(browser, files, tmp_path, name, moves):  # noqa: F811
    """The page's plot: the people, the band, the clicked horizon, and a magenta line at each detected move
    (canvas pixels), none for the steady camera."""
    d = browser
    with ui_server(*page_args(files, files[name], tmp_path)) as url:
        open_with_trapezoid(d, url)
        assert js(d, "window.homocalUI.S.view.complete")
        assert not d.find_element(By.ID, "plot-box").is_displayed()
        d.find_element(By.ID, "watch").click()
        wait_for(d, "window.homocalUI.S.watch !== null")
        assert d.find_element(By.ID, "plot-box").is_displayed()
        plot = js(d, "window.homocalUI.drawn.plot")
        answer = js(d, "window.homocalUI.S.watch")
        assert len(answer["moves"]) == moves == len(plot["moves"])
        assert plot["people"] == len(answer["people"]["t"]) > 40 and plot["band"] > 20
        assert [r["name"] for r in plot["references"]] == ["clicked"]
        columns = magenta_columns(d)
        assert bool(columns) == bool(moves)  # a magenta line where a move is, nowhere else
        assert all(min(abs(c - m["x"]) for m in plot["moves"]) <= 2 for c in columns)
        assert d.find_element(By.ID, "watch-summary").text.startswith(f"{len(answer['people']['t'])} people over")
        if moves:  # a click on the plot late in the file picks the last stretch; a fit is then its correction
            box = d.find_element(By.ID, "timeplot").rect
            ActionChains(d).move_to_element_with_offset(d.find_element(By.ID, "timeplot"), box["width"] // 2 - 15,
                                                         0).click().perform()
            assert js(d, "window.homocalUI.S.at") > answer["moves"][0]["t_s"]
            assert "Fit with pedestrians uses its correction" in d.find_element(By.ID, "watch-summary").text
            Select(d.find_element(By.ID, "method")).select_by_visible_text("pedestrians")
            d.find_element(By.ID, "fit").click()
            wait_for(d, "window.homocalUI.S.fit !== null")
            fitted = js(d, "window.homocalUI.S.fit.correction.fitted.horizon_row")
            assert fitted == pytest.approx(answer["stretches"][-1]["horizon_row"], abs=1e-9)
            assert [r["name"] for r in js(d, "window.homocalUI.drawn.plot")["references"]] == ["clicked", "fitted"]
        assert [e for e in d.get_log("browser") if e["source"] == "javascript"] == []


def page_args(files, boxes: Path, out: Path) -> list[str]:
    """homocal ui's arguments for the test frame and map with a boxes file at FPS."""
    return ["--frame", str(files["frame"]), "--site-map", str(files["map"]), "--scale", "10", "--origin", "200,700",
            "--boxes", str(boxes), "--fps", str(FPS), "--out", str(out)]


def open_with_trapezoid(driver, url: str) -> None:
    """Open the page at url, once ready click TRAP's four corners on the frame and the map."""
    driver.get(url)
    wait_for(driver, "document.body.dataset.ready === '1'")
    for i in range(4):
        click(driver, "frame", TRAP["image"][i])
        click(driver, "map", TRAP["map"][i])
        idle(driver)


def magenta_columns(driver) -> list[int]:
    """The columns of the plot canvas with at least 40 pixels of the moves' magenta (#ff4fd8, +-30 a channel)."""
    return js(driver, """(() => {
        const c = document.getElementById('timeplot'), d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
        const count = new Array(c.width).fill(0);
        for (let i = 0; i < d.length; i += 4) {
          if (Math.abs(d[i] - 255) <= 30 && Math.abs(d[i + 1] - 79) <= 30 && Math.abs(d[i + 2] - 216) <= 30) count[(i / 4) % c.width]++;
        }
        return count.map((n, x) => (n >= 40 ? x : -1)).filter((x) => x >= 0); })()""")


@slow
def test_a_picked_stretch_is_the_fit_and_save_gives_homocal_watch_s(files, tmp_path):
    """Fit with at_s: the correction of the stretch at that time (its horizon, not the whole file's); Save writes it
    and names the homocal watch command whose corrections/<start_s>.json is the same file."""
    import json
    import shlex
    import subprocess
    import sys

    from test_browser import ENV

    session = from_files(files["frame"], files["map"], SITE, (0.0, 0.0), tmp_path, boxes=files["moved"], fps=FPS)
    req = {"trapezoid": TRAP, "camera_origin": [0, 0], "camera_height_m": CAM.mount_height_m, "points": [],
           "method": "pedestrians", **PRIOR}
    stretches = api.watch(session, req)["stretches"]
    late = api.fit(session, {**req, "at_s": SECONDS - 1})
    early = api.fit(session, {**req, "at_s": 10})
    assert late["correction"]["fitted"]["horizon_row"] == pytest.approx(stretches[1]["horizon_row"], abs=1e-9)
    assert early["correction"]["fitted"]["horizon_row"] == pytest.approx(stretches[0]["horizon_row"], abs=1e-9)
    saved = api.save(session, {**req, "at_s": SECONDS - 1})
    command, note = saved["command"].split(" (its ", 1)
    assert note.startswith(f"corrections/{stretches[1]['start_s']:.2f}.json")
    args = [str(tmp_path / "watch") if a == "WATCH_DIR" else a for a in shlex.split(command)]
    subprocess.run([sys.executable, "-m", "homocal.cli", *args[1:]], check=True, capture_output=True, text=True, env=ENV)
    theirs = json.loads((tmp_path / "watch" / "corrections" / f"{stretches[1]['start_s']:.2f}.json").read_text())
    assert theirs == json.loads((tmp_path / "correction.json").read_text())


def things(files, folder: Path) -> Path:
    """The steady camera's boxes with their heights scaled by 0.3-3 (things that are not people standing on the
    ground), as folder/things.csv."""
    rng = np.random.default_rng(0)
    header, *rows = files["static"].read_text().splitlines()
    scaled = []
    for row in rows:
        frame, x1, y1, x2, y2, track = row.split(",")
        top = float(y2) - (float(y2) - float(y1)) * rng.uniform(0.3, 3.0)
        scaled.append(f"{frame},{x1},{top!r},{x2},{y2},{track}")
    (folder / "things.csv").write_text("\n".join([header, *scaled]) + "\n")
    return folder / "things.csv"


REFUSED = r"people are outliers \(implied height beyond 3 sd of 1.71 m at the horizon row"


@slow
def test_a_stretch_of_boxes_that_are_not_people_is_refused_on_the_page(files, tmp_path):
    """Boxes of things: the page's stretch counts its people beyond 3 sd (more than half), says it is refused with
    homocal watch's refusal (homocal.watch.calibrator.stretch_correction), and a fit at its time is refused with it,
    as homocal apply refuses it; the people's stretches are not."""
    session = from_files(files["frame"], files["map"], SITE, (0.0, 0.0), tmp_path, boxes=things(files, tmp_path), fps=FPS)
    req = {"trapezoid": TRAP, "camera_origin": [0, 0], "camera_height_m": CAM.mount_height_m, "points": [],
           "method": "pedestrians", **PRIOR}
    last = api.watch(session, req)["stretches"][-1]
    assert last["n_outliers"] > last["n_people"] / 2
    with pytest.raises(ValueError, match=REFUSED) as refusal:
        api.fit(session, {**req, "at_s": SECONDS - 1})
    assert str(refusal.value).endswith(last["refused"])
    for name in ("static", "moved"):
        people = from_files(files["frame"], files["map"], SITE, (0.0, 0.0), tmp_path, boxes=files[name], fps=FPS)
        assert [s["refused"] for s in api.watch(people, req)["stretches"]] == [None] * (1 if name == "static" else 2)


@slow
@pytest.mark.browser
def test_the_page_shades_a_refused_stretch(browser, files, tmp_path):  # noqa: F811
    """The plot shades a refused stretch red across its time span, and picking a time in it says homocal watch
    refuses its correction."""
    d = browser
    with ui_server(*page_args(files, things(files, tmp_path), tmp_path)) as url:
        open_with_trapezoid(d, url)
        Select(d.find_element(By.ID, "method")).select_by_visible_text("pedestrians")  # its fields shown
        for field, value in (("camera-height", CAM.mount_height_m), ("height-mean", PRIOR["height_mean_m"]),
                             ("height-sd", PRIOR["height_sd_m"])):  # the API test's settings
            d.find_element(By.ID, field).clear()
            d.find_element(By.ID, field).send_keys(str(value))
        d.find_element(By.ID, "watch").click()
        wait_for(d, "window.homocalUI.S.watch !== null")
        stretches = js(d, "window.homocalUI.S.watch.stretches")
        shaded = js(d, "window.homocalUI.drawn.plot.refused")
        assert [s["start_s"] for s in stretches if s["refused"]] == [s["start_s"] for s in shaded] != []
        box = d.find_element(By.ID, "timeplot").rect
        ActionChains(d).move_to_element_with_offset(d.find_element(By.ID, "timeplot"), box["width"] // 2 - 15,
                                                     0).click().perform()
        assert "homocal watch refuses its correction" in d.find_element(By.ID, "watch-summary").text
        assert [e for e in d.get_log("browser") if e["source"] == "javascript"] == []


@pytest.mark.parametrize("rows, message", [
    (["3,100,300,120,360,1", "2,100,300,120,360,1"], "box 1 (from 0) is in frame 2 after frame 3: boxes out of time order"),
    (["0,100,300,120,100,1"], "boxes.csv, line 2: the box is upside down or empty"),
])
def test_bad_boxes_are_one_line(tmp_path, rows, message):
    """Boxes out of time order (or upside down) are refused with the reader's or the watch's one line."""
    cv2.imwrite(str(tmp_path / "frame.png"), np.full((CAM.height, CAM.width, 3), 90, np.uint8))
    cv2.imwrite(str(tmp_path / "map.png"), np.full((800, 400, 3), 60, np.uint8))
    (tmp_path / "boxes.csv").write_text("frame,x1,y1,x2,y2,track_id\n" + "\n".join(rows) + "\n")
    session = from_files(tmp_path / "frame.png", tmp_path / "map.png", SITE, (0.0, 0.0), tmp_path,
                         boxes=tmp_path / "boxes.csv", fps=FPS)
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        api.watch(session, {"trapezoid": TRAP, "camera_origin": [0, 0], "camera_height_m": 4.0})

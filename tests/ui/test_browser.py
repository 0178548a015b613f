"""`homocal ui` in a real headless browser (Debian's chromium driven by selenium through chromium-driver):
click a trapezoid on a simgen frame and its site map, add three reference points, fit, probe, save, load,
and check that the saved files give the same correction as `homocal fit` on them; fit the pedestrian
correction from the dataset's boxes, see its horizon drawn, and apply what Save wrote; what the page shows as its
state changes (its status line, labels, ellipses, fields and boxes). scripts/screenshots.py takes the docs'
screenshots of the page."""
from __future__ import annotations

import contextlib
import csv
import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.actions.action_builder import ActionBuilder
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import Select, WebDriverWait

from homocal.dataset import load_dataset
from homocal.geometry import ViewTransformer

pytestmark = [pytest.mark.browser, pytest.mark.slow, pytest.mark.generate]  # Chromium pages over a rendered dataset

# Without these, chromium tries to reach the network at start (refused on a machine without one).
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--window-size=1400,1200")
METHOD = "hybrid"
ENV = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}  # this checkout's homocal
CALIBRATION_ROWS = (0, 15, 35)  # the calibration objects at 5, 20 and 40 m


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    options = webdriver.ChromeOptions()
    options.binary_location = "/usr/bin/chromium"
    for flag in (*CHROMIUM_FLAGS, f"--user-data-dir={tmp_path_factory.mktemp('chromium')}"):
        options.add_argument(flag)
    driver = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)
    yield driver
    driver.quit()


@contextlib.contextmanager
def ui_server(*args: str):
    """`homocal ui ARGS...` as a user starts it; yields the URL it prints (with its token)."""
    proc = subprocess.Popen([sys.executable, "-m", "homocal.cli", "ui", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
    try:
        line = proc.stdout.readline()
        match = re.search(r"http://127\.0\.0\.1:\d+/\?token=[\w-]+", line)  # the page's POSTs need the token
        assert match, f"no URL in {line!r}: {proc.stderr.read() if proc.poll() is not None else ''}"
        yield match.group(0)
    finally:
        proc.terminate()
        proc.wait(timeout=10)


@pytest.fixture
def server(tiny_dataset, tmp_path):
    """`homocal ui DATASET`; yields the URL it prints (with its token) and its --out folder."""
    out = tmp_path / "out"
    out.mkdir()
    with ui_server(str(tiny_dataset), "--out", str(out)) as url:
        yield url, out


def test_detector_names_are_shown_as_text(browser, tiny_dataset, tmp_path):
    """A detector name of the boxes file is an option's text, never HTML the page runs."""
    import pyarrow as pa

    name = '<img id="injected" src="x">'
    table = pq.read_table(tiny_dataset / "detections.parquet")
    table = table.set_column(table.schema.get_field_index("detector"), "detector",
                             pa.array([name] * table.num_rows, type=table.schema.field("detector").type))
    pq.write_table(table, tmp_path / "boxes.parquet")
    with ui_server(str(tiny_dataset), "--out", str(tmp_path / "out"), "--boxes", str(tmp_path / "boxes.parquet")) as url:
        browser.get(url)
        wait_for(browser, "document.body.dataset.ready === '1'")
        assert js(browser, "document.getElementById('injected')") is None
        assert js(browser, "Array.from(document.getElementById('detector').options, (o) => o.text)") == [name]


def js(driver, script: str, *args):
    return driver.execute_script(f"return {script};", *args)


def wait_for(driver, script: str, *args, timeout: float = 10):
    return WebDriverWait(driver, timeout).until(lambda d: js(d, script, *args), message=script)


def viewport_xy(driver, canvas: str, point) -> tuple[int, int]:
    """The browser-window pixel where the canvas draws image (or map) pixel ``point``."""
    x, y = js(driver, "((s, r) => [s[0] + r.left, s[1] + r.top])(window.homocalUI.toScreen(arguments[0], arguments[1]), "
                      "document.getElementById(arguments[0]).getBoundingClientRect())", canvas, [float(v) for v in point])
    return round(x), round(y)


def click(driver, canvas: str, point) -> None:
    """A real mouse click on the canvas at image (or map) pixel ``point``."""
    actions = ActionBuilder(driver)
    actions.pointer_action.move_to_location(*viewport_xy(driver, canvas, point)).click()
    actions.perform()


def drag(driver, canvas: str, point, dx: int, dy: int) -> None:
    """Press the mouse at image (or map) pixel ``point``, move it by (dx, dy) window pixels in 4 steps, release."""
    x, y = viewport_xy(driver, canvas, point)
    actions = ActionBuilder(driver)
    actions.pointer_action.move_to_location(x, y).pointer_down()
    for k in range(1, 5):
        actions.pointer_action.move_to_location(x + dx * k // 4, y + dy * k // 4)
    actions.pointer_action.pointer_up()
    actions.perform()


def idle(driver) -> None:
    """Wait until the page has no request to the server in flight."""
    wait_for(driver, "window.homocalUI.idle()")


def test_click_fit_save_load_in_a_browser(browser, server, tiny_dataset, tmp_path):
    url, out = server
    ds = load_dataset(tiny_dataset)
    image_quad, map_quad = ds.trapezoid_image, ds.trapezoid_map
    cal_image, cal_ground, _ = ds.calibration_points(source="segmentation")
    d = browser
    d.get(url)
    wait_for(d, "document.body.dataset.ready === '1'")
    S = "window.homocalUI.S"

    # A mirrored map is refused at its fourth corner: the corner is taken back and the reason shown.
    for i in (1, 0, 3, 2):
        click(d, "map", map_quad[i])
        idle(d)
    assert js(d, f"{S}.trap.map.length") == 3
    assert "mirrored" in d.find_element(By.ID, "message").text
    d.find_element(By.ID, "clear-trapezoid").click()
    idle(d)

    # The trapezoid, in order TL, TR, BR, BL: image corners on the frame, map corners on the site map.
    for i in range(4):
        click(d, "frame", image_quad[i])
        click(d, "map", map_quad[i])
        idle(d)
    trap = js(d, f"{S}.trap")
    assert np.abs(np.array(trap["image"]) - image_quad).max() < 1.0  # one CSS pixel is ~1.4 frame pixels

    # Dragging a corner moves it and redraws; the error bars come back when it is let go.
    zoom = js(d, "window.homocalUI.views.frame.zoom")
    drag(d, "frame", trap["image"][2], 12, 0)
    idle(d)
    assert js(d, f"{S}.trap.image[2][0]") == pytest.approx(trap["image"][2][0] + 12 / zoom, abs=0.8)
    assert js(d, f"{S}.trap.image[2][1]") == pytest.approx(trap["image"][2][1], abs=0.8)
    assert js(d, f"{S}.view.errorbars") is not None
    drag(d, "frame", js(d, f"{S}.trap.image[2]"), -12, 0)
    idle(d)
    trap = js(d, f"{S}.trap")
    assert np.abs(np.array(trap["image"]) - image_quad).max() < 1.0
    assert np.abs(np.array(trap["map"]) - map_quad).max() < 2.5
    assert js(d, f"{S}.view.complete") and js(d, f"{S}.view.grid.major.length") > 0
    assert js(d, f"{S}.view.footprint.length") > 0 and js(d, f"{S}.view.horizon") is not None
    assert js(d, f"{S}.view.errorbars.points.length") > 0
    assert re.match(r"trustworthy range .*: \d+\.\d m", d.find_element(By.ID, "errorbar-summary").text)

    # Three reference points: the feet of three calibration objects; the first ground position clicked on the
    # map, the others typed.
    d.find_element(By.ID, "mode-reference").click()
    for n, row in enumerate(CALIBRATION_ROWS):
        click(d, "frame", cal_image[row])
        if n == 0:
            click(d, "map", ds.site_map.to_pixels(cal_ground[row:row + 1])[0])
        else:
            for key, value in zip("xy", cal_ground[row]):
                field = d.find_element(By.CSS_SELECTOR, f'#points-table input[data-i="{n}"][data-key="{key}"]')
                field.clear()
                field.send_keys(repr(float(value)) + "\t")
    points = np.array(js(d, f"{S}.points.map((p) => [p.u, p.v, p.x, p.y])"), dtype=float)
    assert points.shape == (3, 4)
    assert np.abs(points[:, :2] - cal_image[list(CALIBRATION_ROWS)]).max() < 1.5
    assert np.abs(points[:, 2:] - cal_ground[list(CALIBRATION_ROWS)]).max() < 0.25

    # A bad setting is refused by the server and its message shown.
    tolerance = d.find_element(By.ID, "tolerance")
    tolerance.clear()
    tolerance.send_keys("-1\t")
    idle(d)
    assert "tolerance_m: expected a number in [0, 1e+06], got -1" in d.find_element(By.ID, "message").text
    tolerance.clear()
    tolerance.send_keys("0.5\t")
    idle(d)

    method = Select(d.find_element(By.ID, "method"))
    assert method.first_selected_option.text == "least-change"  # the page preselects homocal fit's default
    method.select_by_visible_text(METHOD)
    d.find_element(By.ID, "fit").click()
    wait_for(d, f"{S}.fit !== null")
    summary = d.find_element(By.ID, "fit-summary").text
    assert summary.startswith(f"{METHOD}: mean calibration error")

    d.find_element(By.ID, "mode-probe").click()
    click(d, "frame", (700.0, 520.0))
    wait_for(d, f"{S}.probe !== null")
    probe = js(d, f"{S}.probe")
    assert re.search(r"-> ground .* m; corrected .* m; 1-sigma ellipse", d.find_element(By.ID, "probe-summary").text)

    d.find_element(By.ID, "save").click()
    wait_for(d, "document.getElementById('files-summary').textContent.startsWith('wrote')")
    saved = json.loads((out / "correction.json").read_text())
    fit = js(d, f"{S}.fit")
    assert saved == fit["correction"]  # the file holds the fit the page shows

    # `homocal fit` on the saved trapezoid and points gives the same correction, to the bit.
    cli_out = tmp_path / "cli.json"
    cmd = [sys.executable, "-m", "homocal.cli", "fit", "--trapezoid", str(out / "trapezoid.json"),
           "--points", str(out / "reference_points.csv"), "--method", METHOD, "-o", str(cli_out),
           f"--camera-origin={saved['camera_origin'][0]!r},{saved['camera_origin'][1]!r}",
           "--seed", str(saved["params"]["seed"]), "--threshold", repr(saved["params"]["threshold"])]
    subprocess.run(cmd, check=True, capture_output=True, text=True, env=ENV)
    assert json.loads(cli_out.read_text()) == saved
    assert saved["camera_origin"] == ds.camera_origin.tolist()

    # The probe's ground position is the saved trapezoid's mapping of the clicked pixel.
    transformer = ViewTransformer(np.array(trap["image"]), ds.site_map.to_metres(np.array(trap["map"])))
    expected = transformer.transform_points(np.array([[probe["u"], probe["v"]]]))[0]
    np.testing.assert_allclose(probe["answer"]["ground"], expected, rtol=0, atol=1e-9)

    # Load reads the files back into an emptied page, and the refit shows the same correction.
    d.find_element(By.ID, "clear-trapezoid").click()
    d.find_element(By.ID, "clear-points").click()
    idle(d)
    d.find_element(By.ID, "load").click()
    wait_for(d, "document.getElementById('files-summary').textContent.startsWith('loaded')")
    idle(d)
    assert js(d, f"{S}.trap") == trap
    np.testing.assert_array_equal(js(d, f"{S}.points.map((p) => [p.u, p.v, p.x, p.y])"), points)
    assert js(d, f"{S}.fit.correction") == saved
    assert [entry for entry in d.get_log("browser") if entry["source"] == "javascript"] == []  # no script error


def horizon_at(segment, u: float) -> float:
    """The row at column u of a horizon segment [[u0, v0], [u1, v1]] (image px)."""
    (u0, v0), (u1, v1) = segment
    return v0 + (v1 - v0) * (u - u0) / (u1 - u0)


def drawn_share(driver, segment, rgb, samples: int = 60) -> float:
    """The share of ``samples`` columns across the frame canvas at which a pixel within 2 canvas px of the image
    line ``segment`` has colour ``rgb`` (+-40 a channel): how much of the line is drawn in that colour."""
    return js(driver, """((seg, rgb, n) => {
        const c = document.getElementById('frame'), ctx = c.getContext('2d'), W = window.homocalUI.S.info.frame.width;
        let hit = 0;
        for (let k = 0; k < n; k++) {
          const u = (k + 0.5) * W / n, v = seg[0][1] + (seg[1][1] - seg[0][1]) * (u - seg[0][0]) / (seg[1][0] - seg[0][0]);
          const [x, y] = window.homocalUI.toScreen('frame', [u, v]);
          const d = ctx.getImageData(Math.round(x) - 2, Math.round(y) - 2, 5, 5).data;
          for (let i = 0; i < d.length; i += 4) {
            if (Math.abs(d[i] - rgb[0]) <= 40 && Math.abs(d[i + 1] - rgb[1]) <= 40 && Math.abs(d[i + 2] - rgb[2]) <= 40) { hit++; break; }
          }
        }
        return hit / n; })(arguments[0], arguments[1], arguments[2])""", segment, list(rgb), samples)


def test_pedestrians_fit_save_apply_in_a_browser(browser, server, tiny_dataset, tmp_path):
    """`homocal ui DATASET` with method pedestrians: the dataset's hand-placed trapezoid, the fit from its
    segmentation boxes at its mount height, the fitted horizon drawn (orange) beside the clicked one (red);
    Save's printed command writes the same correction, and `homocal apply` maps with the saved one."""
    from homocal import load_corrector, sigma_radius

    url, out = server
    ds = load_dataset(tiny_dataset)
    d = browser
    d.get(url)
    wait_for(d, "document.body.dataset.ready === '1'")
    S = "window.homocalUI.S"
    d.find_element(By.ID, "use-hand-placed").click()
    idle(d)
    assert js(d, f"{S}.view.complete") and js(d, f"{S}.view.horizon") is not None

    Select(d.find_element(By.ID, "method")).select_by_visible_text("pedestrians")
    assert d.find_element(By.ID, "boxes-fields").is_displayed()
    assert Select(d.find_element(By.ID, "detector")).first_selected_option.text == "segmentation"
    assert float(d.find_element(By.ID, "camera-height").get_attribute("value")) == ds.camera.mount_height_m
    d.find_element(By.ID, "fit").click()
    wait_for(d, f"{S}.fit !== null")
    idle(d)
    summary = d.find_element(By.ID, "fit-summary").text
    assert summary.startswith("pedestrians: no check points") and "people (tracks):" in summary
    fit = js(d, f"{S}.fit")
    clicked = js(d, f"{S}.view.horizon")
    hidden = Select(d.find_element(By.ID, "drop-hidden-feet"))  # a yes, no or auto setting: a choice, at its default
    assert [o.text for o in hidden.options] == ["yes", "no", "auto"] and hidden.first_selected_option.text == "no"
    assert fit["correction"]["params"]["drop_hidden_feet"] is False
    cx = fit["correction"]["fitted"]["principal_point"][0]
    fitted_row = fit["correction"]["fitted"]["horizon_row"]
    assert horizon_at(fit["horizon"], cx) == pytest.approx(fitted_row, abs=1e-6)
    assert horizon_at(clicked, cx) == pytest.approx(ViewTransformer(ds.trapezoid_image, ds.trapezoid_map).horizon_row(cx), abs=1e-6)
    true_row = ds.camera.horizon_row
    assert abs(fitted_row - true_row) < abs(horizon_at(clicked, cx) - true_row)  # the people moved it nearer
    assert d.find_element(By.ID, "show-corrected").is_selected()
    # the fitted horizon in orange dashes (the corrected grid's orange covers at most ~30 % of a line elsewhere),
    # the clicked one in red dashes
    assert drawn_share(d, fit["horizon"], (0xFF, 0x9D, 0x2E)) > 0.6
    assert drawn_share(d, [[u, v + 40] for u, v in fit["horizon"]], (0xFF, 0x9D, 0x2E)) < 0.5
    assert drawn_share(d, clicked, (0xFF, 0x50, 0x50)) > 0.5

    d.find_element(By.ID, "mode-probe").click()
    click(d, "frame", (700.0, 400.0))
    wait_for(d, f"{S}.probe !== null")
    own = js(d, f"{S}.probe.answer.corrected_errorbars")  # the correction's own error bar
    assert own is not None and len(own["sigma"]) == 1
    assert "; corrected 1-sigma ellipse" in d.find_element(By.ID, "probe-summary").text

    d.find_element(By.ID, "save").click()
    wait_for(d, "document.getElementById('files-summary').textContent.startsWith('wrote')")
    saved = json.loads((out / "correction.json").read_text())
    assert saved == fit["correction"]
    command = d.find_element(By.ID, "files-summary").text.split("same as: ", 1)[1]
    args = shlex.split(command)
    assert args[:2] == ["homocal", "fit"] and "--detector" in args and "--camera-json" in args
    cli_out = tmp_path / "cli.json"
    args = [str(cli_out) if a == "CORRECTION.json" else a for a in args[1:]]
    subprocess.run([sys.executable, "-m", "homocal.cli", *args], check=True, capture_output=True, text=True, env=ENV)
    assert json.loads(cli_out.read_text()) == saved

    # homocal apply on the saved file: its mapping, and sigma_m from the correction's own error model
    gt = pq.read_table(tiny_dataset / "gt.parquet", columns=["u", "v", "in_frame"]).to_pydict()
    feet = np.array([(u, v) for u, v, inside in zip(gt["u"], gt["v"], gt["in_frame"]) if inside][::20])
    (tmp_path / "feet.csv").write_text("u,v\n" + "".join(f"{float(u)!r},{float(v)!r}\n" for u, v in feet))
    subprocess.run([sys.executable, "-m", "homocal.cli", "apply", str(out / "correction.json"), "--points",
                    str(tmp_path / "feet.csv"), "-o", str(tmp_path / "out.csv")], check=True, capture_output=True,
                   text=True, env=ENV)
    rows = list(csv.DictReader((tmp_path / "out.csv").open()))
    corrector = load_corrector(out / "correction.json")
    assert [r["status"] for r in rows] == ["ok"] * len(feet)
    np.testing.assert_allclose([[float(r["x"]), float(r["y"])] for r in rows], corrector.transform_points(feet), atol=1e-9)
    np.testing.assert_allclose([float(r["sigma_m"]) for r in rows], sigma_radius(corrector.ground_uncertainty(feet)),
                               rtol=1e-12)
    hidden.select_by_visible_text("auto")  # the page's choice reaches the fit
    d.find_element(By.ID, "fit").click()
    wait_for(d, f"{S}.fit !== null && {S}.fit.correction.params.drop_hidden_feet === 'auto'")
    assert [entry for entry in d.get_log("browser") if entry["source"] == "javascript"] == []  # no script error


# ---- what the page shows as its state changes (issue 35): one server for the module's tests below -----------------
@pytest.fixture(scope="module")
def page(browser, tiny_dataset, tmp_path_factory):
    """`homocal ui DATASET` started once, the page loaded with the dataset's hand-placed trapezoid."""
    with ui_server(str(tiny_dataset), "--out", str(tmp_path_factory.mktemp("page"))) as url:
        browser.get(url)
        wait_for(browser, "document.body.dataset.ready === '1'")
        browser.find_element(By.ID, "use-hand-placed").click()
        idle(browser)
        yield browser


def message(driver) -> tuple[str, str]:
    """The status line's text and kind (its class: error, warn, info or '')."""
    element = driver.find_element(By.ID, "message")
    return element.text, element.get_attribute("class")


def drawn(driver, canvas: str) -> dict:
    return js(driver, f"window.homocalUI.drawn.{canvas}")


def assert_labels_apart(driver) -> None:
    """On both canvases, the labels drawn are inside the canvas and no two of their rectangles overlap."""
    for canvas in ("frame", "map"):
        labels = drawn(driver, canvas)["labels"]
        width, height = js(driver, f"[document.getElementById('{canvas}').width, document.getElementById('{canvas}').height]")
        for i, a in enumerate(labels):
            assert 0 <= a["x"] and a["x"] + a["w"] <= width and 0 <= a["y"] and a["y"] + a["h"] <= height, a
            for b in labels[i + 1:]:
                apart = (a["x"] + a["w"] <= b["x"] or b["x"] + b["w"] <= a["x"] or a["y"] + a["h"] <= b["y"]
                         or b["y"] + b["h"] <= a["y"])
                assert apart, (canvas, a, b)


@pytest.mark.browser
def test_ellipses_only_within_the_trustworthy_range(page, tiny_dataset):
    """The view's 1-sigma ellipses are drawn only for grid nodes within the trustworthy range (on the frame and the
    map); the nodes beyond it are counted in one line that says why."""
    d = page
    bars = js(d, "window.homocalUI.S.view.errorbars")
    reach, origin = bars["trustworthy_range_m"], np.array(load_dataset(tiny_dataset).camera_origin)
    assert reach is not None and bars["beyond"] > 0  # this view has nodes beyond the range: the check is not empty
    for canvas in ("frame", "map"):
        ellipses = [e for e in drawn(d, canvas)["ellipses"] if e["kind"] == "view"]
        assert len(ellipses) == len(bars["points"]) > 0
        assert max(np.hypot(*(np.array(e["ground"]) - origin)) for e in ellipses) <= reach
    assert f"{bars['beyond']} grid nodes beyond it have no ellipse" in d.find_element(By.ID, "errorbar-summary").text
    assert_labels_apart(d)
    assert {"TL", "TR", "BR", "BL", "horizon"} <= {label["text"] for label in drawn(d, "frame")["labels"]}


@pytest.mark.browser
def test_fields_follow_the_method(page):
    """A setting's field shows only for the methods the catalogue gives that setting; the boxes' fields only for
    a method fitted from boxes."""
    from homocal.correctors.catalogue import METHODS

    d = page
    for name, method in METHODS.items():
        Select(d.find_element(By.ID, "method")).select_by_visible_text(name)
        for setting in ("seed", "threshold"):  # each field's id is its setting (the pedestrians': inside boxes-fields)
            assert d.find_element(By.ID, setting).is_displayed() == (setting in method.settings), (name, setting)
        assert d.find_element(By.ID, "boxes-fields").is_displayed() == (method.evidence == "boxes"), name


@pytest.mark.browser
def test_banners_follow_the_state(page, tiny_dataset):
    """A refused fit's message clears once its cause is gone; a fit that makes its check points worse is a warning
    in its own colour with the numbers; the status line keeps its height; the pedestrians fit draws its boxes
    (used and outliers), and hides them when unticked; no two labels overlap."""
    d = page
    S = "window.homocalUI.S"
    cal_image, cal_ground, _ = load_dataset(tiny_dataset).calibration_points(source="segmentation")
    height = js(d, "document.getElementById('message').offsetHeight")
    Select(d.find_element(By.ID, "method")).select_by_visible_text("least-change")
    d.find_element(By.ID, "clear-points").click()
    d.find_element(By.ID, "fit").click()
    idle(d)
    assert message(d) == ("need at least 3 reference points, got 0", "error")

    d.find_element(By.ID, "mode-reference").click()
    for n, row in enumerate(CALIBRATION_ROWS):  # a click adds the point, then its exact values are typed
        click(d, "frame", cal_image[row])
        for key, value in zip("uvxy", [*cal_image[row], *cal_ground[row]]):
            field = d.find_element(By.CSS_SELECTOR, f'#points-table input[data-i="{n}"][data-key="{key}"]')
            field.clear()
            field.send_keys(repr(float(value)) + "\t")
    assert js(d, f"{S}.points.length") == 3
    assert message(d) == ("", "")  # the refusal's cause (no points) is gone: so is its message

    d.find_element(By.ID, "fit").click()
    wait_for(d, f"{S}.fit !== null")
    text, kind = message(d)
    assert kind == "info" and text.startswith("fitted: least-change")
    colours = {"info": js(d, "getComputedStyle(document.getElementById('message')).backgroundColor")}

    Select(d.find_element(By.ID, "method")).select_by_visible_text("pedestrians")
    assert message(d) == ("", "")  # the fit it spoke of is out of date
    Select(d.find_element(By.ID, "detector")).select_by_visible_text("rgb")
    d.find_element(By.ID, "fit").click()
    wait_for(d, f"{S}.fit !== null")
    idle(d)
    fit = js(d, f"{S}.fit")
    before, after = fit["error_before"], fit["error_after"]
    assert after > before  # the rgb boxes' fit makes these check points worse
    text, kind = message(d)
    assert kind == "warn"
    assert text == (f"check points {before:.3f} -> {after:.3f} m, {100 * (before - after) / before:.1f} %: "
                    "this correction makes them worse")
    colours["warn"] = js(d, "getComputedStyle(document.getElementById('message')).backgroundColor")
    assert colours["warn"] != colours["info"]
    assert "worse" in d.find_element(By.ID, "fit-summary").get_attribute("class")
    assert js(d, "document.getElementById('message').offsetHeight") == height

    # the boxes the fit read: used and outliers drawn, as many as it answered; none once unticked
    boxes = drawn(d, "frame")["boxes"]
    assert boxes["used"] == len(fit["boxes"]["used"]) > 0 and boxes["outlier"] == len(fit["boxes"]["outlier"]) > 0
    assert sum(len(fit["boxes"][k]) for k in ("used", "outlier", "border", "hidden")) == fit["boxes"]["total"]
    red = red_pixels(d)
    assert red > 50
    d.find_element(By.ID, "show-boxes").click()
    assert drawn(d, "frame")["boxes"] == {"used": 0, "outlier": 0, "border": 0, "hidden": 0}
    assert red_pixels(d) < red / 10
    d.find_element(By.ID, "show-boxes").click()
    assert_labels_apart(d)
    assert {"horizon", "fitted horizon", "P0", "P1", "P2"} <= {label["text"] for label in drawn(d, "frame")["labels"]}
    assert [entry for entry in d.get_log("browser") if entry["source"] == "javascript"] == []


def red_pixels(driver) -> int:
    """Frame-canvas pixels of the outlier boxes' red (#ff3b3b, +-12 a channel)."""
    return js(driver, """(() => {
        const c = document.getElementById('frame'), d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
        let n = 0;
        for (let i = 0; i < d.length; i += 4) if (d[i] >= 243 && Math.abs(d[i + 1] - 59) <= 12 && Math.abs(d[i + 2] - 59) <= 12) n++;
        return n; })()""")

"""Regenerate the docs' screenshots of `homocal ui` and `homocal report` with headless Chromium, 1400 px wide.

    python3 scripts/screenshots.py DATASET RESULTS_DIR [--out docs/img]

DATASET: a simgen dataset folder (e.g. `simgen generate scenes/scene1 --out DATASET --seconds 1.5 --seed 3`);
RESULTS_DIR: a `homocal study` folder (e.g. `homocal study DATASET -o RESULTS_DIR --variants 10 --n-test 500`).
Writes into --out: ui_trapezoid.jpg (the dataset's hand-placed trapezoid), ui_points.jpg (three of its calibration
objects as reference points), ui_least_change.jpg (a least-change fit), ui_pedestrians.jpg (a fit from the rgb
detector's boxes, which makes the check points worse: the warning), ui_probe.jpg (a probed point) and
report.jpg (the top of the report's page, with its headline figure). Needs Debian's chromium and chromium-driver
and selenium (as tests/ui/test_browser.py).
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np
from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import Select, WebDriverWait

WIDTH, PAGE_HEIGHT, REPORT_HEIGHT = 1400, 1150, 1500  # window px
JPEG_QUALITY = 70
CALIBRATION_ROWS = (0, 15, 35)  # the dataset's calibration objects at 5, 20 and 40 m
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync")
ROOT = Path(__file__).resolve().parents[1]


def browser(profile: Path, height: int) -> webdriver.Chrome:
    options = webdriver.ChromeOptions()
    options.binary_location = "/usr/bin/chromium"
    for flag in (*CHROMIUM_FLAGS, f"--window-size={WIDTH},{height}", f"--user-data-dir={profile}"):
        options.add_argument(flag)
    return webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)


def wait(driver, script: str, timeout: float = 60) -> None:
    WebDriverWait(driver, timeout).until(lambda d: d.execute_script(f"return {script};"), message=script)


def shot(driver, path: Path) -> None:
    """The window's screenshot, scrolled to the top, as a JPEG."""
    driver.execute_script("window.scrollTo(0, 0);")
    image = cv2.imdecode(np.frombuffer(driver.get_screenshot_as_png(), np.uint8), cv2.IMREAD_COLOR)
    assert cv2.imwrite(str(path), image, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    print(f"{path} ({path.stat().st_size // 1024} kB)")


def page_shots(driver, url: str, out: Path) -> None:
    d = driver
    d.get(url)
    wait(d, "document.body.dataset.ready === '1'")
    ui, idle = "window.homocalUI", "window.homocalUI.idle()"
    d.find_element(By.ID, "use-hand-placed").click()
    wait(d, idle)
    shot(d, out / "ui_trapezoid.jpg")

    d.find_element(By.ID, "mode-reference").click()
    calibration = d.execute_script(f"return {ui}.S.info.dataset.calibration;")
    for row in CALIBRATION_ROWS:  # the foot on the frame, then the true position on the map
        u, v, x, y = calibration[row]
        ox, oy = d.execute_script(f"return {ui}.S.info.map.origin_px;")
        scale = d.execute_script(f"return {ui}.S.info.map.scale_px_per_m;")
        d.execute_script(f"{ui}.clickAt('frame', [{u}, {v}], [{u}, {v}]);")
        d.execute_script(f"{ui}.clickAt('map', null, [{ox + scale * x}, {oy - scale * y}]);")
    wait(d, idle)
    shot(d, out / "ui_points.jpg")

    for method, detector, name in (("least-change", None, "ui_least_change.jpg"), ("pedestrians", "rgb", "ui_pedestrians.jpg")):
        Select(d.find_element(By.ID, "method")).select_by_visible_text(method)
        if detector:
            Select(d.find_element(By.ID, "detector")).select_by_visible_text(detector)
        d.find_element(By.ID, "fit").click()
        wait(d, f"{ui}.S.fit !== null && {idle}")
        shot(d, out / name)

    d.find_element(By.ID, "mode-probe").click()
    d.execute_script(f"{ui}.clickAt('frame', [760, 560], [760, 560]);")
    wait(d, f"{ui}.S.probe !== null && {idle}")
    shot(d, out / "ui_probe.jpg")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("dataset", type=Path, metavar="DATASET")
    parser.add_argument("results", type=Path, metavar="RESULTS_DIR")
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "img")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}  # this checkout's homocal
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        report = tmp / "report"
        subprocess.run([sys.executable, "-m", "homocal.cli", "report", str(args.results), "-o", str(report),
                        "--no-progress"], check=True, capture_output=True, env=env)
        proc = subprocess.Popen([sys.executable, "-m", "homocal.cli", "ui", str(args.dataset), "--out", str(tmp / "ui")],
                                stdout=subprocess.PIPE, text=True, env=env)
        try:
            url = re.search(r"http://127\.0\.0\.1:\d+/\?token=[\w-]+", proc.stdout.readline()).group(0)
            driver = browser(tmp / "chromium", PAGE_HEIGHT)
            try:
                page_shots(driver, url, args.out)
                driver.set_window_size(WIDTH, REPORT_HEIGHT)
                driver.get((report / "report.html").as_uri())
                shot(driver, args.out / "report.jpg")
            finally:
                driver.quit()
        finally:
            proc.terminate()
            proc.wait(timeout=10)
    return 0


if __name__ == "__main__":
    sys.exit(main())

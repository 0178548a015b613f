"""research/watch.py's render-free mode on a tiny stream: the boxes it feeds OnlineCalibrator are
simgen.boxstream's of the scene's static camera (their count, against box_stream's own)."""
import re
import subprocess
import sys
from pathlib import Path

import pytest

from simgen.boxstream import box_stream
from simgen.scene import load_scene

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_render_free_mode_counts_the_boxes_of_the_static_stream():
    done = subprocess.run([sys.executable, str(ROOT / "research" / "watch.py"), "--scene", "scene1", "--seeds", "1",
                           "--minutes", "0.25", "--fps", "2", "--at", "5", "--arl0", "20000"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    boxes = int(re.search(r"([\d,]+) boxes in ", done.stdout).group(1).replace(",", ""))
    scene = load_scene(ROOT / "simgen" / "scenes" / "scene1")
    expected = sum(len(xyxy) for _, xyxy, _ in box_stream(scene, 0, 15.0, 2.0))
    assert expected > 0 and boxes == expected
    per_second = float(re.search(r"has (\d+) boxes a second of video", done.stdout).group(1))
    assert abs(per_second - expected / 15.0 * scene.fps / 2.0) <= 0.5  # printed rounded to the box

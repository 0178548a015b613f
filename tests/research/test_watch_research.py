"""research/watch.py's render-free mode on a tiny stream: the boxes it feeds OnlineCalibrator are
simgen.boxstream's of the scene's static camera (their count, against box_stream's own); its --datasets mode's
reading of a recording's motion from the pose track simgen records, and its pooling of the recordings' figures."""
import importlib.util
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from homocal.dataset import PoseTrack
from simgen.boxstream import box_stream
from simgen.scene import CameraMove, Sway, camera_offsets, load_scene

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


SCRIPT = ROOT / "research" / "watch.py"
spec = importlib.util.spec_from_file_location("watch_research", SCRIPT)
script = importlib.util.module_from_spec(spec)
spec.loader.exec_module(script)


def _pose(moves, sway=None, seconds=120.0) -> PoseTrack:
    """The pose track simgen records for these moves (simgen.scene.camera_offsets) on a camera tilted 15 degrees."""
    t = np.arange(round(seconds / 0.05)) * 0.05
    d = camera_offsets(moves, sway, t) + [15.0, 0.0, 0.0]
    return PoseTrack(t, np.arange(len(t)), d[:, 0], d[:, 1], d[:, 2], np.tile([0.0, 1.0, -200.0], (len(t), 1)))


@pytest.mark.parametrize("moves, sway, case, start", [
    ((), None, "static", None),
    ((CameraMove(30.0, tilt_deg=0.5),), None, "step tilt +0.5", 30.0),
    ((CameraMove(30.0, roll_deg=1.0),), None, "step roll +1", 30.0),
    ((CameraMove(30.0, yaw_deg=-2.0),), None, "step yaw -2", 30.0),
    ((CameraMove(30.0, 60.0, 2.0),), None, "ramp tilt +2 over 60 s", 30.0),
    ((), Sway(0.3, 60.0), "sway tilt 0.3", 0.0),
])  # fmt: skip
def test_a_recordings_motion_is_read_from_its_pose_track(moves, sway, case, start):
    assert script.motion(_pose(moves, sway), 0.05) == (case, start)
    assert script.motion(None, 0.05) == ("static", None)


def test_pooling_counts_the_static_minutes_and_the_moves():
    """Two static recordings of 2 minutes (one false alarm), two 1-degree steps at 30 s (one found 4 s after it, with
    a false alarm before; one missed), a sway of 1.5 minutes with 2 alarms (all false, apart)."""
    static = {"case": "static", "t_move": None, "seconds": 120.0, "static_s": 120.0, "detected": None}
    step = {"case": "step tilt +1", "t_move": 30.0, "seconds": 90.0, "static_s": 30.0}
    results = [{**static, "false": 1}, {**static, "false": 0},
               {**step, "false": 1, "detected": 34.0, "rms_before": 3.0, "rms_after": 4.0, "ranges": [(4.0, 2.0), (11.0, 3.0)]},
               {**step, "false": 0, "detected": None, "rms_before": 4.0, "rms_after": math.nan, "ranges": [(6.0, 1.0)]},
               {"case": "sway tilt 0.3", "t_move": 0.0, "seconds": 90.0, "static_s": 0.0, "false": 2, "detected": None}]
    p = script.pooled(results)
    assert p["static_minutes"] == 5.0 and p["false"] == 2 and p["false_per_hour"] == pytest.approx(24.0)
    assert p["sway_minutes"] == 1.5 and p["sway_alarms"] == 2
    c = p["cases"]["step tilt +1"]
    assert list(p["cases"]) == ["step tilt +1"] and c["delays"] == [4.0] and c["missed"] == 1 and c["n"] == 2
    assert c["rms"] == pytest.approx((math.sqrt(12.5), 4.0))
    np.testing.assert_array_equal(c["ranges"][0], [5.0, 1.5])  # the median of the two at -10 s
    np.testing.assert_array_equal(c["ranges"][1], [11.0, 3.0])  # only the found move has one at its detection


def test_rgb_boxes_meet_the_ground_truth_box_of_their_person_and_step():
    """research/watch_rgb_boxes.py's join: a detection at t = 0.1 s (step 2 of 50 ms) meets gt.parquet's box of its
    agent at step 2, not another step's or agent's; unmatched detections (agent -1) and boxes at the border go."""
    import pandas as pd

    spec = importlib.util.spec_from_file_location("watch_rgb_boxes", ROOT / "research" / "watch_rgb_boxes.py")
    rgb_boxes = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(rgb_boxes)
    box = lambda y1: {"x1": 100.0, "y1": y1, "x2": 120.0, "y2": y1 + 50.0}  # noqa: E731
    gt = pd.DataFrame([{"step": s, "agent_id": a, **box(200.0 + 10 * s + a)} for s in range(4) for a in (7, 8)])
    det = pd.DataFrame([{"t": 0.1, "agent_id": 7, **box(190.0)}, {"t": 0.1, "agent_id": -1, **box(300.0)},
                        {"t": 0.15, "agent_id": 8, **box(0.5)}])  # the last one at the top border
    m = rgb_boxes.matched(det, gt, 0.05)
    assert len(m) == 1 and m.step.tolist() == [2] and m.y1.tolist() == [190.0] and m.y1_gt.tolist() == [227.0]

"""research/watch_roll.py on a tiny render-free stream: every case is printed with its false alarms, and per seed the
people, their columns' spread and the roll at the end against the camera's (the steady camera's 0, the rolled
camera's 1 and 2 degrees)."""
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_watch_roll_prints_each_case_and_the_camera_roll():
    done = subprocess.run([sys.executable, str(ROOT / "research" / "watch_roll.py"), "--scene", "scene1", "--seeds", "1",
                           "--minutes", "0.5", "--at", "15"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    cases = re.findall(r"^(steady|roll 1 degree|roll 2 degrees|tilt 1 degree): (\d+) false alarms in ", done.stdout, re.M)
    assert [c for c, _ in cases] == ["steady", "roll 1 degree", "roll 2 degrees", "tilt 1 degree"]
    truths = [float(t) for t in re.findall(r"degrees \(the camera's ([-\d.]+)\)", done.stdout)]
    assert truths == [0.0, 1.0, 2.0, 0.0]
    assert all(int(p) > 0 for p in re.findall(r"seed 0: (\d+) people", done.stdout))

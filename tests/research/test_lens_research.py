"""research/lens_lines.py end to end: one seed of 1 px clicks on scene3's street and houses (its stand-in camera,
scenes/scene3/scene.toml's) gives k1 within 5 % of the scene's, straightness at the clicks' own error, and a range
error within 1.25 times the known lens's (docs/real-camera.md)."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "research" / "lens_lines.py"
SCENE3_K1 = -0.30678  # scenes/scene3/scene.toml


@pytest.mark.slow  # about 5 s alone, more under load
def test_one_seed_of_clicked_lines_recovers_scene3s_lens():
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(SCRIPT.parents[1]), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, str(SCRIPT), "--seeds", "1", "--buildings"], capture_output=True,
                          text=True, env=env, timeout=300)
    assert done.returncode == 0, done.stderr
    row = next(line for line in done.stdout.splitlines() if line.startswith("| 0 |"))
    k1, _, _, _, rms, known, estimated, ratio, _ = map(float, row.strip("| ").split(" | ")[1:])
    assert abs(k1 / SCENE3_K1 - 1) < 0.05
    assert 0.7 < rms < 1.2  # 1 px clicks: about sqrt((n - 2) / n) px of straightness is left, the clicks' own
    assert abs(ratio - estimated / known) < 1e-3 * ratio and ratio < 1.25

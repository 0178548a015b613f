"""research/recording_length.py: its bounds are refused before any stream is drawn."""
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "research" / "recording_length.py"


@pytest.mark.parametrize("args", [["--seeds", "0"], ["--seconds", "10,601"], ["--fps", "61"], ["--drop-hidden-feet", "maybe"]])
def test_bounds_refused(args):
    done = subprocess.run([sys.executable, str(SCRIPT), *args], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and done.stdout == "" and done.stderr.count("error:") == 1, done.stderr
    assert f"error: argument {args[0]}: " in done.stderr

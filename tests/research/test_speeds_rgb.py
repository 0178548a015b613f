"""research/speeds_rgb.py on simgen's own dataset: the report runs through measure_speeds' mappings for both
detectors and prints each figure the page quotes (the script once called mappings with an argument it no longer
took, and nothing ran it)."""
import importlib.util
import math
import re
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location("speeds_rgb", ROOT / "research" / "speeds_rgb.py")
script = importlib.util.module_from_spec(spec)
sys.path.insert(0, str(ROOT / "research"))  # the script imports its sibling measure_speeds, as run from research/
try:
    spec.loader.exec_module(script)
finally:
    sys.path.remove(str(ROOT / "research"))


def test_report_prints_every_figure(tiny_dataset, capsys):
    script.report(str(tiny_dataset), False)
    out = capsys.readouterr().out
    for detector in ("segmentation", "rgb"):
        assert re.search(rf"^  {detector}: [\d,]+ boxes", out, re.M), out
    assert len(re.findall(r"pedestrians' horizon [\d.]+ \+- [\d.]+ px", out)) == 2
    errors = re.findall(r"smoother, (\w+) mapping, .* tracks: .*?: ([\d.na]+) %, (\d+) / (\d+) %", out)
    assert [m for m, *_ in errors] == ["pedestrians"] * 2 + ["exact"] * 2 + ["pedestrians"] * 2 + ["exact"] * 2, out
    for _, median, one, two in errors:
        assert math.isfinite(float(median)) and 0 <= int(one) <= int(two) <= 100
    moves = re.findall(r"\(([-+][\d.]+) px from the true one\); ([-+][\d.na]+) px per px of box height, the error of "
                       r"boxes ([-+][\d.na]+) px taller", out)
    assert len(moves) == 2, out
    fitted = [[float(x) for x in m] for m in moves if m[1] != "nan"]  # nan: a refit refused
    assert fitted, out
    for error, slope, margin in fitted:  # taller boxes, taller people at every tilt: the fit raises the horizon
        assert slope < 0 and math.isclose(margin, error / slope, abs_tol=0.1)
    along = re.findall(r"the exact mapping's foot point ([-+][\d.na]+) m along the line of sight", out)
    assert len(along) == 6, out


def test_line_of_sight_offsets_are_the_component_toward_the_camera():
    class Camera:
        camera_origin = (0.0, -4.0)
    true = np.array([[0.0, 6.0], [3.0, 0.0]])  # 10 m ahead; 5 m away at (3, 4) from the camera's ground point
    mapped = true + [[0.5, -0.2], [0.6 * -0.1, 0.8 * -0.1]]  # 0.2 m nearer (and 0.5 m aside); 0.1 m nearer
    np.testing.assert_allclose(script.line_of_sight_offsets(Camera, mapped, true), [-0.2, -0.1], atol=1e-12)

"""research/speeds_rgb.py on simgen's own dataset: the report runs through measure_speeds' mappings for both
detectors and prints each figure the page quotes (the script once called mappings with an argument it no longer
took, and nothing ran it)."""
import importlib.util
import math
import re
import sys
from pathlib import Path

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

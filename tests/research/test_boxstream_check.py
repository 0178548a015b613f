"""research/boxstream_check.py on the tiny rendered dataset: it pairs every segmentation box with a render-free one
and prints the shares per group (their values: tests/simgen/test_boxstream.py)."""
import re
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq

SCRIPT = Path(__file__).resolve().parents[2] / "research" / "boxstream_check.py"


def test_every_segmentation_box_is_paired_and_each_group_printed(tiny_dataset):
    done = subprocess.run([sys.executable, str(SCRIPT), str(tiny_dataset)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    detector = pq.read_table(tiny_dataset / "detections.parquet", columns=["detector"]).column("detector").to_pylist()
    n = detector.count("segmentation")
    assert f": {n} rendered boxes, {n} render-free (0 rendered ones without)" in done.stdout
    groups = re.findall(r"^  (.+), (\d+) boxes, (occluded|whole): identical", done.stdout, re.M)
    assert [(g, k) for g, _, k in groups] == [(g, k) for g in ("all", "partly occluded (visible_fraction < 0.9)",
                                                                "changed by occlusion") for k in ("occluded", "whole")]
    assert int(groups[0][1]) == n

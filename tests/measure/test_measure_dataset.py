"""homocal measure on a rendered simgen dataset: detections.parquet's boxes linked by IoU, the frame rate from
manifest.json, the image size from camera.json, the speeds against gt.parquet's."""
import json

import numpy as np
import pyarrow.parquet as pq
import pytest

from cli_run import homocal_main

pytestmark = [pytest.mark.slow, pytest.mark.generate]


def test_dataset_boxes_measured_with_their_frame_rate(tiny_dataset, tmp_path, capsys, monkeypatch):
    r = homocal_main("measure", str(tiny_dataset / "trapezoids.json"), "--boxes", str(tiny_dataset / "detections.parquet"),
                     "--out", "tracks.parquet", cwd=tmp_path, capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 0, r.stderr
    fps = json.loads((tiny_dataset / "manifest.json").read_text())["fps"]
    assert "tracks (linked by IoU" in r.stdout and f"at {fps:g} fps" in r.stdout
    tracks = pq.read_table(tmp_path / "tracks.parquet").to_pandas()
    np.testing.assert_allclose(tracks.t, tracks.frame / fps)
    # walkers: the simulated people walk at 0.6-1.8 m/s (gt.parquet's speed), the hand-placed trapezoid is
    # a few px off: medians of whole tracks within walking speeds
    gt = pq.read_table(tiny_dataset / "gt.parquet", columns=["speed"]).to_pandas()
    medians = tracks[tracks.frame >= 5].groupby("track_id").speed_mps.median()
    assert 0.5 * gt.speed.median() < medians.median() < 1.5 * gt.speed.median()


def test_a_correction_of_another_image_size_is_refused(tiny_dataset, tmp_path, capsys, monkeypatch):
    trap = json.loads((tiny_dataset / "trapezoids.json").read_text())["hand_placed"]
    site = json.loads((tiny_dataset / "site_map.json").read_text())
    doubled = {"image": (2 * np.array(trap["image"], float)).tolist(), "map": trap["map"],
               "site_map": {"scale_px_per_m": site["scale_px_per_m"], "origin_px": site["origin_px"]}}
    (tmp_path / "trap.json").write_text(json.dumps(doubled))  # clicked on a frame twice the size
    r = homocal_main("measure", "trap.json", "--boxes", str(tiny_dataset / "detections.parquet"), "--out",
                     "tracks.parquet", cwd=tmp_path, capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 2 and "outside the 1280x720 image" in r.stderr and r.stderr.count("\n") == 1, r.stderr
    assert not (tmp_path / "tracks.parquet").exists()

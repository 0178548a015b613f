"""research/hog_boxes.py: its CSV is HogDetector's boxes on the decoded video in the corners convention, numbered by
sample, read back by homocal.boxes.read_boxes; and its bad input."""
import subprocess
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from homocal.boxes import read_boxes
from simgen.detection.hog import hog_missing

SCRIPT = Path(__file__).resolve().parents[2] / "research" / "hog_boxes.py"


def run(*args):
    return subprocess.run([sys.executable, str(SCRIPT), *map(str, args)], capture_output=True, text=True)


@pytest.mark.skipif(hog_missing() is not None, reason="this OpenCV has no HOGDescriptor (the hog extra)")
@pytest.mark.slow  # HOG over a rendered dataset
def test_the_csv_holds_hogs_boxes_of_every_nth_frame_read_back_in_homocal_pixels(tiny_dataset, tmp_path):
    from simgen.detection.hog import HogDetector

    out = tmp_path / "hog.csv"
    done = run(tiny_dataset, "--every", 7, "--seconds", 1, "-o", out)
    assert done.returncode == 0, done.stderr
    frames = [rgb for i, rgb in enumerate(iio.imiter(tiny_dataset / "video.mp4", plugin="FFMPEG")) if i < 20 and i % 7 == 0]
    expected = [(sample, box) for sample, rgb in enumerate(frames) for box in HogDetector().people(rgb)[0]]
    boxes = read_boxes(out, None)  # a CSV: corners convention, turned into homocal pixels by read_boxes
    assert len(frames) == 3 and len(boxes.frames) == len(expected) > 0
    rows = lambda frames, xyxy: np.column_stack([frames, xyxy])[np.lexsort(np.column_stack([frames, xyxy]).T[::-1])]  # noqa: E731
    got = rows(boxes.frames, boxes.xyxy)  # HOG's own order varies with its threads
    np.testing.assert_array_equal(np.column_stack([boxes.frames, boxes.xyxy]), got)  # the CSV's: canonical, by sample
    want = rows(np.array([s for s, _ in expected]), np.array([b for _, b in expected]))
    np.testing.assert_array_equal(got[:, 0], want[:, 0])
    np.testing.assert_allclose(got[:, 1:], want[:, 1:], atol=1e-9)


@pytest.mark.parametrize("args, message", [
    (["--every", "0"], "--every"), (["--every", "x"], "--every"), (["--seconds", "0"], "--seconds"),
    (["--seconds", "nan"], "--seconds"), (["--seconds", "-1"], "--seconds")])
def test_bad_flags_are_one_line(args, message, tiny_dataset, tmp_path):
    done = run(tiny_dataset, *args, "-o", tmp_path / "hog.csv")
    assert done.returncode == 2 and message in done.stderr and not (tmp_path / "hog.csv").exists()


@pytest.mark.parametrize("case", ["no folder", "not a dataset", "output exists", "output folder missing", "output is a folder"])
def test_bad_paths_are_one_line_and_touch_nothing(case, tiny_dataset, tmp_path):
    dataset, out = tiny_dataset, tmp_path / "hog.csv"
    if case == "no folder":
        dataset = tmp_path / "missing"
    elif case == "not a dataset":
        dataset = tmp_path
    elif case == "output exists":
        out.write_text("frame,x1,y1,x2,y2\nmine\n")
    elif case == "output folder missing":
        out = tmp_path / "missing" / "hog.csv"
    else:
        out = tmp_path
    before = sorted(p.name for p in tmp_path.iterdir())
    done = run(dataset, "-o", out)
    assert done.returncode == 2 and done.stderr.count("\n") == 1 and done.stderr.startswith("hog_boxes: ")
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    if case == "output exists":
        assert out.read_text() == "frame,x1,y1,x2,y2\nmine\n"

"""homocal.boxes' bounds, one for every reader: a file larger than MAX_BOXES_BYTES (made cheaply as a sparse
file) refused before a byte is read, more than MAX_BOXES boxes, more than MAX_BOXES_PER_FRAME in a frame, a folder
or a device; through read_boxes and through homocal fit (one line naming the flag, exit 2, nothing written)."""
from __future__ import annotations

import json
import os
import tracemalloc

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import homocal.boxes
from homocal.boxes import MAX_BOXES_BYTES, read_boxes
from homocal.geometry import PinholeCamera
from homocal.geometry.boxes import MAX_BOXES_PER_FRAME
from tests.cli_run import homocal_main

CAM = PinholeCamera()


def sparse(path, size: int = 2**31):
    """A file of `size` NUL bytes that takes no disk space (truncate)."""
    with open(path, "wb") as f:
        f.truncate(size)
    return path


def crowded_csv(path, n: int = MAX_BOXES_PER_FRAME + 1):
    rows = "".join(f"3,{i % 100},{i % 50},{i % 100 + 20},{i % 50 + 60}\n" for i in range(n))
    path.write_text("frame,x1,y1,x2,y2\n" + rows)
    return path


def crowded_parquet(path, n: int = MAX_BOXES_PER_FRAME + 1):
    pq.write_table(pa.table({"detector": ["segmentation"] * n, "frame": [7] * n, "x1": [1.0] * n, "y1": [1.0] * n,
                             "x2": [9.0] * n, "y2": [30.0] * n}), path)
    return path


def crowded_mot(path, n: int = MAX_BOXES_PER_FRAME + 1):
    path.write_text("".join(f"2,-1,{i % 100 + 1.5},11.5,20,50,1,-1,-1,-1\n" for i in range(n)))
    return path


HUGE = f"larger than {MAX_BOXES_BYTES >> 20} MiB"
CASES = [  # (name, make(tmp_path) -> path, message)
    ("2 GB CSV of NUL bytes", lambda d: sparse(d / "b.csv"), HUGE),
    ("2 GB Parquet", lambda d: sparse(d / "b.parquet"), HUGE),
    ("2 GB MOT", lambda d: sparse(d / "b.txt"), HUGE),
    ("CSV one byte over", lambda d: sparse(d / "b.csv", MAX_BOXES_BYTES + 1), HUGE),
    ("a folder", lambda d: d, "is a folder, not a file"),
    ("/dev/zero", lambda d: "/dev/zero", "not a regular file"),
    ("crowded CSV frame", lambda d: crowded_csv(d / "b.csv"), f"frame 3 has {MAX_BOXES_PER_FRAME + 1:,} boxes, more than"),
    ("crowded Parquet frame", lambda d: crowded_parquet(d / "b.parquet"), f"frame 7 has {MAX_BOXES_PER_FRAME + 1:,} boxes"),
    ("crowded MOT frame", lambda d: crowded_mot(d / "b.txt"), f"frame 1 has {MAX_BOXES_PER_FRAME + 1:,} boxes"),
    ("CSV full of NUL bytes", lambda d: (d / "b.csv").write_bytes(b"frame,x1,y1,x2,y2\n" + b"\0" * 4096) and d / "b.csv",
     "line 2: 1 fields"),
]


@pytest.mark.parametrize("name,make,message", CASES, ids=[c[0] for c in CASES])
def test_read_boxes_refuses(tmp_path, name, make, message):
    path = make(tmp_path)
    tracemalloc.start()
    with pytest.raises(ValueError, match=message):
        read_boxes(path)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 2**25  # none of the 2 GB is read: 32 MiB at most (the crowded files' own 501 rows)


@pytest.mark.parametrize("make,kind", [(crowded_csv, "b.csv"), (crowded_parquet, "b.parquet"), (crowded_mot, "b.txt")])
def test_more_than_max_boxes(tmp_path, monkeypatch, make, kind):
    """MAX_BOXES bounds every reader (here lowered to 100, as read at each call)."""
    monkeypatch.setattr(homocal.boxes, "MAX_BOXES", 100)
    with pytest.raises(ValueError, match="more than 100 (boxes|points)|rows, more than 100"):
        read_boxes(make(tmp_path / kind, 101))


def test_the_bound_itself_is_read(tmp_path):
    """MAX_BOXES_PER_FRAME boxes in a frame are read (the bound is the most, not one less)."""
    assert len(read_boxes(crowded_csv(tmp_path / "b.csv", MAX_BOXES_PER_FRAME)).frames) == MAX_BOXES_PER_FRAME


@pytest.mark.parametrize("boxes,camera,message", [
    ("big.csv", "cam.json", f"--boxes big.csv: {HUGE}"),
    ("crowd.csv", "cam.json", f"--boxes crowd.csv: frame 3 has {MAX_BOXES_PER_FRAME + 1:,} boxes"),
    ("/dev/zero", "cam.json", "--boxes /dev/zero: not a regular file"),
    ("few.csv", "big.json", "--camera-json big.json: larger than 1 MiB"),
])
def test_fit_refuses_in_one_line(tmp_path, capsys, monkeypatch, boxes, camera, message):
    sparse(tmp_path / "big.csv")
    sparse(tmp_path / "big.json")
    crowded_csv(tmp_path / "crowd.csv")
    crowded_csv(tmp_path / "few.csv", 5)
    (tmp_path / "cam.json").write_text(json.dumps({"width": CAM.width, "height": CAM.height, "K": CAM.K.tolist()}))
    ground = [[-3.5, 30.0], [3.5, 30.0], [3.5, 8.0], [-3.5, 8.0]]
    (tmp_path / "trap.json").write_text(json.dumps({"image": CAM.project_ground(np.array(ground)).tolist(), "map": ground}))
    before = sorted(os.listdir(tmp_path))
    result = homocal_main("fit", "--trapezoid", "trap.json", "-o", "c.json", "--method", "pedestrians", "--boxes", boxes,
                          "--camera-json", camera, "--camera-height", "4", cwd=tmp_path, capsys=capsys,
                          monkeypatch=monkeypatch)
    assert result.returncode == 2 and result.stderr.count("\n") == 1, result.stderr
    assert result.stderr.startswith("homocal: error: ") and message in result.stderr
    assert sorted(os.listdir(tmp_path)) == before

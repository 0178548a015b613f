"""simgen under faults (issue 12): folders that are not ours, two writers, a full disk, bad numbers at the flags."""
from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from simgen.cli import main

from scene_copies import SCENES

pytestmark = [pytest.mark.generate, pytest.mark.slow]  # killed and resumed simgen runs


def _tree(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def _generate(scene: Path, out: Path, *extra: str) -> list[str]:
    return ["generate", str(scene), "--out", str(out), "--seconds", "0.5", "--no-progress", *extra]


NOT_OURS = [
    # (id, files in the folder, --resume, message)
    ("user's video, resume", {"video.mp4": b"user", "clip.tmp1.mp4": b"user", "mot/gt.tmp.txt": b"user"}, True, "not a simgen-dataset output folder"),
    ("user's video, no resume", {"video.mp4": b"user"}, False, "exists and is not empty"),
    ("another tool's manifest", {"manifest.json": b'{"format": "homocal-study"}', "video.mp4": b"user"}, True, "not a simgen-dataset output folder"),
    ("manifest without format", {"manifest.json": b'{"seed": 0, "complete": false}'}, True, "not a simgen-dataset output folder"),
    ("manifest not JSON", {"manifest.json": b"\xff\xfe"}, True, "not a simgen-dataset output folder"),
    ("user's .lock file", {".lock": b"mine", "notes.txt": b"x"}, True, "not a simgen-dataset output folder"),
]  # fmt: skip


@pytest.mark.parametrize("files, resume, message", [c[1:] for c in NOT_OURS], ids=[c[0] for c in NOT_OURS])
def test_folder_that_is_not_ours_is_refused_untouched(small_scene, tmp_path, capsys, files, resume, message):
    out = tmp_path / "out"
    for name, data in files.items():
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name).write_bytes(data)
    before = _tree(out)
    assert main(_generate(small_scene, out, *(["--resume"] if resume else []))) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"simgen: error: {out}: ") and message in err and len(err.splitlines()) == 1, err
    assert _tree(out) == before


def test_out_is_a_file(small_scene, tmp_path, capsys):
    (tmp_path / "out").write_text("user")
    assert main(_generate(small_scene, tmp_path / "out", "--resume")) == 2
    assert "exists and is not a folder" in capsys.readouterr().err and (tmp_path / "out").read_text() == "user"


_HOLD = """
import sys, time
from homocal.files import output_folder
from simgen.dataset import FORMAT

with output_folder(sys.argv[1], FORMAT, False):
    open(sys.argv[1] + "/manifest.json", "w").write('{"format": "simgen-dataset"}')
    print("held", flush=True)
    time.sleep(60)
"""


SECOND_WRITERS = {  # a command writing the dataset folder `out`
    "generate": lambda scene, out, tmp: _generate(scene, out),
    "generate --resume": lambda scene, out, tmp: _generate(scene, out, "--resume"),
    "import-mot": lambda scene, out, tmp: ["import-mot", str(out), str(tmp / "det.txt"), "--name", "yolo"],
}


@pytest.mark.parametrize("command", SECOND_WRITERS)
def test_second_writer_is_told_who_holds_the_folder(small_scene, tmp_path, capsys, command):
    """A run holding a dataset folder (here a process holding it as generate does) makes a second writer exit 2."""
    out = tmp_path / "out"
    (tmp_path / "det.txt").write_text("1,-1,100,60,10,20,0.9,-1,-1,-1\n")
    holder = subprocess.Popen([sys.executable, "-c", _HOLD, str(out)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline() == "held\n"
        before = _tree(out)
        assert main(SECOND_WRITERS[command](small_scene, out, tmp_path)) == 2
        err = capsys.readouterr().err
        assert f"locked by pid {holder.pid} on {socket.gethostname()} since 20" in err and len(err.splitlines()) == 1, err
        assert _tree(out) == before
    finally:
        holder.kill()
        holder.wait()


def test_second_generate_while_one_runs(small_scene, tmp_path, capsys):
    """Two real generate commands on one --out: the second names the first's pid and exits 2."""
    out = tmp_path / "out"
    first = subprocess.Popen([sys.executable, "-m", "simgen.cli", *_generate(small_scene, out)[:-3], "--seconds", "3", "--no-progress"],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    try:
        deadline = time.monotonic() + 120
        while not (out / "manifest.json").exists() and first.poll() is None and time.monotonic() < deadline:
            time.sleep(0.01)
        assert first.poll() is None, "the first run ended before the second could start"
        assert main(_generate(small_scene, out, "--resume")) == 2
        err = capsys.readouterr().err
        assert f"locked by pid {first.pid} on " in err and len(err.splitlines()) == 1, err
    finally:
        first.kill()
        first.wait()


def test_full_disk_is_one_line_and_leaves_no_temporary(small_scene, tmp_path, capsys, monkeypatch):
    """Parquet writes go to /dev/full (a real ENOSPC from the kernel) from the calibration table on.

    (Through an open file object: given a path, pyarrow deletes the file when a write fails.)"""
    write_table = pq.write_table

    def full_disk(table, where, **kw):
        with open("/dev/full", "wb") as f:
            write_table(table, f, **kw)

    monkeypatch.setattr(pq, "write_table", full_disk)
    out = tmp_path / "out"
    assert main(_generate(small_scene, out)) == 2
    err = capsys.readouterr().err
    assert err == f"simgen: error: {out / 'calibration.parquet'}: No space left on device\n", err
    assert not [p for p in out.rglob("*") if ".tmp" in p.name or p.name == ".lock"]
    monkeypatch.setattr(pq, "write_table", write_table)  # space again: the run resumes
    assert main(_generate(small_scene, out, "--resume")) == 0
    assert json.loads((out / "manifest.json").read_text())["complete"]


def _on_tiny_disk(folder: Path, size_kib: int) -> list[str] | None:
    """A wrapper that runs a command with ``folder`` a tmpfs of ``size_kib`` KiB in a private mount namespace, then
    prints the files left in it (needs root and unshare; None where that cannot be done)."""
    if shutil.which("unshare") is None or os.geteuid() != 0:
        return None
    mount = f"mount -t tmpfs -o size={size_kib}k tmpfs {folder}"
    if subprocess.run(["unshare", "-m", "--propagation", "private", "sh", "-c", mount], capture_output=True).returncode:
        return None
    return ["unshare", "-m", "--propagation", "private", "sh", "-c", f'{mount} && "$@"; code=$?; cd {folder} && find . -type f; exit $code', "sh"]


def test_a_real_full_disk_is_one_line_even_when_ffmpeg_meets_it(small_scene, tmp_path):
    """generate into a tmpfs too small for the dataset: whichever write meets the full disk (ffmpeg's trailer
    among them), one line on stderr, exit 2, no temporary and no partial video segment left."""
    disk = tmp_path / "disk"
    disk.mkdir()
    messages = []
    for size_kib in (112, 120, 104, 128, 96):  # at 320x180 the first video segment meets the full disk near 112 KiB
        wrap = _on_tiny_disk(disk, size_kib)
        if wrap is None:
            pytest.skip("cannot mount a tmpfs here (needs root, unshare and mount)")
        run = subprocess.run([*wrap, sys.executable, "-m", "simgen.cli", "generate", str(small_scene), "-o", str(disk / "out"),
                              "--seconds", "0.5", "--no-progress"], capture_output=True, text=True, timeout=600)
        assert run.returncode == 2 and run.stderr.count("\n") == 1 and "No space left on device" in run.stderr, run.stderr
        left = run.stdout.split()
        assert left and not [f for f in left if ".tmp" in f or f.endswith(".lock")], left
        messages.append(run.stderr)
        if "ffmpeg could not write the video" in run.stderr:
            assert run.stderr.startswith(f"simgen: error: {disk / 'out' / '_parts' / '00000.mp4'}: "), run.stderr
            assert "./out/_parts/00000.mp4" not in left
            return
    pytest.fail(f"ffmpeg never met the full disk: {messages}")


def test_unwritable_parent_is_one_line(small_scene, tmp_path, capsys):
    """A folder where --out cannot be made (its parent is a file): one line naming it."""
    (tmp_path / "file").write_text("user")
    assert main(_generate(small_scene, tmp_path / "file" / "out")) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"simgen: error: {tmp_path / 'file' / 'out'}: Not a directory") and len(err.splitlines()) == 1, err


BAD_FLAGS = [
    (["--seconds", "inf"], "argument --seconds: must be a finite number in (0, 86400], got inf"),
    (["--seconds", "nan"], "argument --seconds: must be a finite number in (0, 86400]"),
    (["--seconds", "1e400"], "argument --seconds: must be a finite number in (0, 86400]"),
    (["--seconds", "1e12"], "argument --seconds: must be a finite number in (0, 86400], got 1e12"),
    (["--seconds", "0"], "argument --seconds: must be a finite number in (0, 86400]"),
    (["--seconds", "-2"], "argument --seconds"),
    (["--seconds", "two"], "argument --seconds: expected a number, got 'two'"),
    (["--seconds", "0.123"], "run.seconds: must be a positive multiple of 0.05 s"),
    (["--seed", "-1"], "argument --seed: must be an integer in [0, 2**64 - 1], got -1"),
    (["--seed", str(2**64)], "argument --seed: must be an integer in [0, 2**64 - 1]"),
    (["--seed", "1.5"], "argument --seed: expected an integer"),
    (["--fps", "0"], "argument --fps: must be an integer in [1, 1000], got 0"),
    (["--fps", "-20"], "argument --fps"),
    (["--fps", "100000"], "argument --fps: must be an integer in [1, 1000], got 100000"),
    (["--workers", "0"], "argument --workers: must be an integer >= 1"),
    (["--quality", "ultra"], "argument --quality: invalid choice"),
    (["--detectors", "yolo"], "argument --detectors: expected distinct names from segmentation, rgb, hog, got ['yolo']"),
    (["--detectors", ""], "argument --detectors: expected distinct names from segmentation, rgb, hog, got ['']"),
    (["--detectors", "rgb,"], "argument --detectors"),
    (["--detectors", "rgb,rgb"], "argument --detectors"),
    (["--scheduler", "tcp://127.0.0.1:1"], "--scheduler tcp://127.0.0.1:1: cannot connect"),
]  # fmt: skip


@pytest.mark.parametrize("flags, message", BAD_FLAGS, ids=[" ".join(f) for f, _ in BAD_FLAGS])
def test_bad_number_is_one_line_naming_the_flag(tmp_path, capsys, flags, message):
    out = tmp_path / "out"
    args = ["generate", str(SCENES / "scene1"), "--out", str(out), "--no-progress", *flags]
    if "--seconds" not in flags:
        args += ["--seconds", "0.5"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("simgen: error: ") and message in err and len(err.splitlines()) == 1, err
    assert not out.exists()


@pytest.mark.parametrize("flags, message", [(["--t", "-1"], "argument --t"), (["--t", "inf"], "argument --t"),
                                            (["--t", "1e12"], "argument --t: must be a finite number in [0, 86400]"),
                                            (["--seed", "-1"], "argument --seed")])
def test_preview_bad_number(tmp_path, capsys, flags, message):
    assert main(["preview", str(SCENES / "scene1"), "-o", str(tmp_path / "a.png"), *flags]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.splitlines()) == 1 and not (tmp_path / "a.png").exists()


PREVIEW_REFUSED = [
    # (id, make the -o name in tmp_path, message)
    ("a user's PNG", lambda d: (d / "a.png").write_bytes(b"\x89PNG user") and "a.png", "exists and is not a PNG written by simgen preview"),
    ("a symlink to a user's file", lambda d: (d / "u").write_bytes(b"user") and (d / "l.png").symlink_to(d / "u") or "l.png",
     "exists and is not a PNG written by simgen preview"),
    ("a folder", lambda d: (d / "f").mkdir() or "f", "is a folder"),
    ("in a missing folder", lambda d: "missing/a.png", "does not exist"),
]  # fmt: skip


@pytest.mark.parametrize("make, message", [c[1:] for c in PREVIEW_REFUSED], ids=[c[0] for c in PREVIEW_REFUSED])
def test_preview_replaces_only_its_own_png(tmp_path, capsys, make, message):
    out = tmp_path / make(tmp_path)
    before = _tree(tmp_path)
    assert main(["preview", str(SCENES / "scene1"), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"simgen: error: {out}: ") and message in err and len(err.splitlines()) == 1, err
    assert _tree(tmp_path) == before

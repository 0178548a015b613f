"""homocal.files: output folders (marker, lock, cleanup of the tool's own temporaries) and atomic writes."""
from __future__ import annotations

import errno
import json
import os
import re
import signal
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from homocal import files
from homocal.correctors.base import load_corrector
from homocal.files import (LOCK_NAME, MAX_JSON_BYTES, OutputFolderError, create_temporary, os_message, output_folder,
                           read_json, temporaries_of, write_atomic, write_text_atomic)

TOOL = "demo-tool"
OURS = json.dumps({"format": TOOL})


def _tree(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def _make(root: Path, files: dict[str, str] | None) -> Path:
    out = root / "out"
    if files is not None:
        out.mkdir()
        for name, text in files.items():
            (out / name).write_text(text)
    return out


@pytest.mark.parametrize("files, resume, resumed", [
    (None, False, False),                                   # missing folder: created
    (None, True, False),                                    # --resume on a missing folder starts it
    ({}, False, False),                                     # empty folder
    ({LOCK_NAME: json.dumps({"pid": 1, "host": "h", "since": "s"})}, False, False),
    ({"manifest.json": OURS}, True, True),                  # ours: resumed
    ({"manifest.json": OURS, "notes.txt": "x"}, True, True),
])  # fmt: skip
def test_accepted(tmp_path, files, resume, resumed):
    out = _make(tmp_path, files)
    with output_folder(out, TOOL, resume) as folder:
        assert folder.path == out and folder.resumed is resumed and folder.marker == out / "manifest.json"
        assert (out / LOCK_NAME).is_file() and json.loads((out / LOCK_NAME).read_text())["pid"] == os.getpid()
    assert not (out / LOCK_NAME).exists()


@pytest.mark.parametrize("files, resume, message", [
    ({"video.mp4": "user's"}, False, "exists and is not empty"),
    ({"manifest.json": OURS}, False, "exists and is not empty"),
    ({"video.mp4": "user's", "a.tmp1.mp4": "user's"}, True, "not a demo-tool output folder"),
    ({"manifest.json": json.dumps({"format": "other-tool"})}, True, "not a demo-tool output folder"),
    ({"manifest.json": "not json"}, True, "not a demo-tool output folder"),
    ({"manifest.json": "[1, 2]"}, True, "not a demo-tool output folder"),
    ({LOCK_NAME: "a user's file"}, True, "not a demo-tool output folder"),  # a .lock that is not ours counts
    ({LOCK_NAME: "a user's file"}, False, "exists and is not empty"),
    ({LOCK_NAME: ""}, False, r"exists and is not empty \(its .lock is not a lock of ours: it is neither taken nor"),
    ({LOCK_NAME: ""}, True, "not a demo-tool output folder"),
    ({LOCK_NAME: "", "manifest.json": OURS}, True, r"\.lock: not a lock of ours \(its content is not the JSON"),
    ({LOCK_NAME: "{}", "manifest.json": OURS}, True, r"\.lock: not a lock of ours"),
])  # fmt: skip
def test_refused_untouched(tmp_path, files, resume, message):
    out = _make(tmp_path, files)
    before = _tree(out)
    with pytest.raises(OutputFolderError, match=message):
        with output_folder(out, TOOL, resume):
            pytest.fail("entered")
    assert _tree(out) == before


def test_refused_file(tmp_path):
    (tmp_path / "out").write_text("x")
    with pytest.raises(OutputFolderError, match="exists and is not a folder"):
        with output_folder(tmp_path / "out", TOOL, True):
            pass
    assert (tmp_path / "out").read_text() == "x"


def test_second_holder_named_same_process(tmp_path):
    out = tmp_path / "out"
    with output_folder(out, TOOL, False):
        (out / "manifest.json").write_text(OURS)
        for resume in (False, True):
            with pytest.raises(OutputFolderError, match=rf"locked by pid {os.getpid()} on {socket.gethostname()} since 20"):
                with output_folder(out, TOOL, resume):
                    pass
        assert (out / LOCK_NAME).is_file()  # the refused one left the holder's lock alone
    with output_folder(out, TOOL, True) as folder:  # released on exit
        assert folder.resumed


_HOLDER = textwrap.dedent("""
    import sys, time
    from homocal.files import output_folder
    with output_folder(sys.argv[1], "demo-tool", False):
        open(sys.argv[1] + "/manifest.json", "w").write('{"format": "demo-tool"}')
        print("held", flush=True)
        time.sleep(60)
""")


def test_other_process_then_killed(tmp_path):
    """Another process's lock is named (its pid); once it is killed (no cleanup), resume takes the folder."""
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-c", _HOLDER, str(out)], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline() == "held\n"
        with pytest.raises(OutputFolderError, match=rf"locked by pid {proc.pid} on "):
            with output_folder(out, TOOL, True):
                pass
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert (out / LOCK_NAME).is_file()  # left by the killed holder, and not a lock any more
    with output_folder(out, TOOL, True) as folder:
        assert folder.resumed


def test_remove_temporaries_only_ours(tmp_path):
    out = tmp_path / "out"
    user = ["camera.tmpx.json", "other.tmp1.json", "camera.tmp1.txt", "notes.tmp", "sub/camera.tmp1.json"]
    ours = ["camera.tmp123.json", "camera.tmp.json", "_parts/00001.tmp.mp4", "_parts/00001.gt.tmp9.parquet"]
    with output_folder(out, TOOL, False) as folder:
        for name in user + ours:
            (out / name).parent.mkdir(exist_ok=True)
            (out / name).write_text("x")
        assert temporaries_of(out / "camera.json") == [out / "camera.tmp.json", out / "camera.tmp123.json"]
        folder.remove_temporaries(["camera.json", "_parts/00001.mp4", "_parts/00001.gt.parquet", "missing/x.json"])
        assert sorted(_tree(out)) == sorted(user + [LOCK_NAME])


def test_a_lock_that_cannot_be_placed_names_it_and_leaves_no_folder(tmp_path, monkeypatch):
    """A full disk when the lock file is placed: one OSError naming .lock; the folder made for it is removed."""
    def full(*args):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(files.os, "link", full)
    out = tmp_path / "out"
    with pytest.raises(OSError) as e:
        with output_folder(out, TOOL, False):
            pytest.fail("entered")
    assert os_message(e.value) == f"{out / LOCK_NAME}: No space left on device" and not out.exists()
    assert list(tmp_path.iterdir()) == []


def test_a_users_lock_symlink_is_not_followed(tmp_path):
    out = _make(tmp_path, {"manifest.json": OURS})
    victim = tmp_path / "victim"
    victim.write_text("the user's")
    (out / LOCK_NAME).symlink_to(victim)
    with pytest.raises(OutputFolderError, match="not a lock of ours"):
        with output_folder(out, TOOL, True):
            pytest.fail("entered")
    assert victim.read_text() == "the user's" and (out / LOCK_NAME).is_symlink()


def test_temporaries_are_created_exclusively(tmp_path, monkeypatch):
    """A name taken (here by a planted symlink) is never opened: another random name is drawn; the symlink and its
    target stay; the file gets the mode a plain create would (umask applied), not mkstemp's 0600."""
    victim = tmp_path / "victim"
    victim.write_text("the user's")
    planted = tmp_path / f"a.tmp{7:012d}.txt"
    planted.symlink_to(victim)
    draws = iter([7, 8])
    monkeypatch.setattr(files.secrets, "randbelow", lambda n: next(draws))
    write_text_atomic(tmp_path / "a.txt", "ours")
    assert (tmp_path / "a.txt").read_text() == "ours" and victim.read_text() == "the user's" and planted.is_symlink()
    (tmp_path / "plain.txt").write_text("x")
    assert (tmp_path / "a.txt").stat().st_mode == (tmp_path / "plain.txt").stat().st_mode
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["a.txt", planted.name, "plain.txt", "victim"])


def test_temporary_names_are_not_predictable(tmp_path):
    names = {create_temporary(tmp_path / "a.json").name for _ in range(5)}
    assert len(names) == 5 and all(re.fullmatch(r"a\.tmp\d{12}\.json", n) for n in names)
    assert temporaries_of(tmp_path / "a.json") == sorted(tmp_path / n for n in names)


def test_write_atomic_leaves_nothing_on_failure(tmp_path):
    with pytest.raises(UnicodeEncodeError):
        write_text_atomic(tmp_path / "a.txt", "\udcff")  # unencodable: fails mid-write
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("existed", [False, True])
def test_failure_before_any_write_leaves_no_new_folder(tmp_path, existed):
    out = tmp_path / "out"
    if existed:
        out.mkdir()
    with pytest.raises(RuntimeError, match="no backend"):
        with output_folder(out, TOOL, False):
            raise RuntimeError("no backend")
    assert out.exists() is existed and (not existed or list(out.iterdir()) == [])
    with pytest.raises(RuntimeError, match="late"):
        with output_folder(out, TOOL, False):
            (out / "manifest.json").write_text(OURS)
            raise RuntimeError("late")
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json"]  # what was written stays, to resume


def _full_disk(tmp: Path) -> None:
    with open("/dev/full", "wb") as f:  # a real ENOSPC from the kernel, raised by an OSError that names no file
        f.write(b"x" * 65536)


def _temporary_read_only(tmp: Path) -> None:
    raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(tmp))


def _other_file(tmp: Path) -> None:
    raise OSError(errno.ENOENT, os.strerror(errno.ENOENT), "input.csv")


@pytest.mark.parametrize("write, message", [
    (_full_disk, "{out}: No space left on device"),          # no file named: the file meant is
    (_temporary_read_only, "{out}: Read-only file system"),  # the temporary named: the file meant instead
    (_other_file, "input.csv: No such file or directory"),   # another file named: kept
])  # fmt: skip
def test_write_atomic_errors_name_the_file_meant(tmp_path, write, message):
    out = tmp_path / "a.csv"
    with pytest.raises(OSError) as caught:
        write_atomic(out, write)
    assert os_message(caught.value) == message.format(out=out)
    assert list(tmp_path.iterdir()) == []


def test_read_json_refuses_a_file_beyond_its_bound_unread(tmp_path):
    """A correction (any JSON file homocal reads) larger than MAX_JSON_BYTES is refused from its size alone (a
    sparse file: nothing to read), naming it; one at the bound is read."""
    big = tmp_path / "c.json"
    with big.open("wb") as f:
        f.truncate(MAX_JSON_BYTES + 1)
    with pytest.raises(ValueError, match=r"c.json: larger than 16 MiB \(16,777,217 bytes\), the most read"):
        load_corrector(big)
    at = tmp_path / "at.json"
    at.write_text('{"a": 1}' + " " * (MAX_JSON_BYTES - 8))
    assert read_json(at) == {"a": 1}

"""Files a tool owns: atomic writes (a file that exists is whole) and locked, marked output folders
(docs/maintaining.md principle 6); reading a JSON object with one clear error. Shared by homocal and simgen."""
from __future__ import annotations

import csv
import fcntl
import json
import math
import os
import re
import secrets
import socket
import time
from array import array
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

LOCK_NAME = ".lock"
MAX_JSON_BYTES = 16 * 2**20  # a JSON file read (read_json) unless its reader bounds it otherwise: the ones homocal and
# simgen write (corrections, study.json, manifests) are a few KB


def create_temporary(path: str | Path) -> Path:
    """Create, exclusively, an empty file beside ``path`` to write it under: ``<stem>.tmp<12 random
    digits><suffix>`` (same extension: tools pick formats by it). ``O_CREAT | O_EXCL``: a name that exists (a
    file, or a symlink planted there) is never opened; another random name is tried."""
    path = Path(path)
    while True:
        tmp = path.with_name(f"{path.stem}.tmp{secrets.randbelow(10**12):012d}{path.suffix}")
        try:
            os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
            return tmp
        except FileExistsError:
            continue


def temporaries_of(path: str | Path) -> list[Path]:
    """The files beside ``path`` named like one of its temporaries (``<stem>.tmp<digits><suffix>``: the
    random digits of ``create_temporary``, any others or none), sorted; nothing else in the folder matches."""
    path = Path(path)
    if not path.parent.is_dir():
        return []
    pattern = re.compile(rf"{re.escape(path.stem)}\.tmp\d*{re.escape(path.suffix)}")
    return sorted(p for p in path.parent.iterdir() if pattern.fullmatch(p.name) and p.is_file())


def write_atomic(path: str | Path, write: Callable[[Path], object]) -> None:
    """Call write(tmp) on a new temporary file beside ``path`` (``create_temporary``), then rename it to ``path``;
    on any failure the temporary file is removed and nothing is left behind. An OSError that names no file (pyarrow's, ffmpeg's) or the
    temporary one is raised again naming ``path``, so a full disk reads "path: No space left on device"."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        tmp = create_temporary(path)
    except OSError as e:
        raise OSError(e.errno, os.strerror(e.errno) if e.errno else str(e), str(path)) from e
    try:
        write(tmp)
        os.replace(tmp, path)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        if e.filename is not None and Path(e.filename) != tmp:
            raise
        reason = os.strerror(e.errno) if e.errno else (str(e).strip().splitlines() or [type(e).__name__])[0]
        raise OSError(e.errno, reason, str(path)) from e
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def os_message(e: OSError) -> str:
    """One line: the file and the system's reason (``out/gt.parquet: No space left on device``)."""
    if e.filename is not None and e.strerror:
        return f"{e.filename}: {e.strerror}"
    return (str(e).strip().splitlines() or [type(e).__name__])[0]


def write_text_atomic(path: str | Path, text: str) -> None:
    """Write text (UTF-8, newlines as given) atomically."""
    write_atomic(path, lambda tmp: tmp.write_text(text, encoding="utf-8", newline=""))


def write_json_atomic(path: str | Path, obj: object) -> None:
    """Write obj as indented JSON with a final newline, atomically."""
    write_text_atomic(path, json.dumps(obj, indent=2) + "\n")


# ---- output folders ------------------------------------------------------------------------
class OutputFolderError(RuntimeError):
    """The output folder or file cannot be used (not ours, not empty, or locked by another run); one-line
    message."""


@dataclass(frozen=True)
class OutputFolder:
    """An output folder held by this process (see ``output_folder``).

    path: the folder. marker: its marker file. resumed: True if the marker was there at entry (a run
    to continue), False if the folder was new or empty.
    """

    path: Path
    marker: Path
    resumed: bool

    def remove_temporaries(self, names: Iterable[str]) -> None:
        """Delete the leftover temporaries (``temporaries_of``) of the given files, named relative to the
        folder (e.g. ``"camera.json"``, ``"_parts/00003.mp4"``): the only cleanup a tool may do."""
        for name in names:
            for tmp in temporaries_of(self.path / name):
                tmp.unlink()


def check_input_file(path: str | Path, max_bytes: int | None = None) -> Path:
    """``path`` as a Path if it is a regular file (a symlink to one counts) of at most ``max_bytes`` bytes;
    otherwise ValueError naming the file and what it is: no such file, a folder, not a regular file (a device
    such as /dev/zero, a pipe, a socket), or larger than the bound (refused before any byte is read)."""
    path = Path(path)
    if not path.exists():
        raise ValueError(f"{path}: no such file")
    if path.is_dir():
        raise ValueError(f"{path}: is a folder, not a file")
    if not path.is_file():
        raise ValueError(f"{path}: not a regular file (a device, a pipe or a socket)")
    if max_bytes is not None and path.stat().st_size > max_bytes:
        raise ValueError(f"{path}: larger than {max_bytes / 2**20:g} MiB ({path.stat().st_size:,} bytes), the most read")
    return path


def read_json(path: str | Path, max_bytes: int = MAX_JSON_BYTES) -> dict:
    """Read a JSON object from path; ValueError (naming the file) if it is missing, not a regular file, larger
    than max_bytes (refused before any byte is read), unreadable or not an object (check_input_file)."""
    path = check_input_file(path, max_bytes)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"{path}: not a JSON file ({e})") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a JSON object, got {type(data).__name__}")
    return data


def json_format(path: Path) -> object:
    """The "format" of the JSON object in ``path`` (a marker, a correction), or None if there is none."""
    try:
        return read_json(path).get("format")
    except (OSError, ValueError):
        return None


def csv_header(path: Path) -> list[str] | None:
    """The fields of the first line of the CSV file ``path``, or None if it cannot be read as UTF-8 text."""
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            return next(csv.reader([f.readline()]), [])
    except (OSError, ValueError):
        return None


def check_output_file(path: str | Path, is_ours: Callable[[Path], bool], what: str) -> None:
    """The single output file ``path`` a command was told to write (``-o FILE``), checked before any work.

    Refused (``OutputFolderError``, one line naming it): a folder; a file whose folder does not exist; a file
    that exists (or a symlink, judged by what it points to) unless ``is_ours(path)`` recognises it by its
    content as a ``what`` written by this command (a format tag, a header line): re-running a command replaces
    its own output, never a user's file. The write itself goes through ``write_atomic``, which replaces a
    symlink, never the file it points to.
    """
    path = Path(path)
    if path.is_dir():
        raise OutputFolderError(f"{path}: is a folder; give the name of the file to write")
    if not path.parent.is_dir():
        raise OutputFolderError(f"{path}: the folder {path.parent} does not exist")
    if (path.exists() or path.is_symlink()) and not is_ours(path):
        raise OutputFolderError(f"{path}: exists and is not a {what}; a file this command did not write is never "
                                "replaced (move it, or choose another name)")


def _holder(lock: Path) -> str | None:
    """Who a lock file of ours names ("pid P on HOST since T"), or None if ``lock`` is missing or not one of
    ours: a lock is ours only when its content is the JSON this module writes (a user's empty ``.lock`` is not)."""
    try:
        h = json.loads(lock.read_text(encoding="utf-8"))
        return f"pid {h['pid']} on {h['host']} since {h['since']}"
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _lock_content() -> bytes:
    since = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    return json.dumps({"pid": os.getpid(), "host": socket.gethostname(), "since": since}).encode()


def _place_lock(lock: Path) -> None:
    """Put a lock file of ours at ``lock`` if nothing is there: written whole under a temporary name, then
    linked into place (``os.link`` never replaces), so a lock file is never seen empty."""
    try:
        tmp = create_temporary(lock)
        try:
            tmp.write_bytes(_lock_content())
            os.link(tmp, lock)
        finally:
            tmp.unlink()
    except FileExistsError:
        pass  # another run's, or a user's: examined by the caller
    except OSError as e:  # a full disk, a read-only folder: named as the lock file
        raise OSError(e.errno, os.strerror(e.errno) if e.errno else str(e), str(lock)) from None


@contextmanager
def output_folder(path: str | Path, tool: str, resume: bool, marker: str = "manifest.json", resumable: bool = True
                  ) -> Iterator[OutputFolder]:
    """Create or reopen the output folder ``path`` of ``tool`` and hold its lock for the ``with`` block.

    Ownership: a folder is ``tool``'s when the JSON file ``path/marker`` has ``"format": tool`` (e.g.
    ``output_folder(out, "simgen-dataset", resume)`` with manifest.json, or ``output_folder(out,
    "homocal-study", resume, marker="study.json")``). The caller writes that marker, first of its files.

    On entry, in this order (each refusal raises ``OutputFolderError`` naming the folder, before anything
    is created or written):
      1. ``path`` exists and is not a directory: refused.
      2. Another process holds the folder's lock (``fcntl.flock`` on ``path/.lock``): refused with who
         holds it ("locked by pid P on HOST since 2026-11-23T05:30:00Z"). The kernel releases a lock when
         its holder dies, so a killed run never blocks a resume.
      3. The folder is missing, or holds nothing but a lock file of ours (the JSON this function writes; a
         ``.lock`` with other content, even empty, is a user's file: it counts as content and is never taken
         or deleted): a new folder (created with its parents), ``resumed`` False, whatever ``resume`` says.
      4. Otherwise: without ``resume``, refused ("exists and is not empty", suggesting --resume if the command
         has it: ``resumable``); with ``resume``, refused unless
         the marker is there with the right format ("not a <tool> output folder"): a folder that is not
         the tool's is never written to.
      5. The lock is taken (``LOCK_EX | LOCK_NB``; ``path/.lock`` placed whole if missing, ``_place_lock``) and
         the lock file then holds this process's pid, host and start time (UTC).
    On exit (normal or exception): the lock file is deleted, then unlocked; if the block raised and this
    call created the folder and nothing is in it, the folder is removed (a run that fails before writing
    anything, e.g. no OpenGL, leaves nothing behind). Locking checks that the locked
    file is still the one at ``path/.lock`` (and retries if not), so a deletion racing a new run never
    leaves two holders. Works on local file systems (flock is advisory and per open file; NFS may not
    honour it).
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OutputFolderError(f"{path}: exists and is not a folder")
    lock = path / LOCK_NAME
    fd = _lock(lock, create=False) if _holder(lock) else None  # a run writing it is named before other refusals
    created = False
    try:
        entries = {p.name for p in path.iterdir()} - ({LOCK_NAME} if _holder(lock) else set()) if path.is_dir() else set()
        foreign_lock = (f" (its {LOCK_NAME} is not a lock of ours: it is neither taken nor deleted)"
                        if LOCK_NAME in entries else "")
        resumed = bool(entries)
        if resumed and not resume:
            hint = "use --resume to continue it, or another output folder" if resumable else "use another output folder"
            raise OutputFolderError(f"{path}: exists and is not empty{foreign_lock} ({hint})")
        if resumed and json_format(path / marker) != tool:
            raise OutputFolderError(f"{path}: not a {tool} output folder (no {marker} with format {tool!r}); refused, "
                                    "nothing touched")
        created = not path.exists()
        path.mkdir(parents=True, exist_ok=True)
        fd = fd if fd is not None else _lock(lock, create=True)
    except BaseException:
        if fd is not None:
            os.close(fd)
        if created and path.is_dir() and not any(path.iterdir()):  # made here, the lock could not be placed
            path.rmdir()
        raise
    try:
        try:
            content = _lock_content()  # written over the old content, then cut to length: never seen empty
            os.pwrite(fd, content, 0)
            os.ftruncate(fd, len(content))
        except OSError as e:
            raise OSError(e.errno, e.strerror, str(lock)) from None
        yield OutputFolder(path, path / marker, resumed)
    except BaseException:
        if created and {p.name for p in path.iterdir()} == {LOCK_NAME}:
            lock.unlink()
            path.rmdir()
        raise
    finally:
        lock.unlink(missing_ok=True)
        os.close(fd)  # closing releases the flock


def _lock(lock: Path, create: bool) -> int | None:
    """Open and exclusively lock the lock file of ours at ``lock`` (placed first if missing and ``create``; None if
    it is absent and not ``create``): the descriptor of the file that is at that path once locked. A file there
    that is not a lock of ours (``_holder``) is refused (``OutputFolderError``) and left alone."""
    while True:
        if create:
            _place_lock(lock)
        try:
            fd = os.open(lock, os.O_RDWR | os.O_NOFOLLOW)
        except FileNotFoundError:
            if create:
                continue  # its holder deleted it after we placed ours: place it again
            return None
        except OSError:  # a symlink (ELOOP) or unreadable: not ours
            fd = None
        if fd is None or _holder(lock) is None:
            if fd is not None:
                os.close(fd)
            raise OutputFolderError(f"{lock}: not a lock of ours (its content is not the JSON this tool writes); "
                                    "it is neither taken nor deleted: move it away to use the folder")
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise OutputFolderError(f"{lock.parent}: locked by {_holder(lock) or 'another process'} (another run is writing it)") from None
        except BaseException:
            os.close(fd)
            raise
        try:
            if os.stat(lock).st_ino == os.fstat(fd).st_ino:
                return fd
        except FileNotFoundError:
            pass
        os.close(fd)  # the holder deleted the file between our open and our lock: try again


# ---- input tables ---------------------------------------------------------------------------
def read_points_csv(
    path: str | Path, required: tuple[str, ...], finite: bool, most: int | None = None, optional: tuple[str, ...] = (),
    max_bytes: int | None = None, keep_rows: bool = True,
) -> tuple[list[str], list[dict[str, str]], dict[str, np.ndarray], list[int]]:
    """Read a CSV of points with a header line (``homocal fit``'s REF.csv, ``apply``'s FEET.csv); return (column
    names, rows as dicts of text (none kept unless ``keep_rows``: a large table's numbers alone), the
    ``required`` columns and those of ``optional`` the header has as (N,) float64, the line number of each row).

    ValueError naming the file (and line) for: a missing file, a folder, a device, a file larger than
    ``max_bytes`` (check_input_file), a missing column, a column name given twice, text that is not UTF-8 or
    not CSV (a NUL byte, a field beyond csv's limit), a row of the wrong length, a value that is not a number
    (or not finite, if ``finite``), more than ``most`` rows (the file is read no further).
    """
    path = check_input_file(path, max_bytes)
    try:
        with path.open(newline="", encoding="utf-8-sig") as f:
            reader = csv.reader(f)
            try:
                return _read_points(reader, path, required, finite, most, optional, keep_rows)
            except csv.Error as e:
                raise ValueError(f"{path}, line {reader.line_num + 1}: not a CSV file ({e})") from None
    except UnicodeDecodeError as e:
        raise ValueError(f"{path}: not UTF-8 text ({e})") from None


def _read_points(reader, path: Path, required: tuple[str, ...], finite: bool, most: int | None,
                 optional: tuple[str, ...], keep_rows: bool):
    header = [name.strip() for name in next(reader, [])]
    twice = sorted({name for name in header if header.count(name) > 1})
    if twice:
        raise ValueError(f"{path}: column(s) {', '.join(map(repr, twice))} appear more than once in the header line")
    missing = [c for c in required if c not in header]
    if missing:
        raise ValueError(f"{path}: missing column(s) {', '.join(missing)} in the header line "
                         f"(found: {', '.join(header) or 'nothing'}; expected {','.join(required)})")
    required = required + tuple(c for c in optional if c in header)
    rows, values, lines = [], {c: array("d") for c in required}, array("q")
    for fields in reader:
        if not fields:
            continue
        if most is not None and len(lines) == most:
            raise ValueError(f"{path}, line {reader.line_num}: more than {most:,} points (the most this command takes)")
        if len(fields) != len(header):
            raise ValueError(f"{path}, line {reader.line_num}: {len(fields)} fields, the header has {len(header)}")
        row = dict(zip(header, fields))
        for c in required:
            try:
                value = float(row[c])
            except ValueError:
                raise ValueError(f"{path}, line {reader.line_num}: column {c}: {row[c]!r} is not a number") from None
            if finite and not math.isfinite(value):
                raise ValueError(f"{path}, line {reader.line_num}: column {c}: {row[c]!r} is not a finite number")
            values[c].append(value)
        if keep_rows:
            rows.append(row)
        lines.append(reader.line_num)
    return header, rows, {c: np.array(v, dtype=np.float64) for c, v in values.items()}, lines.tolist()

"""Every homocal command that writes files replaces only what it wrote (issue 12): a single ``-o FILE`` of
fit, apply and advise is replaced only if its content says this command wrote it (a correction's format tag,
the CSV's header line); report's folder is replaced only if its report.json says it is a report folder.
Anything else (a user's file, the command's own input, a folder, a symlink to a user's file) is refused with
one line and exit 2, and the files are left byte for byte."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from homocal.cli import main
from study_results import write_results

STREET = Path(__file__).resolve().parents[2] / "examples" / "street"
USER = b"a user's file\n"
COMMANDS = {  # command -> (argv writing OUT in the work folder, what the refusal calls its own output)
    "fit": (["fit", "--trapezoid", "trapezoid.json", "--points", "reference_points.csv", "-o", "OUT"],
            "not a homocal correction"),
    "apply": (["apply", "correction.json", "--points", "feet.csv", "-o", "OUT"], "not a CSV written by homocal apply"),
    "advise": (["advise", "--trapezoid", "trapezoid.json", "--distances", "10,20,30,40", "--samples", "2", "-o", "OUT"],
               "not a homocal advise CSV"),
}


def _tree(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def _run(argv: list[str], capsys) -> tuple[int, str]:
    try:
        code = main(argv)
    except SystemExit as e:
        code = e.code
    return code, capsys.readouterr().err


@pytest.fixture
def work(tmp_path, monkeypatch) -> Path:
    for name in ("trapezoid.json", "reference_points.csv", "feet.csv"):
        shutil.copy(STREET / name, tmp_path / name)
    monkeypatch.chdir(tmp_path)
    assert main(["fit", "--trapezoid", "trapezoid.json", "--points", "reference_points.csv", "-o", "correction.json"]) == 0
    return tmp_path


def _user_file(work: Path) -> str:
    (work / "mine.txt").write_bytes(USER)
    return "mine.txt"


def _symlink_to_user_file(work: Path) -> str:
    (work / "link").symlink_to(work / _user_file(work))
    return "link"


def _folder(work: Path) -> str:
    (work / "dir").mkdir()
    return "dir"


REFUSED = [
    # (id, make the output name in the work folder, message)
    ("a user's file", _user_file, "exists and is not a"),
    ("the command's own input", lambda w: "feet.csv", "exists and is not a"),
    ("a symlink to a user's file", _symlink_to_user_file, "exists and is not a"),
    ("a folder", _folder, "is a folder"),
    ("in a missing folder", lambda w: "missing/out", "the folder missing does not exist"),
]  # fmt: skip


@pytest.mark.parametrize("command", sorted(COMMANDS))
@pytest.mark.parametrize("make, message", [c[1:] for c in REFUSED], ids=[c[0] for c in REFUSED])
def test_output_file_not_ours_is_refused_untouched(work, capsys, command, make, message):
    out = make(work)
    before = _tree(work)
    code, err = _run([out if a == "OUT" else a for a in COMMANDS[command][0]], capsys)
    assert code == 2 and err.startswith(f"homocal: error: {out}: ") and err.count("\n") == 1, err
    assert message in err and (message != "exists and is not a" or COMMANDS[command][1] in err), err
    assert _tree(work) == before


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_rerun_replaces_its_own_output(work, capsys, command):
    argv = [("out" if a == "OUT" else a) for a in COMMANDS[command][0]]
    assert _run(argv, capsys)[0] == 0
    first = (work / "out").read_bytes()
    assert _run(argv, capsys)[0] == 0
    assert (work / "out").read_bytes() == first  # replaced by the same bytes (same inputs)
    assert not list(work.glob("*.tmp*"))


# ---- homocal report: a marked, locked output folder ----------------------------------------------
@pytest.fixture(scope="module")
def results(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("results")
    write_results(root)
    return root


def _report(results: Path, out: Path | None, capsys) -> tuple[int, str]:
    return _run(["report", str(results), "--no-progress", *([] if out is None else ["-o", str(out)])], capsys)


@pytest.mark.slow  # reports drawn
def test_report_folder_is_marked_and_rewritten(results, tmp_path, capsys):
    out = tmp_path / "page"
    assert _report(results, out, capsys)[0] == 0
    assert json.loads((out / "report.json").read_text())["format"] == "homocal-report"
    (out / "notes.txt").write_bytes(USER)  # a user's file in our folder: never touched
    ours = {n: b for n, b in _tree(out).items() if n != "notes.txt"}
    (out / "table.md").write_text("stale")
    assert _report(results, out, capsys)[0] == 0
    assert _tree(out) == {**ours, "notes.txt": USER}  # its own files replaced, the same bytes again


REPORT_REFUSED = [
    # (id, files in the folder (None: the folder is a file), message)
    ("a user's folder", {"report.html": USER, "figures/a.png": USER}, "not a homocal-report output folder"),
    ("a study folder", {"study.json": b'{"format": "homocal-study"}'}, "not a homocal-report output folder"),
    ("report.json of another tool", {"report.json": b'{"format": "x"}', "table.md": USER}, "not a homocal-report output folder"),
    ("a file", None, "exists and is not a folder"),
]  # fmt: skip


@pytest.mark.parametrize("files, message", [c[1:] for c in REPORT_REFUSED], ids=[c[0] for c in REPORT_REFUSED])
def test_report_refuses_a_folder_not_ours_untouched(results, tmp_path, capsys, files, message):
    out = tmp_path / "out"
    if files is None:
        out.write_bytes(USER)
    for name, data in (files or {}).items():
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name).write_bytes(data)
    before = _tree(tmp_path)
    code, err = _report(results, out, capsys)
    assert code == 2 and err.startswith(f"homocal: error: {out}: ") and err.count("\n") == 1 and message in err, err
    assert _tree(tmp_path) == before


def test_report_second_writer_is_told_who_holds_the_folder(results, tmp_path, capsys):
    out = tmp_path / "page"
    holder = subprocess.Popen([sys.executable, "-c", (
        "import sys, time\nfrom homocal.files import output_folder\n"
        "with output_folder(sys.argv[1], 'homocal-report', True, marker='report.json'):\n"
        "    print('held', flush=True)\n    time.sleep(60)\n"), str(out)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline() == "held\n"
        code, err = _report(results, out, capsys)
        assert code == 2 and f"locked by pid {holder.pid} on " in err and err.count("\n") == 1, err
    finally:
        holder.kill()
        holder.wait()

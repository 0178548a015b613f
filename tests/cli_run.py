"""homocal.cli.main run in-process, as a CompletedProcess: shared by the command tests of every package."""
import subprocess
from pathlib import Path

from homocal.cli import main


def homocal_main(*args: str, cwd: Path, capsys, monkeypatch) -> subprocess.CompletedProcess:
    """homocal.cli.main(args) run in-process in cwd, as a CompletedProcess (usage errors exit through SystemExit)."""
    monkeypatch.chdir(cwd)
    try:
        code = main(list(args))
    except SystemExit as e:
        code = e.code
    out = capsys.readouterr()
    return subprocess.CompletedProcess(args, code, out.out, out.err)

"""The console scripts' entry points (homocal.launch): a cheap ``import homocal`` and ``homocal --version``, one
version for both tools, and the one-line refusal when another distribution's simgen shadows ours."""
from __future__ import annotations

import os
import subprocess
import sys
from importlib.metadata import version
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
HEAVY = ("numba", "pyarrow", "cv2", "scipy", "matplotlib", "mujoco")


def run(code: str, extra_path: Path | None = None) -> subprocess.CompletedProcess:
    path = os.pathsep.join(str(p) for p in (REPO, extra_path) if p)
    return subprocess.run([sys.executable, "-c", code], env={**os.environ, "PYTHONPATH": path}, cwd=REPO,
                          capture_output=True, text=True, timeout=120)


def test_import_homocal_and_version_load_no_compiled_or_file_libraries():
    code = ("import sys; sys.argv = ['homocal', '--version']; import homocal.launch as l; l.homocal(); "
            f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))")
    done = run(code)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == [f"homocal {version('homocal')}", "[]"]


def test_both_tools_report_the_distribution_version():
    import homocal
    import simgen

    assert homocal.__version__ == simgen.__version__ == version("homocal")
    done = run("import sys; from simgen.cli import main; sys.exit(main(['--version']))")
    assert done.stdout == f"simgen {version('homocal')}\n"


def test_a_shadowing_simgen_distribution_is_named_in_one_line(tmp_path):
    info = tmp_path / "simgen-9.9.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: simgen\nVersion: 9.9\n")
    (info / "top_level.txt").write_text("simgen\n")
    done = run("import sys; from homocal.launch import simgen; sys.exit(simgen())", tmp_path)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.splitlines() == [
        "simgen: error: the distribution simgen also installs a top-level simgen package (PyPI's unrelated simgen), "
        "so simgen runs a mix of both: pip uninstall simgen, then reinstall homocal "
        "(pip install --force-reinstall --no-deps . in its checkout)"]
    assert run("import sys; from homocal.launch import simgen_shadows; print(simgen_shadows())").stdout == "[]\n"

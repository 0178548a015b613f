"""One guarded import of mujoco (simgen.backend): a missing OpenGL library gives the same one-line message
whichever simgen module is imported first, and the command exits 3 with it."""
import glob
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
MODULES = sorted(p.relative_to(ROOT).with_suffix("").as_posix().replace("/", ".").removesuffix(".__init__")
                 for p in (ROOT / "simgen").rglob("*.py"))  # fmt: skip
# each module imported first, in a process of its own: it imports without mujoco, or fails with BackendError
FIRST_IMPORT = """
import importlib, sys
for name in sys.argv[1:]:
    for loaded in [m for m in sys.modules if m.split(".")[0] in ("simgen", "mujoco")]:
        del sys.modules[loaded]
    try:
        importlib.import_module(name)
        print(name, "ok", "mujoco" in sys.modules)
    except Exception as e:
        print(name, type(e).__module__ + "." + type(e).__name__, str(e).splitlines()[0])
"""


def run(env: dict, *args: str, wrap: list[str] | None = None) -> subprocess.CompletedProcess:
    """A fresh process as a user starts it: without the PYOPENGL_PLATFORM that importing mujoco (egl) in
    this test process set, which would make PyOpenGL load EGL whatever MUJOCO_GL says."""
    base = {k: v for k, v in os.environ.items() if k != "PYOPENGL_PLATFORM"}
    return subprocess.run([*(wrap or []), sys.executable, *args], capture_output=True, text=True, timeout=300,
                          env={**base, "PYTHONPATH": str(ROOT), **env}, cwd=ROOT)


def test_no_module_reaches_mujoco_around_the_guard():
    """MUJOCO_GL=bogus makes ``import mujoco`` raise (RuntimeError): every simgen module that imports mujoco
    must turn that into BackendError naming the packages to install."""
    lines = run({"MUJOCO_GL": "bogus"}, "-c", FIRST_IMPORT, *MODULES).stdout.splitlines()
    assert [line.split()[0] for line in lines] == MODULES
    failed = [line for line in lines if " ok " not in line]
    assert {line.split()[0] for line in failed} >= {"simgen.backend", "simgen.model", "simgen.render", "simgen.dataset"}
    for line in failed:
        assert line.split()[1] == "simgen.backend.BackendError", line
        assert "cannot render offscreen with MUJOCO_GL=bogus" in line and "apt-get install libegl1" in line, line
    assert all(line.endswith("ok False") for line in lines if " ok " in line)  # a module that imports fine has no mujoco


def test_the_command_says_it_in_one_line(tmp_path):
    out = tmp_path / "out"
    result = run({"MUJOCO_GL": "bogus"}, "-m", "simgen.cli", "generate", "scenes/scene1", "-o", str(out), "--seconds", "0.5")
    assert result.returncode == 3 and result.stdout == ""
    assert result.stderr.startswith("simgen: error: cannot render offscreen with MUJOCO_GL=bogus") and result.stderr.count("\n") == 1
    assert not out.exists()


def _hide_osmesa() -> list[str] | None:
    """A wrapper that runs a command with the OSMesa library replaced by an empty file, in a private mount
    namespace (needs root and unshare); None where that cannot be done."""
    libraries = sorted(glob.glob("/usr/lib/*/libOSMesa.so*") + glob.glob("/usr/lib/libOSMesa.so*"))
    if not libraries or shutil.which("unshare") is None or os.geteuid() != 0:
        return None
    mounts = " && ".join(f"mount --bind /dev/null {lib}" for lib in libraries)
    probe = subprocess.run(["unshare", "-m", "--propagation", "private", "sh", "-c", f"{mounts} && true"], capture_output=True)
    return ["unshare", "-m", "--propagation", "private", "sh", "-c", f'{mounts} && exec "$@"', "sh"] if probe.returncode == 0 else None


@pytest.mark.parametrize("module", ["simgen.model", "simgen.stage", "simgen.backend"])
def test_osmesa_without_its_library(module):
    """What a user without libosmesa6 meets (NOTES.md: an AttributeError inside import mujoco), imported from
    different first modules."""
    wrap = _hide_osmesa()
    if wrap is None:
        pytest.skip("cannot hide libOSMesa here (needs root, unshare and mount)")
    result = run({"MUJOCO_GL": "osmesa"}, "-c", FIRST_IMPORT, module, wrap=wrap)
    assert result.stdout.startswith(f"{module} simgen.backend.BackendError cannot render offscreen with MUJOCO_GL=osmesa "
                                    "(AttributeError: "), result.stdout + result.stderr
    assert result.stdout.rstrip().endswith("fix: apt-get install libosmesa6")


IMPORTS = """
import os, sys
import cv2  # first: its loader sets LD_LIBRARY_PATH, its own doing
before = dict(os.environ)
import simgen, simgen.cli, simgen.scene, simgen.detection, simgen.export
print(dict(os.environ) == before, "mujoco" in sys.modules)
import simgen.dataset
print(os.environ.get("MUJOCO_GL"), simgen.dataset.source_digest.cache_info().currsize)
"""


def test_importing_simgen_changes_nothing():
    """simgen and its modules that need no rendering change no environment variable; simgen.backend (here through
    simgen.dataset) sets MUJOCO_GL's default only as it imports mujoco; nothing hashes the sources at import."""
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}
    result = subprocess.run([sys.executable, "-c", IMPORTS], capture_output=True, text=True, timeout=300,
                            env={**env, "PYTHONPATH": str(ROOT)}, cwd=ROOT)
    assert result.stdout.splitlines() == ["True False", "egl 0"], result.stdout + result.stderr

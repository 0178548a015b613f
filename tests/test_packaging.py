"""The distribution as a user without a clone gets it: a wheel built from the checkout carries both scenes and
the dependencies pyproject promises, ``simgen generate scene1`` works from the installed wheel alone, run
outside the checkout, and a fresh virtual environment with the wheel and nothing else runs every command of the
README's three quick starts (pip fetches the dependencies at install time, never at run time)."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import zipfile
from email.parser import Parser
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # builds a wheel, installs it, renders from it

ROOT = Path(__file__).resolve().parents[1]
SCENE_FILES = ("scene.toml", "scene.xml", "ground.png")
NOT_SOURCE = shutil.ignore_patterns(".git", "build", "*.egg-info", "__pycache__", ".pytest_cache", ".hypothesis", "out")


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The wheel pip builds from a copy of the checkout (the copy keeps build files out of the checkout)."""
    tmp = tmp_path_factory.mktemp("wheel")
    source = tmp / "source"
    shutil.copytree(ROOT, source, symlinks=True, ignore=NOT_SOURCE)
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp / "dist"), str(source)],
                   check=True, capture_output=True, timeout=600)
    (found,) = (tmp / "dist").glob("homocal-*.whl")
    return found


def test_the_wheel_carries_both_scenes_as_in_the_checkout(wheel):
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
        for scene in ("scene1", "scene2"):
            for name in SCENE_FILES:
                assert z.read(f"simgen/scenes/{scene}/{name}") == (ROOT / "scenes" / scene / name).read_bytes()
    assert not [n for n in names if n.startswith("simgen/scenes/") and n.endswith(".py")]  # the asset script stays in the clone
    assert {"homocal/__init__.py", "simgen/__init__.py", "simgen/cli.py"} <= names


def test_the_wheel_depends_on_opencv_python_headless_and_hog_is_an_extra(wheel):
    with zipfile.ZipFile(wheel) as z:
        (metadata,) = [n for n in z.namelist() if n.endswith(".dist-info/METADATA")]
        requires = Parser().parsestr(z.read(metadata).decode()).get_all("Requires-Dist")
    base = [r for r in requires if "extra ==" not in r]
    assert any(r.startswith("opencv-python-headless") for r in base)
    assert not any("contrib" in r for r in base)
    assert any(r.startswith("opencv-contrib-python-headless") and 'extra == "hog"' in r for r in requires)


@pytest.mark.generate
def test_generate_a_shipped_scene_by_name_from_the_installed_wheel(wheel, tmp_path):
    """The wheel installed alone into a folder (its dependencies are this environment's), run from a folder
    outside the checkout: ``scene1`` is found in the package."""
    site = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-index", "--target", str(site), str(wheel)],
                   check=True, capture_output=True, timeout=300)
    env = {**os.environ, "PYTHONPATH": str(site), "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    where = subprocess.run([sys.executable, "-c", "import simgen.scene as s; print(s.SHIPPED)"], env=env, cwd=tmp_path,
                           capture_output=True, text=True, check=True)
    assert Path(where.stdout.strip()) == site / "simgen" / "scenes"
    run = subprocess.run([sys.executable, "-m", "simgen.cli", "generate", "scene1", "--out", "data", "--seconds", "0.5",
                          "--no-progress"], env=env, cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0 and run.stdout.startswith("simgen generate: data: scene1, seed 0, 10 frames"), run.stderr
    assert (tmp_path / "data" / "video.mp4").stat().st_size > 0


QUICK_START = re.compile(r"^## Quick start: (.*?)\n(.*?)(?=^## )", re.S | re.M)
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.S | re.M)
SHORT = ((" --seconds 10", " --seconds 1"), (" --preset quick", " --preset quick --variants 3"))  # a short study
NOT_RUN = ("homocal ui ",)  # a server that runs until stopped (tests/ui drive it)


def quick_starts() -> list[tuple[str, list[str], list[str]]]:
    """(title, shell commands, python blocks) of each of the README's quick starts, shortened by SHORT."""
    out = []
    for title, body in QUICK_START.findall((ROOT / "README.md").read_text(encoding="utf-8")):
        commands, python = [], []
        for language, block in FENCE.findall(body):
            if language == "python":
                python.append(block)
                continue
            lines = [line[2:] for line in block.splitlines() if line.startswith("$ ")] if language == "console" \
                else [line.split("  #")[0].strip() for line in block.splitlines() if line.strip()]
            for command in lines:
                for old, new in SHORT:
                    command = command.replace(old, new)
                if not command.startswith(NOT_RUN):
                    commands.append(command)
        out.append((title, commands, python))
    return out


def test_the_readme_has_three_quick_starts_and_the_short_study():
    starts = quick_starts()
    assert [title for title, _, _ in starts] == ["a real camera", "a dataset", "the study"]
    assert all(commands for _, commands, _ in starts)
    assert any("--variants 3" in c for c in starts[2][1]) and any("--seconds 1 " in c for c in starts[1][1])


@pytest.fixture(scope="module")
def plain_venv(wheel, tmp_path_factory) -> Path:
    """A fresh virtual environment with the wheel and its declared dependencies only: no extras, no test packages."""
    venv = tmp_path_factory.mktemp("venv") / "env"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, capture_output=True, timeout=300)
    done = subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "install", "-q", "--disable-pip-version-check",
                           str(wheel)], capture_output=True, text=True, timeout=1800)
    assert done.returncode == 0, done.stderr[-2000:]
    return venv


@pytest.mark.generate
def test_every_quick_start_command_runs_from_a_plain_install(plain_venv, tmp_path):
    """`pip install` of the wheel alone, then the README's three quick starts in order from a folder outside the
    checkout (the first one's files from `homocal examples`), each command exiting 0; the Python block too."""
    python = plain_venv / "bin" / "python"
    listed = subprocess.run([str(python), "-m", "pip", "list", "--format=freeze"], capture_output=True, text=True).stdout
    assert not [p for p in ("pytest", "hypothesis", "selenium", "dask", "opencv-contrib") if p in listed.lower()]
    env = {key: value for key, value in os.environ.items() if key not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env |= {"PATH": f"{plain_venv / 'bin'}{os.pathsep}{env.get('PATH', '')}", "MUJOCO_GL": env.get("MUJOCO_GL", "egl")}
    ran = []
    for command in ["homocal examples examples"] + [c for _, commands, _ in quick_starts() for c in commands]:
        done = subprocess.run(["bash", "-c", command], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=1200)
        assert done.returncode == 0, f"{command}\n{done.stderr[-3000:]}"
        ran.append(command.split()[:2])
    for block in (b for _, _, python_blocks in quick_starts() for b in python_blocks):
        done = subprocess.run([str(python), "-c", block], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr[-3000:]
    assert ["homocal", "study"] in ran and ["simgen", "export-mot"] in ran and ["homocal", "apply"] in ran
    assert (tmp_path / "out" / "study" / "report" / "report.html").is_file()

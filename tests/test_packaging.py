"""The distribution as a user without a clone gets it: a wheel built from the checkout carries both scenes and
the dependencies pyproject promises, and ``simgen generate scene1`` works from the installed wheel alone, run
outside the checkout."""
from __future__ import annotations

import os
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

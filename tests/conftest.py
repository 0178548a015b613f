"""Shared fixtures: one small real dataset made by `simgen generate`, for the homocal tests that read datasets."""
from __future__ import annotations

import fcntl
import os
import subprocess
import sys
from pathlib import Path

import pytest

SCENES = Path(__file__).resolve().parents[1] / "scenes"
RENDERING_FIXTURES = {"tiny_dataset"}  # a test that uses one is marked generate and slow (a 20 s render; pyproject.toml)
FIRST = ("test_packaging.py",)  # the longest file (a wheel, a fresh venv, every quick start: minutes) runs first,
# so that test.sh's other pytest-xdist process runs the rest beside it


def pytest_collection_modifyitems(items):
    for item in items:
        if RENDERING_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.generate)
            item.add_marker(pytest.mark.slow)
    items.sort(key=lambda item: item.path.name not in FIRST)  # stable: every other test in its order


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory) -> Path:
    """A complete scene1 dataset of 1.5 s at 1280x720 (both detectors), written by the simgen command; rendered
    once per run: pytest-xdist's workers (test.sh) share it through their run's folder, the first one renders."""
    root = tmp_path_factory.getbasetemp()
    if "PYTEST_XDIST_WORKER" in os.environ:
        root = root.parent  # the run's folder, each worker's is inside it
    out = root / "tiny_dataset" / "scene1"
    with open(root / "tiny_dataset.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if not out.parent.joinpath("done").exists():
            env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
            cmd = [sys.executable, "-m", "simgen.cli", "generate", str(SCENES / "scene1"), "--out", str(out),
                   "--seconds", "1.5", "--seed", "3", "--no-progress"]  # fmt: skip
            subprocess.run(cmd, check=True, env=env, capture_output=True, timeout=600)
            out.parent.joinpath("done").touch()
    return out

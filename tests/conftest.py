"""Shared fixtures: one small real dataset made by `simgen generate`, for the homocal tests that read datasets."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

SCENES = Path(__file__).resolve().parents[1] / "scenes"
RENDERING_FIXTURES = {"tiny_dataset"}  # a test that uses one is marked generate and slow (a 20 s render; pyproject.toml)


def pytest_collection_modifyitems(items):
    for item in items:
        if RENDERING_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.generate)
            item.add_marker(pytest.mark.slow)


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory) -> Path:
    """A complete scene1 dataset of 1.5 s at 1280x720 (both detectors), written by the simgen command."""
    out = tmp_path_factory.mktemp("datasets") / "scene1"
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    cmd = [sys.executable, "-m", "simgen.cli", "generate", str(SCENES / "scene1"), "--out", str(out),
           "--seconds", "1.5", "--seed", "3", "--no-progress"]  # fmt: skip
    subprocess.run(cmd, check=True, env=env, capture_output=True, timeout=600)
    return out

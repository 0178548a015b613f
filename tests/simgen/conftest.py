"""Fixtures of the simgen tests."""
from __future__ import annotations

from pathlib import Path

import pytest

from scene_copies import copy_scene


@pytest.fixture
def small_scene(tmp_path: Path) -> Path:
    """A copy of scene1 at 320x180 with 8 agents (scene_copies.copy_scene)."""
    return copy_scene(tmp_path)

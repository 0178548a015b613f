"""Helpers for the simgen tests: scene folders copied to tmp and edited like a user would."""
from __future__ import annotations

import re
import shutil
from pathlib import Path

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def edit_toml(path: Path, section: str, key: str, value: str | None) -> None:
    """Set ``key = value`` (TOML text) in ``[section]`` of the file, or delete the line if value is None."""
    lines, current, done = path.read_text().splitlines(keepends=True), "", False
    for i, line in enumerate(lines):
        head = re.match(r"\s*\[+([^\]]+)\]+", line)
        if head:
            current = head.group(1).strip()
        elif current == section and re.match(rf"{re.escape(key)}\s*=", line) and not done:
            lines[i], done = ("" if value is None else f"{key} = {value}\n"), True
    assert done, f"{section}.{key} not found in {path}"
    path.write_text("".join(lines))


def copy_scene(tmp_path: Path, name: str = "scene1", small: bool = True, shrink: int = 4) -> Path:
    """A copy of scenes/<name> in tmp_path; ``small``: the image ``shrink`` times smaller (320x180 by default),
    8 agents, 0.5 s chunks, 5 warm-up frames."""
    folder = tmp_path / name
    shutil.copytree(SCENES / name, folder)
    if small:
        toml = folder / "scene.toml"
        text = toml.read_text()
        image = eval(re.search(r"hand_placed_image = (.*)", text).group(1))  # noqa: S307 (our own file)
        scaled = [[round((u + 0.5) / shrink - 0.5), round((v + 0.5) / shrink - 0.5)] for u, v in image]
        for section, key, value in (
            ("camera", "width", str(1280 // shrink)), ("camera", "height", str(720 // shrink)), ("run", "chunk_seconds", "0.5"),
            ("agents", "count", "8"), ("detection", "rgb_warmup_frames", "5"),
            ("trapezoid", "hand_placed_image", str(scaled)),
        ):  # fmt: skip
            edit_toml(toml, section, key, value)
    return folder

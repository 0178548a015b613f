"""README.md's shown outputs, produced here.

The convention (README.md says it where it first uses it):
- a ```console block is a sequence of `$ command` lines, each followed by the output it prints (stdout and
  stderr, compared line by line, exactly); the commands run in bash, in order, in a fresh folder holding a
  link to the repository's examples/, with this checkout's homocal;
- every ```python block runs, in the README's order, in one namespace, in a fresh folder holding examples/;
  an expression statement whose last line ends in `# -> VALUE` (a number or a list of them) must give VALUE
  to the decimals shown.
Plain ``` blocks (commands that take minutes, a server, a folder layout) are not run.
"""
from __future__ import annotations

import ast
import os
import re
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest

from homocal.geometry import PinholeCamera, ViewTransformer

REPO = Path(__file__).resolve().parents[1]
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.S | re.M)
EXPECTED = re.compile(r"#\s*->\s*(\[[-0-9.,\s\[\]]*\]|-?[0-9]+(?:\.[0-9]+)?)")


def blocks(language: str) -> list[str]:
    return [body for lang, body in FENCE.findall((REPO / "README.md").read_text(encoding="utf-8")) if lang == language]


def commands(block: str) -> list[tuple[str, str]]:
    """[(command, expected output)] of a console block."""
    out = []
    for line in block.splitlines(keepends=True):
        if line.startswith("$ "):
            out.append((line[2:].strip(), ""))
        else:
            out[-1] = (out[-1][0], out[-1][1] + line)
    return out


@pytest.fixture
def folder(tmp_path: Path, monkeypatch) -> Path:
    (tmp_path / "examples").symlink_to(REPO / "examples")
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.mark.parametrize("block", blocks("console"), ids=lambda b: b.split("\n")[0][2:60])
def test_console_block(block, folder):
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    for command, expected in commands(block):
        done = subprocess.run(["bash", "-c", command], cwd=folder, env=env, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr
        assert (done.stdout + done.stderr).splitlines() == expected.splitlines(), command


def test_python_blocks(folder):
    namespace, checked = {}, 0
    for block in blocks("python"):
        lines = block.splitlines()
        for stmt in ast.parse(block).body:
            found = EXPECTED.search(lines[stmt.end_lineno - 1])
            if not (isinstance(stmt, ast.Expr) and found):
                exec(compile(ast.Module([stmt], []), "README.md", "exec"), namespace)
                continue
            got = np.asarray(eval(compile(ast.Expression(stmt.value), "README.md", "eval"), namespace), dtype=float)
            shown = found.group(1)
            decimals = len(re.search(r"\.([0-9]*)", shown).group(1)) if "." in shown else 0
            expected = np.asarray(ast.literal_eval(shown), dtype=float)
            assert got.shape == expected.shape and np.allclose(got, expected, rtol=0, atol=0.5 * 10**-decimals), \
                f"README.md: {lines[stmt.lineno - 1].strip()} gives {got}, the README shows {shown}"
            checked += 1
    assert checked == sum(len(EXPECTED.findall(b)) for b in blocks("python")) > 0


def test_opencv_get_perspective_transform_claims():
    """The README's paragraph on OpenCV's getPerspectiveTransform, measured: float64 refused; float32 within
    2e-6 m of ours on the paper's camera; a horizon through the image origin (h33 = 0): |h33| < 1e-9 and within
    1e-6 m of ours, no failure."""
    ground = np.array([[-3.5, 30.0], [3.5, 30.0], [3.5, 8.0], [-3.5, 8.0]])
    image = PinholeCamera().project_ground(ground)
    with pytest.raises(cv2.error):
        cv2.getPerspectiveTransform(image, ground)
    horizon = ViewTransformer(image, ground).horizon_row(640.0)
    for src, tolerance in ((image, 2e-6), (image - [0.0, horizon], 1e-6)):
        m = cv2.getPerspectiveTransform(src.astype(np.float32), ground.astype(np.float32))
        inside = src + [[5, 5], [-5, 5], [-5, -5], [5, -5]]
        theirs = cv2.perspectiveTransform(inside.reshape(-1, 1, 2), m).reshape(-1, 2)
        assert np.abs(theirs - ViewTransformer(src, ground).transform_points(inside)).max() < tolerance
    assert abs(m[2, 2]) < 1e-9

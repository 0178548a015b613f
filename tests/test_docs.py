"""The documentation's shown outputs, produced here: README.md and every docs/*.md page.

The convention (docs/camera.md says it where it first uses it):
- a ```console block is a sequence of `$ command` lines, each followed by the output it prints (stdout and
  stderr, compared line by line, exactly, except that a number shown with FULL_PRECISION or more significant
  digits, a float written in full, may differ from it by FLOAT_RTOL = 1e-6 relative: another CPU's BLAS kernels
  move a fitted float's last digits, never its sixth); the commands run in bash,
  in order, in a fresh folder holding a link to the repository's examples/, with this checkout's homocal;
- every ```python block of a page runs, in the page's order, in one namespace per page, in a fresh folder
  holding examples/; an expression statement whose last line ends in `# -> VALUE` (a number or a list of them)
  must give VALUE to the decimals shown.
Plain ``` blocks (commands that take minutes, a server, a folder layout) and ```text blocks are not run.
Also: README.md is short, every relative link of the pages reaches a file, no tracked file tells the project's
history by session, and docs/cli.md is what scripts/cli_reference.py makes of the parsers.
"""
from __future__ import annotations

import ast
import importlib.util
import os
import re
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest

from homocal.geometry import PinholeCamera, ViewTransformer

REPO = Path(__file__).resolve().parents[1]
PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.S | re.M)
EXPECTED = re.compile(r"#\s*->\s*(\[[-0-9.,\s\[\]]*\]|-?[0-9]+(?:\.[0-9]+)?)")
LINK = re.compile(r"\]\(([^)#\s]+)")
README_MAX_LINES = 250
NUMBER = re.compile(r"-?[0-9]+\.[0-9]+(?:e[-+]?[0-9]+)?")
FULL_PRECISION = 12  # significant digits from which a shown number is a float written in full
FLOAT_RTOL = 1e-6  # how far a float written in full may move (relative) on another machine
SLOW_BLOCK = 2  # a console block running this many homocal commands or more is marked slow (a 2 s interpreter each)
HISTORY = re.compile(r"sessions?\s+[0-9]", re.I)  # a session and its number: history lives in git and CHANGELOG.md


def name(page: Path) -> str:
    return str(page.relative_to(REPO))


def blocks(page: Path, language: str) -> list[str]:
    return [body for lang, body in FENCE.findall(page.read_text(encoding="utf-8")) if lang == language]


def significant_digits(number: str) -> int:
    return len(number.split("e")[0].lstrip("-").replace(".", "").lstrip("0"))


def same_output(got: str, shown: str) -> bool:
    """Whether a command's output is the one a page shows (module docstring: full-precision floats to FLOAT_RTOL)."""
    if NUMBER.sub("#", got) != NUMBER.sub("#", shown):
        return False
    pairs = zip(NUMBER.findall(got), NUMBER.findall(shown))
    return all(a == b or (significant_digits(b) >= FULL_PRECISION and np.isclose(float(a), float(b), rtol=FLOAT_RTOL, atol=0))
               for a, b in pairs)


def test_same_output_lets_only_full_precision_floats_move():
    shown = "0,384.0,-5.346877664924247,0.18018507631087466,ok (96.8 %)"
    assert same_output("0,384.0,-5.346877664924241,0.18018507631087469,ok (96.8 %)", shown)
    assert same_output("0,384.0,-5.346880664924247,0.18018517631087466,ok (96.8 %)", shown)  # within 1e-6
    assert not same_output("0,384.0,-5.346877664924247,0.18018507631087466,ok (96.9 %)", shown)  # a rounded figure
    assert not same_output("0,384.0,-5.3469,0.18018507631087466,ok (96.8 %)", shown)  # rounded, beyond 1e-6
    assert not same_output("0,384.0,-5.346887664924247,0.18018507631087466,ok (96.8 %)", shown)  # beyond 1e-6
    assert not same_output("0,384.0,-5.346877664924247,0.18018507631087466,no (96.8 %)", shown)  # the text


def commands(block: str) -> list[tuple[str, str]]:
    """[(command, expected output)] of a console block."""
    out = []
    for line in block.splitlines(keepends=True):
        if line.startswith("$ "):
            out.append((line[2:].strip(), ""))
        else:
            out[-1] = (out[-1][0], out[-1][1] + line)
    return out


CONSOLE = [pytest.param(page, block, id=f"{name(page)}: {block.split(chr(10))[0][2:60]}",
                        marks=[pytest.mark.slow] if len(re.findall(r"^\$ homocal ", block, re.M)) >= SLOW_BLOCK else [])
           for page in PAGES for block in blocks(page, "console")]
PYTHON = [page for page in PAGES if blocks(page, "python")]


@pytest.fixture
def folder(tmp_path: Path, monkeypatch) -> Path:
    (tmp_path / "examples").symlink_to(REPO / "examples")
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.mark.parametrize("page, block", CONSOLE)
def test_console_block(page, block, folder):
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    for command, expected in commands(block):
        done = subprocess.run(["bash", "-c", command], cwd=folder, env=env, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, f"{name(page)}: {command}\n{done.stderr}"
        got, shown = (done.stdout + done.stderr).splitlines(), expected.splitlines()
        assert len(got) == len(shown) and all(map(same_output, got, shown)), f"{name(page)}: {command}\n{done.stdout}{done.stderr}"


@pytest.mark.parametrize("page", PYTHON, ids=name)
def test_python_blocks(page, folder):
    namespace, checked = {}, 0
    for block in blocks(page, "python"):
        lines = block.splitlines()
        for stmt in ast.parse(block).body:
            found = EXPECTED.search(lines[stmt.end_lineno - 1])
            if not (isinstance(stmt, ast.Expr) and found):
                exec(compile(ast.Module([stmt], []), name(page), "exec"), namespace)
                continue
            code = compile(ast.Expression(stmt.value), name(page), "eval")
            got = np.asarray(eval(code, namespace), dtype=float)  # noqa: S307  (the page's own expression)
            shown = found.group(1)
            decimals = len(re.search(r"\.([0-9]*)", shown).group(1)) if "." in shown else 0
            expected = np.asarray(ast.literal_eval(shown), dtype=float)
            assert got.shape == expected.shape and np.allclose(got, expected, rtol=0, atol=0.5 * 10**-decimals), \
                f"{name(page)}: {lines[stmt.lineno - 1].strip()} gives {got}, the page shows {shown}"
            checked += 1
    assert checked == sum(len(EXPECTED.findall(b)) for b in blocks(page, "python"))


def test_readme_is_short():
    lines = len((REPO / "README.md").read_text(encoding="utf-8").splitlines())
    assert lines <= README_MAX_LINES, f"README.md has {lines} lines (at most {README_MAX_LINES}: the rest belongs in docs/)"


@pytest.mark.parametrize("page", PAGES, ids=name)
def test_relative_links_reach_a_file(page):
    missing = [link for link in LINK.findall(page.read_text(encoding="utf-8"))
               if "://" not in link and not (page.parent / link).exists()]
    assert not missing, f"{name(page)} links to {missing}"


def tracked_files() -> list[Path]:
    try:
        listed = subprocess.run(["git", "ls-files", "-z"], cwd=REPO, capture_output=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    return [REPO / f for f in listed.decode().split("\0") if f]


def test_no_tracked_file_tells_history_by_session():
    found = []
    for path in tracked_files():
        try:
            text = path.read_text(encoding="utf-8")
        except (UnicodeDecodeError, IsADirectoryError, FileNotFoundError):
            continue  # binary files; a file deleted but not yet committed
        found += [f"{path.relative_to(REPO)}: {m.group(0)!r}" for m in HISTORY.finditer(text)]
    assert not found, f"history belongs in git and CHANGELOG.md: {found[:10]}"


def test_history_pattern_finds_what_it_must():
    said = (f"as sessions {1}-21 did", f"Session {12}'s preset", f"session\n{22}", "ui/session.py")  # f-strings: not history here
    assert [bool(HISTORY.search(text)) for text in said] == [True, True, True, False]


def cli_reference():
    spec = importlib.util.spec_from_file_location("cli_reference", REPO / "scripts" / "cli_reference.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_cli_reference_is_the_parsers():
    """docs/cli.md regenerated from homocal's and simgen's parsers is byte for byte the committed page."""
    module = cli_reference()
    if f"(Python {module.PYTHON})" not in module.PAGE.read_text(encoding="utf-8"):
        pytest.skip(f"docs/cli.md was written by another Python's argparse than {module.PYTHON}")
    assert module.main(["--check"]) == 0, "docs/cli.md differs from the parsers: run python scripts/cli_reference.py"


def test_cli_reference_check_fails_on_a_stale_page(tmp_path, monkeypatch, capsys):
    module = cli_reference()
    stale = tmp_path / "cli.md"
    stale.write_text(module.reference().replace("--trapezoid TRAP.json", "--trap TRAP.json", 1), encoding="utf-8")
    monkeypatch.setattr(module, "PAGE", stale)
    assert module.main(["--check"]) == 1
    assert capsys.readouterr().err.splitlines() == [
        "cli_reference.py: error: docs/cli.md differs from the parsers: run python scripts/cli_reference.py"]


def test_cli_reference_covers_every_subcommand():
    page = (REPO / "docs" / "cli.md").read_text(encoding="utf-8")
    module = cli_reference()
    for module_name, function in module.PARSERS:
        parser = getattr(importlib.import_module(module_name), function)()
        for sub in module.subparsers(parser).values():
            assert f"\n### {sub.prog}\n" in page and f"usage: {sub.prog} " in page, sub.prog


def test_opencv_get_perspective_transform_claims():
    """docs/camera.md's paragraph on OpenCV's getPerspectiveTransform, measured: float64 refused; float32 within
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

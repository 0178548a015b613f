"""The simgen command's conventions, as homocal's: --version, -o/--out on every subcommand that writes (never
``-``), help text on every option, progress bars as --progress/--no-progress or the terminal say, one line and
exit 2 when the output cannot be written."""
import argparse
from importlib.metadata import version

import cv2
import pytest

from homocal.progress import show_progress
from simgen.cli import _parser, main

WRITERS = ("generate", "preview", "export-mot", "import-mot")


def subparsers() -> dict[str, argparse.ArgumentParser]:
    return next(a for a in _parser()._actions if isinstance(a, argparse._SubParsersAction)).choices


def test_no_command_is_one_line_pointing_to_help(capsys):
    assert main([]) == 2
    assert capsys.readouterr().err == "simgen: error: the following arguments are required: COMMAND (see simgen --help)\n"


def test_scenes_lists_the_shipped_scenes(capsys):
    assert main(["scenes"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "scene1: a straight two-lane street; 1280x720, 60 s at 20 fps, 24 people, detectors segmentation,rgb"
    assert lines[1].startswith("scene2: a four-lane avenue; 1280x720, 60 s at 20 fps, 30 people, ")
    assert lines[2].startswith("scene3: scene 1's street seen by a real CCTV camera; 1280x720, 60 s at 20 fps, 24 people, ")
    assert lines[3].startswith("simgen scenes: 3 shipped scenes in ") and len(lines) == 4


@pytest.mark.parametrize("scene", ["scene4", "../scene1", "scenes/scene1/", ".", "", "a\nb", "x" * 300])
def test_a_scene_that_is_neither_a_folder_nor_shipped_is_one_line(scene, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    if scene == ".":  # an existing folder is a scene folder: it has no scene.toml
        message = "scene.toml: no such scene config"
    else:
        message = f"scene {scene!r:.30}"
    assert main(["generate", scene, "-o", "out", "--seconds", "0.5"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("simgen: error: ") and message in err and len(err.splitlines()) == 1, err
    if scene != ".":
        assert err.endswith("(shipped: scene1, scene2, scene3)\n"), err
    assert list(tmp_path.iterdir()) == []


def test_version_is_the_installed_distribution_s(capsys):
    assert main(["--version"]) == 0 and capsys.readouterr().out == f"simgen {version('homocal')}\n"


@pytest.mark.parametrize("name", sorted(subparsers()))
def test_every_option_has_help(name):
    for action in subparsers()[name]._actions:
        assert action.help not in (None, "", argparse.SUPPRESS), (name, action.option_strings or action.dest)


def test_the_writers_are_the_subcommands_with_an_output():
    assert sorted(n for n, p in subparsers().items() if any("--out" in a.option_strings for a in p._actions)) == sorted(WRITERS)


@pytest.mark.parametrize("name", WRITERS)
def test_every_writer_takes_o_and_out_and_refuses_stdout(name, tmp_path, capsys, monkeypatch):
    options = {s: a for a in subparsers()[name]._actions for s in a.option_strings}
    assert options["-o"] is options["--out"] and options["-o"].required is (name != "import-mot")  # its DATASET may come first
    monkeypatch.chdir(tmp_path)
    assert main([name, "in", "-o", "-", *(["--name", "yolo"] if name == "import-mot" else [])]) == 2
    err = capsys.readouterr().err
    assert err == f"simgen: error: {name}: argument -o/--out: simgen writes files, not a table to stdout: give a path\n"
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("flag,expected", [(["--progress"], True), (["--no-progress"], False), ([], False)])
def test_progress_option(flag, expected):
    """Default: stderr is a terminal (under pytest's capture it is not)."""
    assert show_progress(_parser().parse_args(["generate", "s", "-o", "x", *flag])) is expected


@pytest.mark.generate  # renders a frame
def test_preview_writes_its_png_and_says_so(small_scene, tmp_path, capsys):
    png = tmp_path / "frame.png"
    assert main(["preview", str(small_scene), "-o", str(png), "--t", "2"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"simgen preview: {png}: {small_scene.name} at t = 2 s, seed 0, ") and out.endswith(" agents in view\n")
    shape = cv2.imread(str(png)).shape
    assert shape[1:] == (320, 3) and shape[0] > 180  # the 320x180 frame, its legend strip below


def test_preview_on_an_unwritable_path_is_one_line(small_scene, tmp_path, capsys):
    (tmp_path / "file").write_text("mine")
    assert main(["preview", str(small_scene), "-o", str(tmp_path / "file" / "frame.png")]) == 2
    err = capsys.readouterr().err
    assert err == f"simgen: error: {tmp_path / 'file' / 'frame.png'}: the folder {tmp_path / 'file'} does not exist\n", err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file", small_scene.name] and (tmp_path / "file").read_text() == "mine"

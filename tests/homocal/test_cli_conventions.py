"""The homocal command's conventions: --version, -o/--out on every subcommand that writes, `-o -` for the
table apply writes, help text on every option, progress bars as --progress/--no-progress or the terminal say."""
import argparse
import subprocess
import sys
from importlib.metadata import version

import pytest

from homocal.cli import SUBCOMMANDS, build_parser, main
from homocal.correctors import RegressionCorrector
from homocal.geometry import ViewTransformer
from homocal.progress import show_progress

from cli_run import homocal_main
from test_cli import GROUND, IMAGE, REF_G, REF_Q, work  # noqa: F401 (work is a fixture)

WRITERS = ("fit", "apply", "study", "sweep", "report", "ui", "advise", "lens", "measure", "watch")


def subparsers() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices


def test_version_is_the_installed_distribution_s(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0 and capsys.readouterr().out == f"homocal {version('homocal')}\n"


@pytest.mark.parametrize("name", sorted(subparsers()))
def test_every_option_has_help(name):
    for action in subparsers()[name]._actions:
        assert action.help not in (None, "", argparse.SUPPRESS), (name, action.option_strings or action.dest)


@pytest.mark.parametrize("name", WRITERS)
def test_every_writer_takes_o_and_out(name):
    options = {s: a for a in subparsers()[name]._actions for s in a.option_strings}
    assert options["-o"] is options["--out"] and options["-o"].option_strings == ["-o", "--out"]  # one spelling


@pytest.mark.parametrize("flag,expected", [(["--progress"], True), (["--no-progress"], False), ([], False)])
@pytest.mark.parametrize("name", ["study", "sweep", "report"])
def test_progress_option(name, flag, expected):
    """Default: stderr is a terminal (under pytest's capture it is not)."""
    args = {"study": ["study", "d", "-o", "x"], "sweep": ["sweep", "d", "-o", "x"], "report": ["report", "r"]}[name]
    assert show_progress(build_parser().parse_args(args + flag)) is expected


def test_apply_writes_its_table_to_stdout(work, capsys, monkeypatch):  # noqa: F811
    RegressionCorrector().fit(ViewTransformer(IMAGE, GROUND), REF_Q, REF_G, (0.0, 0.0)).save(work / "c.json")
    to_file = homocal_main("apply", "c.json", "--points", "feet.csv", "--out", "out.csv", cwd=work, capsys=capsys,
                           monkeypatch=monkeypatch)
    to_stdout = homocal_main("apply", "c.json", "--points", "feet.csv", "-o", "-", cwd=work, capsys=capsys,
                             monkeypatch=monkeypatch)
    assert to_file.returncode == to_stdout.returncode == 0
    assert to_stdout.stdout == (work / "out.csv").read_text()
    assert to_stdout.stderr == to_file.stdout.replace("written to out.csv", "written to stdout")
    assert not (work / "-").exists()


def test_fit_refuses_stdout(work, capsys, monkeypatch):  # noqa: F811
    before = sorted(p.name for p in work.iterdir())
    result = homocal_main("fit", "--trapezoid", "trap.json", "--points", "ref.csv", "--method", "regression", "-o", "-",
                          cwd=work, capsys=capsys, monkeypatch=monkeypatch)
    assert result.returncode == 2 and result.stderr.startswith("homocal: error: -o -:") and result.stderr.count("\n") == 1
    assert sorted(p.name for p in work.iterdir()) == before


def test_subcommands_table_names_what_each_module_adds():
    """SUBCOMMANDS (command -> module) is what each module's add_parser adds, in --help's order."""
    assert list(subparsers()) == list(SUBCOMMANDS)
    for command, module in SUBCOMMANDS.items():
        parser = build_parser(command)
        added = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices
        assert command in added and {SUBCOMMANDS[c] for c in added} == {module}


def test_one_command_loads_only_its_module():
    """`homocal apply` imports neither the study nor the page (their modules cost ~2 s of CPU to import)."""
    probe = ("import sys; from homocal.cli import build_parser; build_parser('apply'); "
             "print(sorted(m for m in ('homocal.study.advise', 'homocal.ui.cli', 'homocal.study.cli') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
